"""Pose sweeps (issue 9): the batched stability against the per-structure engine, the Nyquist
gain limit against the closed-loop poles, the sweep end to end (twin and trained model), its
resume after a kill, the report in headless Chromium, and bad input."""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from posedyn.robot import GridPose, pose_modes
from posedyn.errors import InputError
from posedyn.io.cut import read_cut
from posedyn.io import read_modal_table
from posedyn.io.model_dir import save_model
from posedyn.posemodel import PoseModel
from posedyn.io.twin_file import load_twin
from posedyn.robot import ToolPose
from posedyn.stability import Discretization, StabilityModel
from posedyn.stability.batch import BatchStability
from tests.cli_helpers import cli_in_process, json_in_process, run_cli

ROOT = Path(__file__).resolve().parents[1]
TWIN = ROOT / "datasets/robots/kr_r2700_twin.toml"
CUT = ROOT / "datasets/cuts/sweep_demo_cut.toml"
GRID = """[meta]
kind = "pose_grid"
source = "test"
twin = "{twin}"

[grid]
x_mm = [1300, 1600, 1900]
y_mm = [-300, 300]
z_mm = [600]
beta_deg = [-40, 30]

[[poses]]
label = "far_away"
x_mm = 4000
y_mm = 0
z_mm = 600
beta_deg = 0
"""


@pytest.fixture(scope="module")
def twin_structures():
    robot, params = load_twin(TWIN)
    rng = np.random.default_rng(3)
    out = []
    for _ in range(6):
        pose = ToolPose.from_beta(rng.uniform(1.3, 1.9), rng.uniform(-0.3, 0.3), 0.6, math.radians(rng.uniform(-60, 60)))
        out.append(pose_modes(robot, GridPose("p", pose), params)[1].dynamics())
    return out


@pytest.fixture()
def grid(tmp_path):
    path = tmp_path / "grid.toml"
    path.write_text(GRID.format(twin=TWIN.as_posix()))
    return path


def test_batch_stability_equals_the_per_structure_engine(twin_structures):
    """Same bracketing from the same ladder, but the monodromy on the tool-tip history instead
    of the modal one: the critical depths and chatter frequencies agree to the tolerance. (The
    ladder must be the same: at some speeds the first unstable depth is a narrow island, found
    or not depending on where the rungs fall.)"""
    cut, rpm, _ = read_cut(CUT)
    disc = Discretization(20)
    engine = BatchStability(twin_structures, cut, rpm, disc)
    guess = 5.0 * engine.scale_m
    batch = engine.critical_depths(rel_tol=1e-7, guess_m=guess)
    for j, dyn in enumerate(twin_structures):
        single = StabilityModel(dyn, cut, disc).critical_depths([rpm], rel_tol=1e-7, guess_m=guess[j : j + 1])
        assert batch.depth_m[j] == pytest.approx(single.depth_m[0], rel=1e-6)
        assert batch.dominant_chatter_hz[j] == pytest.approx(single.dominant_chatter_hz[0], rel=1e-6)


def test_tool_tip_monodromy_has_the_modal_monodromys_multipliers(twin_structures):
    cut, rpm, _ = read_cut(CUT)
    disc = Discretization(12)
    batch = BatchStability(twin_structures[:2], cut, rpm, disc)
    depths = np.array([0.5e-3, 2e-3])
    for j, dyn in enumerate(twin_structures[:2]):
        compact = np.linalg.eigvals(batch.tool_tip_monodromy(np.array([j, j]), depths))
        full = np.linalg.eigvals(StabilityModel(dyn, cut, disc).step_matrices([rpm, rpm], depths).monodromy())
        for c, f in zip(compact, full):
            big_c = np.sort_complex(c[np.abs(c) > 1e-6])
            big_f = np.sort_complex(f[np.abs(f) > 1e-6])
            assert len(big_c) == len(big_f)
            np.testing.assert_allclose(np.abs(big_c), np.abs(big_f), rtol=1e-8)


def test_batch_over_speeds_gives_the_lobes(twin_structures):
    cut, rpm, _ = read_cut(CUT)
    disc = Discretization(20)
    speeds = np.linspace(1500, 2500, 7)
    dyn = twin_structures[0]
    engine = BatchStability([dyn] * len(speeds), cut, speeds, disc)
    guess = 5.0 * engine.scale_m
    lobes = engine.critical_depths(frequencies=False, rel_tol=1e-7, guess_m=guess).depth_m
    single = StabilityModel(dyn, cut, disc).critical_depths(speeds, rel_tol=1e-7, frequencies=False, guess_m=guess).depth_m
    np.testing.assert_allclose(lobes, single, rtol=1e-6)


