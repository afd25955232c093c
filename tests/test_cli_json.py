"""Every command's `--json` on the smallest inputs it accepts prints valid JSON (no NaN or
Infinity: undefined values are null, with a note where they are not obvious), and the one
defaults rule (issue 19): the cut from --cut or the model directory, else a clear error."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from tests.cli_helpers import cli_in_process, json_in_process, run_cli, strict_json

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "datasets"
SEED004 = DATA / "seeds/hou2023_positions.csv"
CUT = DATA / "seeds/hou2023_cut.toml"
CUT_FLAGS = ["--teeth", "3", "--kt-mpa", "796", "--kn-mpa", "169", "--radial-immersion", "0.5"]


def run(*args):
    return subprocess.run([sys.executable, "-m", "service", *map(str, args)], capture_output=True, text=True, cwd=ROOT, timeout=600)


def json_of(*args):
    done = run(*args, "--json")
    assert done.returncode == 0, done.stderr
    return strict_json(done.stdout)


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """Seed 004's positions 1, 4 and 7 (the smallest table `train --cv 3` accepts), a model of
    them that carries the seed's cut, and one pose."""
    folder = tmp_path_factory.mktemp("small")
    lines = SEED004.read_text().splitlines()
    keep = [lines[0]] + [l for l in lines[1:] if l.split(",")[0] in ("P1", "P4", "P7")]
    (folder / "three.csv").write_text("\n".join(keep) + "\n")
    (folder / "pose.csv").write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nP4,1500,0,800,0\n")
    return folder


def test_train_with_one_pose_folds_is_valid_json_and_says_why_r2_is_null(small):
    out = json_in_process("train", small / "three.csv", "--cv", "3", "--cut", CUT, "--out", small / "model")
    entry = out["cv"]["x1.fn_hz"]
    assert entry["r2_mean"] is None and entry["r2_std"] is None and "fewer than two poses" in entry["note"]
    assert entry["r2_pooled"] is not None and math.isfinite(entry["rmse"])
    assert (small / "model" / "cut.toml").read_text() == CUT.read_text()


def test_a_refused_fold_count_leaves_an_existing_model_as_it_was(small, tmp_path):
    """`train --cv 1` (or more folds than poses) is refused before anything is written: it had
    replaced the model directory's files and deleted its cut, then failed."""
    model = tmp_path / "model"
    json_in_process("train", small / "three.csv", "--cv", "0", "--cut", CUT, "--out", model)
    before = {p.name: p.read_bytes() for p in model.iterdir()}
    for folds in ("1", "4"):
        code, _, err = cli_in_process("train", small / "three.csv", "--cv", folds, "--out", model)
        assert code == 2 and "--cv" in err and "between 2 and 3 folds" in err
        assert {p.name: p.read_bytes() for p in model.iterdir()} == before


def test_every_command_prints_strict_json_on_small_inputs(small, tmp_path):
    if not (small / "model").exists():
        json_in_process("train", small / "three.csv", "--cv", "0", "--cut", CUT, "--out", small / "model")
    json_of("data", "check", small / "three.csv")  # through a new interpreter, as installed; the rest in this process
    (tmp_path / "tables").mkdir()
    (tmp_path / "tables" / "three.csv").write_text((small / "three.csv").read_text())
    json_in_process("data", "summary", tmp_path / "tables")
    f = np.linspace(5.0, 60.0, 400)  # one mode, 20 Hz, zeta 0.03, k 1e6 N/m: the smallest FRF fit accepts
    h = 1.0 / (1e6 * (1 - (f / 20.0) ** 2 + 2j * 0.03 * f / 20.0))
    frf = tmp_path / "frf.csv"
    frf.write_text("# pose_id = P1\n# x_mm = 1500\n# y_mm = 0\n# z_mm = 800\n# beta_deg = 0\nfrequency_hz,h_xx_re,h_xx_im\n" + "".join(f"{float(a)!r},{float(b.real)!r},{float(b.imag)!r}\n" for a, b in zip(f, h)))
    json_in_process("fit", frf, "--out", tmp_path / "fitted.csv")
    json_in_process("predict", small / "model", "--poses", small / "pose.csv")
    json_in_process("absorber", "field", "--target-hz", "20")
    json_in_process("absorber", "robust", "--host", DATA / "seeds/dogan2024_host_milling.toml", "--rpm-min", "2700", "--rpm-max", "2700", "--rpm-steps", "1", "--samples", "50")
    json_in_process("absorber", "tune", "--host-fn-hz", "20", "--host-k-n-per-m", "5e5", "--host-zeta", "0.03", "--mass-ratio", "0.05", "--layout", "tmd", *CUT_FLAGS)
    entries = json_in_process("schedule", small / "model", "--poses", small / "pose.csv")  # the model's cut
    assert entries[0]["stability"]["converged"] is True
    json_in_process("control", "schedule", "--modes", small / "three.csv", "--poses", small / "pose.csv")
    json_in_process("chatter", "--modes", small / "three.csv", "--pose-id", "P4", "--rpm", "2000", *CUT_FLAGS)
    json_in_process("lobes", "--modes", small / "three.csv", "--pose-id", "P4", "--rpm-min", "1900", "--rpm-max", "2100", "--rpm-steps", "2", *CUT_FLAGS)
    json_in_process("sle", "--modes", small / "three.csv", "--pose-id", "P4", "--direction", "y", "--rpm", "2000", "--teeth", "3", "--kt-mpa", "796", "--kn-mpa", "169",
            "--tool-diameter-mm", "6", "--helix-deg", "30", "--radial-depth-mm", "3", "--axial-depth-mm", "0.2", "--feed-per-tooth-mm", "0.05", "--milling", "down")
    json_in_process("twin", "modes", "--x-mm", "1600", "--y-mm", "0", "--z-mm", "600", "--beta-deg", "0")
    grid = tmp_path / "grid.toml"
    grid.write_text('[meta]\nkind = "pose_grid"\nsource = "test"\n\n[[poses]]\nx_mm = 1600\ny_mm = 0\nz_mm = 600\nbeta_deg = 0\n')
    json_in_process("twin", "campaign", "--grid", grid, "--out", tmp_path / "campaign.csv")
    json_in_process("sweep", "--twin", DATA / "robots/kr_r2700_twin.toml", "--grid", grid, "--cut", DATA / "cuts/sweep_demo_cut.toml", "--out", tmp_path / "sweep", "--workers", "1", "--no-lobes")
    made = run_cli("gap-campaign", "--cut", CUT, "--out", tmp_path / "meas.csv", "--poses", "2")
    assert made.returncode == 0, made.stderr
    json_in_process("gap", "--measured", tmp_path / "meas.csv", "--twin", "--cut", CUT, "--out", tmp_path / "gap")


