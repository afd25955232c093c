"""Issue 18, honest statistics: the gap workflow on campaigns it did not generate. The data here
are made without the library's effect functions (other functional forms of the same physics,
Student-t noise, noise larger than stated, conditions that vary together, an effect outside the
library), 20 seeds per kind, and scored: right verdict in at least 18 of 20."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from posedyn.gap import Measurements, analyse, fit_noise
from tests.cli_helpers import run_cli

SEEDS = range(20)
FN_STD, K_STD = 0.003, 0.03  # stated relative std of fn and k (an impact test's)


def campaign(seed: int, kind: str) -> tuple[Measurements, np.ndarray]:
    """(measurements, the model's predictions): 12 poses, two robot modes each, fn and k rows
    under random conditions (device mounted, force level, robot moving), the hidden cause of
    `kind` written here from the physics."""
    rng = np.random.default_rng(1000 + seed)
    rows = []
    for p in range(12):
        x_mm, y_mm, beta = rng.uniform(1300, 1900), rng.uniform(-300, 300), rng.uniform(-60, 60)
        for mode, direction in ((1, "x"), (2, "y")):
            fn, k = rng.uniform(10.0, 20.0), 10 ** rng.uniform(6.0, 7.0)
            for quantity, count in (("fn_hz", 4), ("k_n_per_m", 2)):
                for _ in range(count):
                    force = float(rng.choice([0.0, 400.0, 800.0, 1200.0]))
                    device = float(rng.integers(0, 2)) if kind != "confounded" else float(force >= 800.0)
                    rows.append(dict(pose_id=f"p{p}", direction=direction, mode=mode, quantity=quantity, fn=fn, k=k, x_mm=x_mm, y_mm=y_mm,
                                     beta_deg=beta, force_n=force, device=device, moving=float(rng.integers(0, 2))))
    n = len(rows)
    col = {key: np.array([r[key] for r in rows]) for key in rows[0]}
    fn, k, q = col["fn"], col["k"], col["quantity"]
    model = np.where(q == "fn_hz", fn, k)
    true_fn, true_k = fn.copy(), k.copy()
    if kind in ("device", "confounded"):  # 8 kg on the tool: fn = sqrt(k / (m + M)) / 2 pi, k unchanged
        mass = k / (2 * math.pi * fn) ** 2
        true_fn = np.sqrt(k / (mass + 8.0 * col["device"])) / (2 * math.pi)
    if kind == "softening_t":  # joint softening k / (1 + F / 3 kN): another form than the library's k (1 - a F)
        true_k = k / (1.0 + col["force_n"] / 3000.0)
        true_fn = fn / np.sqrt(1.0 + col["force_n"] / 3000.0)
    if kind == "outside":  # the real robot stiffer towards the front: no library effect follows x
        true_fn = fn * (1.0 + 0.03 * (col["x_mm"] - 1600.0) / 300.0)
    truth = np.where(q == "fn_hz", true_fn, true_k)
    std = np.where(q == "fn_hz", FN_STD, K_STD) * np.abs(truth)
    if kind in ("student_t", "softening_t"):
        noise = rng.standard_t(3.0, n)
    elif kind == "wide":
        noise = 1.7 * rng.standard_normal(n)
    else:
        noise = rng.standard_normal(n)
    conditions = {c: col[c].astype(float) for c in ("x_mm", "y_mm", "beta_deg", "force_n", "device", "moving")}
    conditions["model_k_n_per_m"] = k
    m = Measurements(q.astype(str), truth + noise * std, std, col["pose_id"].astype(str), col["direction"].astype(str), col["mode"], conditions)
    return m, model


def named(result) -> list[str]:
    return sorted(e["name"] for e in result.effects)


def score(kind: str, right) -> int:
    return sum(bool(right(analyse(*campaign(seed, kind)))) for seed in SEEDS)


def test_noise_of_the_stated_std_no_claim():
    assert score("noise", lambda r: not named(r) and not r.ambiguous and r.noise["model"] == "stated") >= 18


def test_noise_larger_than_stated_is_reported_not_explained_by_an_effect():
    """Real noise 1.7 x the stated std, nothing hidden: no effect, and the stated std is said to
    look too small by about 1.7."""
    def right(r):
        return not named(r) and r.noise["model"] == "scaled" and 1.45 < r.noise["scale"] < 1.95 and "too small" in r.noise["verdict"]

    assert score("wide", right) >= 18


def test_heavy_tailed_noise_is_reported_not_read_as_an_effect():
    """Student-t noise (3 degrees of freedom) with a random `moving` column: no spurious effect,
    and the noise is not reported as the stated one (Student-t in 19 of 20 seeds, once Gaussian
    1.4 x)."""
    assert score("student_t", lambda r: not named(r) and r.noise["model"] != "stated") >= 18


def test_force_softening_of_another_form_under_heavy_tailed_noise_is_named_alone():
    """k / (1 + F / 3 kN) with Student-t noise: `force_level_stiffness` (the library's linear
    form) and nothing else, no `moving_robot` from the outliers."""
    assert score("softening_t", lambda r: named(r) == ["force_level_stiffness"]) >= 18


def test_device_mass_is_named_and_estimated_within_ten_percent():
    def right(r):
        return named(r) == ["device_mass"] and abs(r.effects[0]["parameters"]["mass_kg"] - 8.0) <= 0.8

    assert score("device", right) >= 18


def test_a_device_mounted_only_at_high_force_is_undecided_not_claimed():
    """The design itself ties the device to the force level: device mass and force softening are
    reported as undecided, with the measurement that separates them."""
    def right(r):
        return not named(r) and r.ambiguous and sorted(r.ambiguous[0]["candidates"]) == ["device_mass", "force_level_stiffness"]

    assert score("confounded", right) >= 18


def mrf_campaign(seed: int) -> tuple[Measurements, np.ndarray]:
    """Absorber frequency rows at random field, temperature (15-45 C) and angle to gravity; the
    fluid's modulus falls as exp(-a (T - 20 C)), a = 3e-3 / K, from the model's value at 20 C."""
    rng = np.random.default_rng(500 + seed)
    n = 48
    field, temperature = rng.choice([0.0, 100.0, 200.0, 300.0, 400.0, 500.0], n), rng.uniform(15.0, 45.0, n)
    model = 20.0 + 0.08 * field
    truth = model * np.sqrt(np.exp(-3e-3 * (temperature - 20.0)))
    std = 0.005 * truth
    conditions = {"field_mt": field, "temperature_c": temperature, "absorber_angle_deg": rng.choice([0.0, 45.0, 90.0], n)}
    m = Measurements(np.full(n, "absorber_fn_hz"), truth + rng.standard_normal(n) * std, std, np.full(n, "absorber"), np.full(n, ""), np.full(n, np.nan), conditions)
    return m, model


def test_an_mrf_temperature_law_with_another_reference_is_named_with_its_reference():
    """exp(-a (T - 20 C)) where the library's model holds at 25 C: the law's reference temperature
    is a parameter, so the drift is named alone (no absorber_gravity_stiffness for the offset),
    a within 10 %, the reference within 2 C, and the residual brought to the stated noise."""
    def right(r):
        if named(r) != ["mrf_temperature_drift"]:
            return False
        p = r.effects[0]["parameters"]
        return abs(p["modulus_drop_per_mk"] - 3.0) <= 0.3 and abs(p["reference_c"] - 20.0) <= 2.0 and r.rmse_after <= 1.5

    assert sum(bool(right(analyse(*mrf_campaign(seed)))) for seed in SEEDS) >= 18


def test_an_effect_outside_the_library_is_unexplained_and_located():
    """fn growing 3 % per 300 mm of x (10 stated stds): nothing claimed, x_mm among the residual's
    correlates, and the smooth discrepancy map runs along x first, rising by more than 12 stds
    across the workspace (the truth: 20)."""
    def right(r):
        d = r.discrepancy
        if d is None or list(d.axes)[0] != "x_mm":
            return False
        along_x = d.mean.mean(axis=tuple(range(1, d.mean.ndim)))
        return not named(r) and not r.explained and any(c["variable"] == "x_mm" for c in r.correlates) and along_x[-1] - along_x[0] > 12.0

    assert score("outside", right) >= 18


@pytest.mark.parametrize("dof", [3.0, 10.0])
def test_fit_noise_recovers_the_scale_and_the_tails(dof):
    r = 1.5 * np.random.default_rng(7).standard_t(dof, 2000)
    noise = fit_noise(r)
    assert noise.model == "student_t" and noise.scale == pytest.approx(1.5, rel=0.1) and noise.dof == pytest.approx(dof, rel=0.5)
    assert fit_noise(np.random.default_rng(8).standard_normal(300)).model == "stated"


def twin_campaign(seed: int, mass_kg: float = 0.0, joint_scale=(1.0,) * 6, gravity_per_knm: float = 0.0, sensor_kg: float = 0.0):
    """fn and k rows of a twin campaign in which the real cell differs from the twin: a device of
    `mass_kg` on the flange in the `device` = 1 rows, joint stiffnesses scaled by `joint_scale`,
    and/or each joint softer under the gravity torque it carries, k / (1 + c |tau|), tau from
    pinocchio's generalized gravity here (the twin's own physics: its modes recomputed, so fn and
    the modal stiffness both change, differently per pose), stated noise; with the baseline (the
    nominal twin)."""
    from dataclasses import replace

    import pinocchio as pin

    from posedyn.robot import direction_rows
    from posedyn.robot.twin import twin_modes
    from service.gap.baseline import Baseline, campaign_design

    root = Path(__file__).resolve().parents[1]
    nominal = Baseline(twin_file=root / "datasets/robots/kr_r2700_twin.toml")
    real = Baseline(twin_file=root / "datasets/robots/kr_r2700_twin.toml")
    real.params = real.params.scaled(joint_scale)
    design = campaign_design(seed)
    design = design.take(np.flatnonzero(np.isin(design.quantity, ("fn_hz", "k_n_per_m"))))
    first_spindle = nominal.params.robot_modes_per_direction + 1  # the modal tables number the spindle modes after the robot's
    if sensor_kg:  # the impact tests also read the first spindle mode of x and y, where a sensor's mass shows
        spindle = design.take(np.flatnonzero(design.quantity == "fn_hz"))
        design = replace(design, quantity=np.concatenate([design.quantity, spindle.quantity]), value=np.concatenate([design.value, spindle.value]),
                         std=np.concatenate([design.std, spindle.std]), pose_id=np.concatenate([design.pose_id, spindle.pose_id]),
                         direction=np.concatenate([design.direction, spindle.direction]), mode=np.concatenate([design.mode, np.full(len(spindle), float(first_spindle))]),
                         conditions={c: np.concatenate([v, spindle.conditions[c]]) for c, v in design.conditions.items()})
    y, m = nominal.predict(design)
    truth, _ = real.predict(design)
    if mass_kg:
        real.params = replace(real.params, flange_mass_kg=mass_kg)
        with_device, _ = real.predict(design)
        truth = np.where(m.conditions["device"] > 0.5, with_device, truth)
    if sensor_kg:  # the robot modes through the twin's mass matrix; each spindle mode by its own modal mass: fn sqrt(m / (m + m_s)), m = k / w^2
        real.params = replace(real.params, tip_mass_kg=sensor_kg)
        robot_rows, _ = real.predict(design)
        spindle = m.mode == first_spindle
        modal_mass = m.conditions["model_k_n_per_m"] / (2 * np.pi * np.where(m.quantity == "fn_hz", y, np.nan)) ** 2
        truth = np.where(spindle, np.where(m.quantity == "fn_hz", y * np.sqrt(modal_mass / (modal_mass + sensor_kg)), truth), robot_rows)
    if gravity_per_knm:
        robot, params = real.twin()
        data = robot.model.createData()
        for i in range(len(truth)):
            q = np.array([m.conditions[f"model_q{j}_rad"][i] for j in range(1, 7)])
            softer = params.scaled(1.0 / (1.0 + gravity_per_knm * np.abs(pin.computeGeneralizedGravity(robot.model, data, q)) / 1000.0))
            rows = direction_rows(twin_modes(robot, q, softer), str(m.direction[i]), params.robot_modes_per_direction)
            truth[i] = rows[int(m.mode[i]) - 1][0 if m.quantity[i] == "fn_hz" else 2]
    std = np.where(m.quantity == "fn_hz", FN_STD, K_STD) * np.abs(truth)
    m = replace(m, value=truth + np.random.default_rng(seed).standard_normal(len(y)) * std, std=std)
    return nominal, m, y


def flange_campaign(seed: int, mass_kg: float = 7.0):
    return twin_campaign(seed, mass_kg=mass_kg)


def test_a_device_on_the_flange_is_named_through_the_twin():
    """A 7 kg device in the twin itself (fn and modal stiffness change together, differently per
    pose): the twin-level candidate `flange_device` is named alone with the mass within 10 % and
    the residual brought to the stated noise; the library's surrogate (fn / sqrt(1 + M / m_r), k
    unchanged) could not explain it (RMS after > 2)."""
    from posedyn.gap import LIBRARY

    right, surrogate_fails = 0, 0
    for seed in range(2):
        nominal, m, y = flange_campaign(seed)
        r = analyse(m, y, library=nominal.library())
        right += named(r) == ["flange_device"] and abs(r.effects[0]["parameters"]["mass_kg"] - 7.0) <= 0.7 and r.rmse_after <= 1.5 and r.explained
        surrogate_fails += analyse(m, y, library=LIBRARY).rmse_after > 2.0
    assert right == 2 and surrogate_fails == 2


def test_gap_cli_writes_the_twin_with_the_named_effects(tmp_path):
    """The most common twin error, and a device: the real robot's axis 2 is 30 % softer and axis 3
    25 % stiffer than the twin, and it carries a 7 kg device in the device = 1 rows. The
    pose-following candidates (a joint's stiffness in the twin, the modes recomputed at every
    pose) are selected on the fn rows first (continuous in the stiffness; the modal stiffness of a
    mode numbered by frequency rank jumps where modes cross), then the device: all three named
    (joints within 2 %, mass within 10 %), the residual at the stated noise. `posedyn gap --twin
    --out DIR` writes DIR/twin.toml, the twin with the fitted joint factors and flange mass
    (provenance in its comment), whose modes at a pose are those of the nominal twin changed by
    exactly those; the gap on held-out rows shrinks 100-fold."""
    import json
    from dataclasses import replace

    from posedyn.io.measurements import format_measurements
    from posedyn.io.twin_file import load_twin
    from posedyn.robot import GridPose, pose_modes, tool_pose
    from service.gap.baseline import campaign_poses

    nominal, m, y = twin_campaign(3, mass_kg=7.0, joint_scale=(1.0, 0.7, 1.25, 1.0, 1.0, 1.0))
    measured = tmp_path / "meas.csv"
    measured.write_text(format_measurements(m, [c for c in m.conditions if not c.startswith("model_")]))
    done = run_cli("gap", "--measured", str(measured), "--twin", "--out", str(tmp_path / "gap"), "--json")
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout)
    fitted = {e["name"]: list(e["parameters"].values())[0] for e in doc["effects"]}
    assert sorted(fitted) == ["flange_device", "joint_stiffness_a2", "joint_stiffness_a3"] and doc["explained"]
    assert fitted["flange_device"] == pytest.approx(7.0, rel=0.1) and 2 ** fitted["joint_stiffness_a2"] == pytest.approx(0.7, rel=0.02)
    assert 2 ** fitted["joint_stiffness_a3"] == pytest.approx(1.25, rel=0.02) and doc["rmse_after"] <= 1.5
    assert doc["held_out_chi2_per_row"]["after"] < 0.01 * doc["held_out_chi2_per_row"]["before"]
    text = (tmp_path / "gap/twin.toml").read_text()
    assert doc["updated_model"] == str(tmp_path / "gap/twin.toml") and "flange_device: mass_kg" in text and "joint_stiffness_a3: stiffness x" in text
    robot, updated = load_twin(tmp_path / "gap/twin.toml")
    scale = [1.0, 2 ** fitted["joint_stiffness_a2"], 2 ** fitted["joint_stiffness_a3"], 1.0, 1.0, 1.0]
    want_params = replace(nominal.params.scaled(scale), flange_mass_kg=fitted["flange_device"])
    assert updated.flange_mass_kg == pytest.approx(fitted["flange_device"], rel=1e-12)
    assert np.allclose(updated.joint_stiffness_nm_per_rad, want_params.joint_stiffness_nm_per_rad, rtol=1e-12)
    pose = GridPose("p0", tool_pose(campaign_poses(m, [0]), 0))
    _, got = pose_modes(robot, pose, updated)
    _, want = pose_modes(nominal.twin()[0], pose, want_params)
    assert np.allclose(got.fn_hz, want.fn_hz, rtol=1e-12) and np.allclose(np.abs(got.tip_shapes), np.abs(want.tip_shapes), rtol=1e-9)
    # the updated twin in `posedyn schedule --twin`: scheduled on the nominal twin's modes with
    # exactly the named effects' parameters changed (the modes it reports equal the twin's own
    # with the fitted values, computed here), and not the nominal twin's schedule
    from posedyn.io import read_pose_table
    from posedyn.robot import direction_rows
    from posedyn.robot.twin import twin_modes

    root = Path(__file__).resolve().parents[1]
    poses = tmp_path / "poses.csv"
    poses.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nb,1800,200,600,40\n")
    runs = {}
    for name, twin_file in (("nominal", root / "datasets/robots/kr_r2700_twin.toml"), ("updated", tmp_path / "gap/twin.toml")):
        done = run_cli("schedule", "--twin", str(twin_file), "--poses", str(poses),
                       "--cut", str(root / "datasets/seeds/hou2023_cut.toml"), "--json")
        assert done.returncode == 0, done.stderr
        runs[name] = json.loads(done.stdout)[0]
    q = robot.inverse(tool_pose(read_pose_table(poses), 0))
    modes = twin_modes(robot, q, want_params)
    want = {(d, j): row for d in ("x", "y", "z") for j, row in enumerate(direction_rows(modes, d, want_params.robot_modes_per_direction), 1)}
    for row in runs["updated"]["modes"]:
        fn, _, k = want[(row["direction"], row["mode"])]
        assert row["fn_hz"] == pytest.approx(fn, rel=1e-9) and row["k_n_per_m"] == pytest.approx(k, rel=1e-9)
    changes = [abs(runs["updated"][k] / runs["nominal"][k] - 1.0) for k in ("critical_depth_mm", "dominant_chatter_hz", "critical_depth_with_absorber_mm")]
    assert max(changes) > 0.01, changes


def test_two_joints_the_fn_rows_cannot_tell_apart_get_the_pose_to_measure_next():
    """Where two changed twins fit a campaign alike, the workflow names the pose and mode where
    they differ most (a 5 x 5 x 5 search over the campaign's x, y, beta box): there the two
    predictions are further apart than at any pose the campaign measured, and by the amount the
    text states (checked here with the twin directly)."""
    import math
    import re

    from posedyn.gap.twin_candidates import updated_twin
    from posedyn.robot import ToolPose, direction_rows
    from posedyn.robot.twin import twin_modes

    nominal, m, _ = twin_campaign(0)
    robot, params = nominal.twin()
    a, b = {"joint_stiffness_a2": math.log2(0.8)}, {"joint_stiffness_a3": math.log2(1.3)}
    text = nominal.library()["joint_stiffness_a2"].separate(m, a, b)
    d, j, x, y, z, beta, fa, fb = re.match(
        r"measure fn of (\w) mode (\d) at x (\S+) mm, y (\S+) mm, z (\S+) mm, beta (\S+) deg: (\S+) Hz with .*, (\S+) Hz with", text).groups()

    def fn(q, values):
        modes = twin_modes(robot, q, updated_twin(params, values))
        return {(dd, jj): row[0] for dd in ("x", "y") for jj, row in enumerate(direction_rows(modes, dd, params.robot_modes_per_direction), 1)}

    q = robot.inverse(ToolPose.from_beta(float(x) * 1e-3, float(y) * 1e-3, float(z) * 1e-3, math.radians(float(beta))))
    there = fn(q, a)[(d, int(j))], fn(q, b)[(d, int(j))]
    assert there == pytest.approx((float(fa), float(fb)), rel=2e-3, abs=2e-3)  # x, y, beta printed rounded
    gap = abs(there[0] / there[1] - 1.0)
    for p in set(m.pose_id):
        i = np.flatnonzero(m.pose_id == p)[0]
        qp = np.array([m.conditions[f"model_q{k}_rad"][i] for k in range(1, 7)])
        fa_p, fb_p = fn(qp, a), fn(qp, b)
        assert all(abs(fa_p[k] / fb_p[k] - 1.0) < gap for k in fa_p.keys() & fb_p.keys())


def test_a_physics_model_gets_the_named_twin_effects_written_into_its_prior(tmp_path):
    """`posedyn gap --model MODEL_DIR --out DIR` with twin effects named writes DIR/model: the
    physics model with its prior twin changed (joint factor, flange mass) and everything learned
    kept, so its fn and k predictions move by exactly the changed/nominal twin ratio with which
    the candidates corrected the model in the fit (zeta untouched); the model's cut comes along,
    and the record names what was added."""
    import math
    from dataclasses import replace
    from types import SimpleNamespace

    from posedyn.io import read_modal_table
    from posedyn.io.model_dir import load_model, save_model
    from posedyn.io.twin_file import load_twin
    from posedyn.posemodel import PoseModel
    from posedyn.robot import direction_rows
    from posedyn.robot.twin import twin_modes
    from service.cli.gap import _write_updated_model
    from service.gap.baseline import Baseline

    root = Path(__file__).resolve().parents[1]
    table = read_modal_table(root / "datasets/campaigns/seed003_twin_s1.csv")
    model = PoseModel("physics", twin=load_twin()).fit(table.select_poses(list(range(0, 112, 7))))
    save_model(model, tmp_path / "m")
    (tmp_path / "m/cut.toml").write_text((root / "datasets/seeds/hou2023_cut.toml").read_text())
    effects = [{"name": "flange_device", "parameters": {"mass_kg": 7.0}, "parameter_std": {"mass_kg": 0.2}},
               {"name": "joint_stiffness_a2", "parameters": {"log2_factor": math.log2(0.8)}, "parameter_std": {"log2_factor": 0.01}}]
    written = _write_updated_model(tmp_path / "gap", SimpleNamespace(effects=effects), None, tmp_path / "m", Path("meas.csv"))
    assert written == str(tmp_path / "gap/model") and (tmp_path / "gap/model/cut.toml").exists()
    updated = load_model(written)
    assert "flange_device: mass_kg = 7" in updated.physics_["gap_effects"][0]

    poses = table.poses.subset([3, 50, 101])
    before, after = load_model(tmp_path / "m").predict_table(poses), updated.predict_table(poses)
    robot, nominal = Baseline(model_dir=tmp_path / "m").twin()
    changed = replace(nominal.scaled([1.0, 0.8, 1.0, 1.0, 1.0, 1.0]), flange_mass_kg=nominal.flange_mass_kg + 7.0)
    q = np.radians(poses.joints_deg)
    for p in range(len(poses)):
        ratio = {}
        for params, name in ((nominal, "nominal"), (changed, "changed")):
            modes = twin_modes(robot, q[p], params)
            ratio[name] = {(d, j): row for d in ("x", "y", "z") for j, row in enumerate(direction_rows(modes, d, nominal.robot_modes_per_direction), 1)}
        for r in np.flatnonzero(before.pose_index == p):
            key = (str(before.direction[r]), int(before.mode[r]))
            assert after.fn_hz[r] == pytest.approx(before.fn_hz[r] * ratio["changed"][key][0] / ratio["nominal"][key][0], rel=1e-9)
            assert after.k_n_per_m[r] == pytest.approx(before.k_n_per_m[r] * ratio["changed"][key][2] / ratio["nominal"][key][2], rel=1e-9)
            assert after.zeta[r] == before.zeta[r]


def test_joints_softer_under_gravity_are_named_through_the_twin(tmp_path):
    """Each joint of the real robot k / (1 + 0.1 |tau_g| / 1 kN m) under the gravity torque it
    carries (computed here with pinocchio): `gravity_softening` named alone within 10 %, the
    residual at the stated noise; the twin file written with it reads back the same law."""
    from dataclasses import replace

    from posedyn.gap.twin_candidates import updated_twin
    from posedyn.io.twin_file import load_twin, read_twin, write_twin

    nominal, m, y = twin_campaign(0, gravity_per_knm=0.1)
    r = analyse(m, y, library=nominal.library())
    assert named(r) == ["gravity_softening"] and abs(r.effects[0]["parameters"]["softening_per_knm"] - 0.1) <= 0.01 and r.rmse_after <= 1.5
    root = Path(__file__).resolve().parents[1]
    spec = read_twin(root / "datasets/robots/kr_r2700_twin.toml")
    write_twin(tmp_path / "twin.toml", replace(spec, params=updated_twin(spec.params, {"gravity_softening": 0.1})), source="test")
    assert load_twin(tmp_path / "twin.toml")[1].gravity_softening_per_knm == 0.1


def test_a_sensor_on_the_tool_tip_is_named_and_not_written_into_the_machining_twin(tmp_path):
    """0.2 kg of accelerometer at the tool tip in every impact test (the first spindle mode,
    about 1 kg of modal mass, reads 10 % low, written here from its modal mass; the robot modes
    barely notice, through the twin's mass matrix): `sensor_mass`
    named alone within 10 %, and the twin written out leaves it out (the robot that machines
    does not carry it)."""
    from types import SimpleNamespace

    from service.cli.gap import _write_updated_model

    nominal, m, y = twin_campaign(0, sensor_kg=0.2)
    r = analyse(m, y, library=nominal.library())
    assert named(r) == ["sensor_mass"] and abs(r.effects[0]["parameters"]["mass_kg"] - 0.2) <= 0.02 and r.rmse_after <= 1.5
    root = Path(__file__).resolve().parents[1]
    result = SimpleNamespace(effects=[dict(r.effects[0], parameter_std={"mass_kg": 0.01})])
    assert _write_updated_model(tmp_path, result, root / "datasets/robots/kr_r2700_twin.toml", None, Path("meas.csv")) is None