def test_batch_refuses_mixed_mode_counts(twin_structures):
    cut, rpm, _ = read_cut(CUT)
    from posedyn.dynamics import ToolTipDynamics
    from posedyn.table import Mode

    one = ToolTipDynamics.from_modes(x=[Mode(20.0, 0.03, 1e6)])
    with pytest.raises(InputError, match="group them by mode count"):
        BatchStability([twin_structures[0], one], cut, rpm)


def test_nyquist_gain_limit_matches_the_closed_loop_poles():
    from absorber.active_damping import DVF, Actuator, modal_frf

    for modes in ([(13.0, 0.03, 1e6), (15.7, 0.03, 2e6)], [(9.2, 0.04, 5e5)], [(20, 0.02, 3e6), (50, 0.03, 1e7)]):
        H = modal_frf(modes)
        loop = DVF(H, H, H, Actuator(), 9.0)
        assert loop.nyquist_gain_limit() == pytest.approx(loop.max_stable_gain(), rel=2e-3)


# --- the sweep end to end ----------------------------------------------------------------------


def sweep_cli(*args):
    """`posedyn sweep ARGS` as its own process (it starts a Dask cluster), asserting success."""
    cmd = [sys.executable, "-c", "from service.cli import main; main()", "sweep", *map(str, args)]
    out = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    return out