def test_a_command_without_a_cut_names_both_ways_to_give_one(small, tmp_path):
    done = run_cli("sweep", "--twin", DATA / "robots/kr_r2700_twin.toml", "--grid", DATA / "campaigns/seed003_grid.toml", "--out", tmp_path / "o")
    assert done.returncode == 2 and "--cut" in done.stderr and "cut.toml" in done.stderr and "Traceback" not in done.stderr


def test_the_gap_baseline_honours_a_b_c_orientations():
    """A campaign that gives its poses as A/B/C is predicted at those orientations: the same
    fn as the equivalent beta pose, not the beta = 0 one (issue 19: it used to read beta only)."""
    from posedyn.gap import Measurements
    from posedyn.robot import abc_from_rotation, rotation_from_beta
    from service.gap.baseline import Baseline

    a, b, c = np.degrees(abc_from_rotation(rotation_from_beta(math.radians(50.0))))

    def campaign(orientation):
        conditions = {"x_mm": np.array([1600.0]), "y_mm": np.array([100.0]), "z_mm": np.array([600.0]), **{k: np.array([v]) for k, v in orientation.items()}}
        return Measurements(quantity=np.array(["fn_hz"]), value=np.ones(1), std=np.ones(1), pose_id=np.array(["p"]), direction=np.array(["x"]), mode=np.array([1.0]), conditions=conditions)

    baseline = Baseline(twin_file=DATA / "robots/kr_r2700_twin.toml")
    fn_abc = baseline.predict(campaign({"a_deg": a, "b_deg": b, "c_deg": c}))[0][0]
    fn_beta = baseline.predict(campaign({"beta_deg": 50.0}))[0][0]
    fn_zero = baseline.predict(campaign({"beta_deg": 0.0}))[0][0]
    assert fn_abc == pytest.approx(fn_beta, rel=1e-9)
    assert abs(fn_abc / fn_zero - 1) > 1e-3


def test_cross_validation_says_how_honest_the_predictive_std_was(tmp_path):
    """A new user saw a predicted zeta std of 1.2e-5 at P5 beside a cross-validated zeta RMSE of
    0.0055. `train --cv` reports each target's held-out errors in the stds of the predicted
    measurement (latent std and fitted noise; `z_rms`, 1 is honest): on seed 004's nine positions
    1.5-7.3 stds rms, and the text says to read those stds as a lower bound."""
    out = json_in_process("train", SEED004, "--cv", "7", "--out", tmp_path / "model")
    z = {name: entry["z_rms"] for name, entry in out["cv"].items()}
    assert all(v is not None and v > 0 for v in z.values())
    assert z["x1.zeta"] > 1.5 and z["x1.k_n_per_m"] > 5
    code, text, _ = cli_in_process("train", SEED004, "--cv", "7", "--out", tmp_path / "model2")
    assert code == 0 and "was too narrow on the held-out poses" in text


def test_flags_that_would_be_ignored_or_refused_later_are_errors_at_once(tmp_path):
    """`absorber robust --rpm-steps 1` silently ignored --rpm-max; `serve --pivot-mm -5` with a
    tool change started and refused every query."""
    done = run_cli("absorber", "robust", "--host", DATA / "seeds/dogan2024_host_milling.toml", "--rpm-min", "2700", "--rpm-max", "3000", "--rpm-steps", "1")
    assert done.returncode == 2 and done.stderr.startswith("error: option '--rpm-steps'")
    done = run_cli("serve", "--model", tmp_path, "--cell", "c", "--cut", DATA / "seeds/hou2023_cut.toml", "--state-dir", tmp_path / "state",
                   "--reference-tool", DATA / "seeds/seed003_reference_tool.toml", "--target-tool", DATA / "seeds/seed003_target_tool.toml", "--pivot-mm", "-5")
    assert done.returncode == 2 and done.stderr.startswith("error: option '--pivot-mm'") and not (tmp_path / "state").exists()