def read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def twin_sweep(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sweep")
    grid = folder / "grid.toml"
    grid.write_text(GRID.format(twin=TWIN.as_posix()))
    out = folder / "out"
    sweep_cli("--twin", TWIN, "--grid", grid, "--cut", CUT, "--out", out, "--workers", "1", "--chunk-size", "4", "--lobe-speeds", "12", "--json")
    return out


def test_sweep_writes_results_chunks_and_report(twin_sweep):
    rows = read_rows(twin_sweep / "results.csv")
    assert len(rows) == 13
    assert sorted(p.name for p in (twin_sweep / "chunks").iterdir()) == [f"chunk_0000{i}.csv" for i in range(4)]
    far = next(r for r in rows if r["pose_id"] == "far_away")
    assert far["reachable"] == "false" and far["flags"] == "unreachable" and far["critical_depth_mm"] == ""
    reachable = [r for r in rows if r["reachable"] == "true"]
    assert len(reachable) == 12
    for r in reachable:
        assert float(r["critical_depth_with_absorber_mm"]) > 0.9 * float(r["critical_depth_mm"])
        assert 5 < float(r["lowest_fn_hz"]) < 30 and float(r["field_mt"]) >= 0 and float(r["sle_um"]) != 0
        assert float(r["std_fn_x1_hz"]) == 0.0  # the twin has no uncertainty
    import pyarrow.parquet as pq

    assert pq.read_table(twin_sweep / "results.parquet").num_rows == 13
    html = (twin_sweep / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 7 and "Worst poses" in html and "Provenance" in html
    assert "src='http" not in html and 'src="http' not in html  # self-contained


def test_sweep_refuses_to_mix_runs(twin_sweep, grid):
    again = run_cli("sweep", "--twin", TWIN, "--grid", grid, "--cut", CUT, "--out", twin_sweep, "--workers", "1", "--chunk-size", "4")
    assert again.returncode == 2 and "--resume" in again.stderr
    changed = run_cli("sweep", "--twin", TWIN, "--grid", grid, "--cut", CUT, "--out", twin_sweep, "--workers", "1", "--chunk-size", "4", "--steps", "30", "--resume")
    assert changed.returncode == 2 and "fingerprint" in changed.stderr


def test_a_bad_input_file_writes_nothing(grid, tmp_path, datasets):
    """Every input file is read before the output folder is made: a bad actuator file used to
    leave sweep.json and an empty chunks/ behind (the next run then refused without --resume)."""
    bad = tmp_path / "actuator.toml"
    bad.write_text((datasets / "seeds/sahu2024_active_damping.toml").read_text() + '\n[control]\nmount_axis = "diagonal"\n')
    done = run_cli("sweep", "--twin", TWIN, "--grid", grid, "--cut", CUT, "--actuator", bad, "--out", tmp_path / "sweep", "--workers", "1")
    assert done.returncode == 2 and done.stderr.startswith(f"error: {bad}, column 'control.mount_axis'")
    assert not (tmp_path / "sweep").exists()


def test_sweep_with_a_trained_model_reports_uncertainty_and_equals_posedyn_schedule(tmp_path, grid):
    """The sweep and `posedyn schedule` run the one per-pose chain: the same model and poses give
    the same numbers to the last digit; `posedyn chatter` on the predicted modes agrees to 0.5 %."""
    table = read_modal_table(ROOT / "datasets/campaigns/seed003_twin_s1.csv")
    model = PoseModel(method="stgp").fit(table)
    save_model(model, tmp_path / "model")
    out = tmp_path / "out"
    sweep_cli(tmp_path / "model", "--grid", grid, "--cut", CUT, "--out", out, "--workers", "1", "--no-lobes")
    rows = read_rows(out / "results.csv")
    assert next(r for r in rows if r["pose_id"] == "far_away")["flags"] == "unreachable"  # the grid's twin checks reach
    reachable = [r for r in rows if r["reachable"] == "true"]
    assert len(reachable) == 12 and all(float(r["lowest_fn_std_hz"]) > 0 for r in reachable)

    picked = reachable[:2]
    (tmp_path / "poses.csv").write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\n" + "".join(f"{r['pose_id']},{r['x_mm']},{r['y_mm']},{r['z_mm']},{r['beta_deg']}\n" for r in picked))
    for row, entry in zip(picked, json_in_process("schedule", tmp_path / "model", "--poses", tmp_path / "poses.csv", "--cut", CUT)):
        assert entry["pose_id"] == row["pose_id"]
        assert float(row["critical_depth_mm"]) == pytest.approx(entry["critical_depth_mm"], rel=1e-9)
        assert float(row["dominant_chatter_hz"]) == pytest.approx(entry["dominant_chatter_hz"], rel=1e-9)
        assert float(row["field_mt"]) == pytest.approx(entry["absorber"]["field_mt"], rel=1e-9)
        assert float(row["critical_depth_with_absorber_mm"]) == pytest.approx(entry["critical_depth_with_absorber_mm"], rel=1e-9)
        assert float(row["dvf_gain_ns_per_m"]) == pytest.approx(entry["controller"]["dvf_gain_ns_per_m"], rel=1e-9)
        assert entry["stability"]["method"] == "floquet" and entry["stability"]["converged"]
    code, _, err = cli_in_process("predict", tmp_path / "model", "--poses", tmp_path / "poses.csv", "--out", tmp_path / "modes.csv")
    assert code == 0, err
    cut, rpm, _ = read_cut(CUT)
    for row in picked:
        single = json_in_process("chatter", "--modes", tmp_path / "modes.csv", "--pose-id", row["pose_id"], "--rpm", rpm, "--teeth", cut.teeth,
                                 "--kt-mpa", cut.kt_pa / 1e6, "--kn-mpa", cut.kn_pa / 1e6, "--radial-immersion", cut.radial_immersion, "--milling", cut.milling)
        assert single["critical_depth_mm"] == pytest.approx(float(row["critical_depth_mm"]), rel=5e-3)
        assert single["dominant_chatter_hz"] == pytest.approx(float(row["dominant_chatter_hz"]), rel=5e-3)


def test_a_model_without_a_twin_has_its_reach_decided_by_the_shipped_twin(tmp_path):
    """README, Defaults: a model without a twin of its own (stgp), with a grid that names none, still
    has its poses' reach decided (by the shipped twin): the sweep flags the far pose `unreachable`
    and `posedyn schedule` refuses it, as `posedyn serve` does (`unreachable_pose`); both used to
    give it numbers."""
    from service.sweep import SweepSpec
    from service.sweep.chunk import compute_chunk
    from service.sweep.spec import read_sweep_poses

    model = PoseModel(method="stgp").fit(read_modal_table(ROOT / "datasets/campaigns/seed003_twin_s1.csv"))
    save_model(model, tmp_path / "model")
    grid = tmp_path / "grid.toml"
    grid.write_text("\n".join(line for line in GRID.splitlines() if not line.startswith("twin =")) + "\n")
    poses, grid_twin = read_sweep_poses(grid)
    assert grid_twin is None
    spec = SweepSpec(poses=str(grid), cut=str(CUT), model=str(tmp_path / "model"))
    far = [i for i in range(len(poses)) if poses.pose_id[i] == "far_away"]
    rows = compute_chunk(spec.to_json(), poses.subset(far + [0]), grid_twin)
    assert rows[0]["reachable"] is False and rows[0]["flags"] == "unreachable" and rows[0]["critical_depth_mm"] is None
    assert rows[1]["reachable"] is True and rows[1]["critical_depth_mm"] > 0
    (tmp_path / "poses.csv").write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nnear,1600,0,600,0\nfar,9000,0,800,0\n")
    code, _, err = cli_in_process("schedule", tmp_path / "model", "--poses", tmp_path / "poses.csv", "--cut", CUT, "--json")
    assert code == 2 and "poses the robot reaches" in err and "far" in err and "near" not in err.split("got")[-1]


def test_sweep_bad_input_names_the_file(tmp_path):
    bad = tmp_path / "grid.toml"
    bad.write_text('[meta]\nkind = "pose_grid"\nsource = "t"\n[grid]\nx_mm = [1300, "a"]\ny_mm = [0]\nz_mm = [600]\nbeta_deg = [0]\n')
    out = run_cli("sweep", "--twin", TWIN, "--grid", bad, "--cut", CUT, "--out", tmp_path / "out")
    assert out.returncode == 2 and str(bad) in out.stderr and "x_mm" in out.stderr and "Traceback" not in out.stderr
    missing = run_cli("sweep", "--twin", TWIN, "--grid", tmp_path / "nope.toml", "--cut", CUT, "--out", tmp_path / "out")
    assert missing.returncode == 2 and "nope.toml" in missing.stderr


def test_killed_sweep_resumes_to_the_same_results(tmp_path):
    """SIGKILL the whole sweep (driver, scheduler, workers) half way, rerun with --resume: the
    results file is byte-identical to an uninterrupted run's. (Stability by the 20-step
    semi-discretization override: this tests the bookkeeping, and three converged sweeps of 25
    poses would take minutes.)"""
    grid = tmp_path / "grid.toml"
    grid.write_text(GRID.format(twin=TWIN.as_posix()).replace("beta_deg = [-40, 30]", "beta_deg = [-60, -20, 20, 60]"))
    args = ["--twin", TWIN, "--grid", grid, "--cut", CUT, "--workers", "1", "--chunk-size", "2", "--no-lobes", "--steps", "20"]
    full = tmp_path / "full"
    sweep_cli(*args, "--out", full)

    cut_short = tmp_path / "resumed"
    cmd = [sys.executable, "-c", "from service.cli import main; main()", "sweep", *map(str, args), "--out", str(cut_short)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    chunks = cut_short / "chunks"
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline and len(list(chunks.glob("chunk_*.csv"))) < 4:
        assert proc.poll() is None, "the sweep ended before it could be killed"
        time.sleep(0.01)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done = len(list(chunks.glob("chunk_*.csv")))
    assert 4 <= done < 13 and not (cut_short / "results.csv").exists()
    assert not list(chunks.glob("*.tmp*"))  # nothing half-written is left looking like a chunk

    resumed = sweep_cli(*args, "--out", cut_short, "--resume", "--json")
    summary = json.loads(resumed.stdout)
    assert summary["chunks_resumed"] == done and summary["chunks_computed"] == 13 - done
    assert 0 <= summary["seconds"] <= summary["wall_seconds"]  # the chunks' time within all of it (a user saw 18 s said for a 44 s run)
    assert (cut_short / "results.csv").read_bytes() == (full / "results.csv").read_bytes()


def test_report_renders_in_headless_chromium(twin_sweep, tmp_path):
    from browser import find_or_install_chromium, inspect_page

    browser, reason = find_or_install_chromium()
    if browser is None:
        pytest.skip(reason)
    shot = ROOT / "build" / "test-artifacts" / "sweep_report.png"
    shot.parent.mkdir(parents=True, exist_ok=True)
    result = inspect_page(browser, twin_sweep / "report.html", shot)
    assert len(result["images"]) >= 8  # 7 maps + lobes
    for image in result["images"]:
        assert image["complete"] and image["width"] > 100 and image["height"] > 100, image
    assert result["errors"] == []
    assert shot.stat().st_size > 20_000


def test_a_grid_whose_twin_is_missing_is_named(tmp_path):
    """The grid's twin file missing was reported as the twin's path alone, not the grid that named it."""
    from posedyn.errors import InputError
    from posedyn.io.grid import read_grid

    grid = tmp_path / "grid.toml"
    grid.write_text(GRID.format(twin="nothere.toml"))
    with pytest.raises(InputError) as err:
        read_grid(grid)
    assert err.value.file == str(grid) and err.value.column == "meta.twin" and str(tmp_path / "nothere.toml") in err.value.expected


def test_sweep_workers_run_without_the_profiler():
    """Every sweep worker gets the plugin (`service.sweep.runner._dask`), which stops Dask's 10 ms
    stack sampler, whose profiles nothing reads; fails where a worker still has it."""
    from service.sweep.runner import _dask

    def state(dask_worker):
        return sorted(k for k in dask_worker.periodic_callbacks if k.startswith("profile"))

    with _dask(1, None) as client:
        assert list(client.run(state).values()) == [[]]
