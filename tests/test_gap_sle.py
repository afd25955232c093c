"""Issue 18 item 5: surface location error rows as measured data in the gap workflow.

The campaigns here are written from the physics, not from the library's effect functions: the
true walls are cut by `posedyn.sle` with the cause put where it physically is (a tool of another
radius, with the radial depth it then really cuts; a path offset that also changes the radial
depth; a slow extra mode in the surface normal for the compliance under load; scaled cutting
coefficients in the cut; each tool's farthest tooth at its own clamping phase for runout), plus
CMM-like noise (1 um + 2 %, Gaussian or Student-t with 3 dof). The model's predictions come from
`posedyn gap`'s own baseline (the shipped twin's modes at each pose, the sweep demo's cut).
20 seeds per kind, scored: right verdict in at least 18."""

from __future__ import annotations

import math
from dataclasses import replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from posedyn.dynamics import ToolTipDynamics
from posedyn.gap import Measurements, analyse
from posedyn.io.shipped import SHIPPED_TWIN
from posedyn.sle import SleCut, sle_m
from posedyn.stability import critical_points
from posedyn.table import Mode
from service.gap.baseline import Baseline
from tests.cli_helpers import run_cli

SEEDS = range(20)
KT_PA, KN_PA, HELIX_DEG = 796e6, 169e6, 30.0  # datasets/cuts/sweep_demo_cut.toml


ROOT = Path(__file__).resolve().parents[1]


@lru_cache(maxsize=1)
def BASELINE() -> Baseline:
    return Baseline(twin_file=SHIPPED_TWIN, cut_file=ROOT / "datasets/cuts/sweep_demo_cut.toml")


@lru_cache(maxsize=None)
def design(seed: int, chatter_tests: bool = False) -> tuple[Measurements, np.ndarray]:
    """(campaign rows, the model's predictions): 3 poses x 12 walls, each wall with its own face
    (surface normal x or y), speed, tool (2-4 teeth, 10-16 mm), radial and axial depth, feed per
    tooth and milling direction; with `chatter_tests` also a critical depth per pose (the cut
    file's cut at a random speed)."""
    rng = np.random.default_rng(5000 + seed)
    rows = []
    for p in range(3):
        pose = dict(x_mm=rng.uniform(1300, 1900), y_mm=rng.uniform(-300, 300), z_mm=600.0, beta_deg=rng.uniform(-60, 60))
        for _ in range(12):
            rows.append(dict(pose, pose_id=f"p{p}", quantity="sle_um", direction=str(rng.choice(["x", "y"])), rpm=float(rng.uniform(1500, 12000)),
                             teeth=float(rng.choice([2, 3, 4])), tool_diameter_mm=float(rng.choice([10.0, 12.0, 16.0])),
                             radial_depth_mm=float(rng.choice([0.5, 1.0, 2.0, 3.0])), axial_depth_mm=float(rng.choice([0.5, 1.0, 2.0, 3.0])),
                             feed_per_tooth_mm=float(rng.choice([0.05, 0.1, 0.15, 0.2])), up_milling=float(rng.integers(0, 2))))
        for _ in range(1 if chatter_tests else 0):
            rows.append(dict(pose, pose_id=f"p{p}", quantity="critical_depth_mm", direction="", rpm=float(rng.uniform(2000, 8000))))
    n = len(rows)
    names = {k for r in rows for k in r} - {"pose_id", "direction", "quantity"}
    conditions = {k: np.array([r.get(k, np.nan) for r in rows], dtype=float) for k in sorted(names)}
    m = Measurements(np.array([r["quantity"] for r in rows]), np.zeros(n), np.ones(n), np.array([r["pose_id"] for r in rows]),
                     np.array([r["direction"] for r in rows]), np.full(n, np.nan), conditions)
    model, with_context = BASELINE().predict(m)
    return with_context, model


def true_values(b: Baseline, m: Measurements, kind: str, value: float) -> np.ndarray:
    """The walls as cut, and the chatter limits, with the hidden cause in the physics (module docstring)."""
    modes = b.pose_rows(m)
    out = np.empty(len(m))
    force = 1.0 + value / 100.0 if kind == "cutting" else 1.0
    depth_rows = np.flatnonzero(m.quantity == "critical_depth_mm")
    if len(depth_rows):  # the chatter tests through the stability engine with the true coefficients
        cut = replace(b.cut, kt_pa=b.cut.kt_pa * force, kn_pa=b.cut.kn_pa * force)
        structures = [ToolTipDynamics.from_modes(x=[Mode(*r) for k, r in sorted(modes[str(m.pose_id[i])].items()) if k[0] == "x"],
                                                 y=[Mode(*r) for k, r in sorted(modes[str(m.pose_id[i])].items()) if k[0] == "y"]) for i in depth_rows]
        out[depth_rows] = [r.depth_m * 1e3 for r in critical_points(structures, cut, m.conditions["rpm"][depth_rows], frequencies=False)]
    for i in np.flatnonzero(m.quantity == "sle_um"):
        c = {k: float(v[i]) for k, v in m.conditions.items()}
        rows = modes[str(m.pose_id[i])]
        x = [Mode(*rows[k]) for k in sorted(rows) if k[0] == "x"]
        y = [Mode(*rows[k]) for k in sorted(rows) if k[0] == "y"]
        if kind == "compliance":  # a 3 Hz mode in the surface normal with static compliance `value` um/N
            extra = Mode(3.0, 0.05, 1e6 / value)
            x, y = (x + [extra], y) if m.direction[i] == "x" else (x, y + [extra])
        dyn = ToolTipDynamics.from_modes(x=x, y=y)
        if m.direction[i] == "x":
            dyn = dyn.rotated(-math.pi / 2)
        radius_m = value * 1e-6 if kind == "radius" else 0.0
        speed_mm_min = c["feed_per_tooth_mm"] * c["teeth"] * c["rpm"]
        path_m = value * 1e-6 * speed_mm_min / 1000.0 if kind == "path" else 0.0  # outside the commanded path: less radial depth
        cut = SleCut(int(c["teeth"]), KT_PA * force, KN_PA * force, c["tool_diameter_mm"] * 1e-3 + 2 * radius_m, math.radians(HELIX_DEG),
                     c["radial_depth_mm"] * 1e-3 + radius_m - path_m, c["axial_depth_mm"] * 1e-3, c["feed_per_tooth_mm"] * 1e-3,
                     "up" if c["up_milling"] else "down")
        wall_m = float(sle_m(dyn, cut, c["rpm"])[0]) - radius_m + path_m
        if kind == "runout":  # each tool's farthest tooth at its own clamping phase cuts the wall
            n = int(c["teeth"])
            phase = np.random.default_rng([n, int(c["tool_diameter_mm"])]).uniform(0, 2 * math.pi)
            wall_m -= value * 1e-6 * max(math.cos(phase + 2 * math.pi * j / n) for j in range(n))
        out[i] = wall_m * 1e6
    return out


def campaign(seed: int, kind: str, value: float = 0.0, tails: bool = False, chatter_tests: bool = False):
    """(measured campaign, the model's predictions): walls to 1 um + 2 % (CMM), critical depths to 3 %."""
    m, model = design(seed, chatter_tests)
    truth = true_values(BASELINE(), m, kind, value)
    rng = np.random.default_rng([seed, 7])
    std = np.where(m.quantity == "sle_um", 1.0 + 0.02 * np.abs(truth), 0.03 * np.abs(truth))
    noise = rng.standard_t(3.0, len(m)) if tails else rng.standard_normal(len(m))
    return replace(m, value=truth + noise * std, std=std), model


def verdicts(kind, value=0.0, tails=False, chatter_tests=False) -> list:
    return [analyse(*campaign(seed, kind, value, tails, chatter_tests)) for seed in SEEDS]


def only(result, name: str) -> float | None:
    """The parameter of `name` when it is the one effect named, else None."""
    if len(result.effects) != 1 or result.effects[0]["name"] != name or result.ambiguous:
        return None
    return next(iter(result.effects[0]["parameters"].values()))


def test_the_model_sle_of_a_row_is_posedyn_sle_at_the_pose():
    """The baseline's SLE rows are `sle_m` on the pose's x-y modes (x face: turned as `posedyn sle
    --direction x`) with the row's tool and cut; an extra static compliance dC moves it by dC F_0
    (the row's model_sle_mean_force_n)."""
    m, model = design(0)
    truth = true_values(BASELINE(), m, "none", 0.0)
    assert np.allclose(model, truth, rtol=1e-12, atol=1e-9)
    extra = true_values(BASELINE(), m, "compliance", 0.4) - truth
    assert np.allclose(extra, 0.4 * m.conditions["model_sle_mean_force_n"], rtol=0.01, atol=0.02)


@pytest.mark.parametrize("tails", [False, True])
def test_nothing_hidden_no_claim(tails):
    results = verdicts("none", tails=tails)
    assert sum(not r.effects and not r.ambiguous and r.explained for r in results) >= 18


def test_a_tool_radius_error_is_named_within_ten_percent_under_heavy_tailed_noise():
    """A tool 10 um smaller in radius than nominal (it also cuts 10 um less radial depth)."""
    values = [only(r, "tool_radius_error") for r in verdicts("radius", -10.0, tails=True)]
    assert sum(v is not None and abs(v + 10.0) <= 1.0 for v in values) >= 18, values


def test_a_path_following_offset_is_named_within_ten_percent():
    """Seed 001 Table 2's size: 4 um per m/min of feed, outside the commanded path."""
    values = [only(r, "path_following_offset") for r in verdicts("path", 4.0)]
    assert sum(v is not None and abs(v - 4.0) <= 0.4 for v in values) >= 18, values


def test_a_compliance_under_load_is_named_within_ten_percent():
    """0.5 um/N more static compliance than the impact-test modes (a 3 Hz mode in the surface normal)."""
    values = [only(r, "load_compliance") for r in verdicts("compliance", 0.5)]
    assert sum(v is not None and abs(v - 0.5) <= 0.05 for v in values) >= 18, values


def test_cutting_coefficients_are_named_within_ten_percent_from_walls_and_chatter_tests():
    """k_t and k_n 25 % above the cut file's: every wall's SLE scales by 1.25 and every critical
    depth (here from the engine with the true coefficients) by about 1 / 1.25. Walls alone leave
    it close to compliance under load on a robot whose static deflection dominates the SLE (then
    undecided between the two, or named: never another effect); with a chatter test per pose it
    is named within 10 %."""
    walls = verdicts("cutting", 25.0)
    assert all(only(r, "cutting_coefficient_error") is not None or
               (not r.effects and sorted(r.ambiguous[0]["candidates"]) == ["cutting_coefficient_error", "load_compliance"]) for r in walls)
    values = [only(r, "cutting_coefficient_error") for r in verdicts("cutting", 25.0, chatter_tests=True)]
    assert sum(v is not None and abs(v - 25.0) <= 2.5 for v in values) >= 18, values


def test_runout_is_named_as_runout():
    """15 um runout, each tool at its own clamping phase (the library's form takes the expected
    farthest reach over phases, so the fit is approximate and need not explain every wall)."""
    values = [only(r, "spindle_runout") for r in verdicts("runout", 15.0)]
    assert sum(v is not None and 9.0 <= v <= 18.0 for v in values) >= 18, values


def test_the_shipped_wall_campaign_from_the_independent_geometric_simulation():
    """datasets/campaigns/sle_walls.csv (tests/make_sle_walls.py): 32 walls cut by the geometric
    simulation written blind to posedyn.sle (geometric engagement, regenerative chip, the wall as
    the envelope of the edge paths), with a path offset of 4 um per m/min and a tool 6 um under
    its radius hidden, on the twin's modal tables (all six robot modes). With the SLE's geometric
    engagement (datasets/cuts/walls_geometric_cut.toml): both named, each within 2 reported stds
    of the truth, nothing else, and the residual at the stated noise (README walk-through). With
    seed 001's fixed angles the deflected engagement (2-9 % of the larger walls, up to 9 um of 98)
    hides the radius error: the path offset alone is named and the rest is said to be
    unexplained, not passed as noise."""
    from posedyn.io.measurements import read_measurements

    walls = read_measurements(ROOT / "datasets/campaigns/sle_walls.csv")
    geometric = Baseline(twin_file=SHIPPED_TWIN, cut_file=ROOT / "datasets/cuts/walls_geometric_cut.toml")
    model, m = geometric.predict(walls)
    r = analyse(m, model)
    got = {e["name"]: (next(iter(e["parameters"].values())), next(iter(e["parameter_std"].values()))) for e in r.effects}
    assert sorted(got) == ["path_following_offset", "tool_radius_error"] and r.explained and not r.ambiguous
    assert abs(got["path_following_offset"][0] - 4.0) <= 2 * got["path_following_offset"][1]
    assert abs(got["tool_radius_error"][0] + 6.0) <= 2 * got["tool_radius_error"][1]
    assert r.rmse_before > 5 and r.rmse_after < 1.2

    model, m = BASELINE().predict(walls)  # the fixed angles
    r = analyse(m, model)
    got = {e["name"]: (next(iter(e["parameters"].values())), next(iter(e["parameter_std"].values()))) for e in r.effects}
    assert sorted(got) == ["path_following_offset"] and not r.explained and not r.ambiguous and r.rmse_after > 2


def test_gap_writes_the_cut_with_the_named_cutting_and_tool_effects(tmp_path):
    """`posedyn gap --out DIR` on the wall campaign writes DIR/cut.toml: the cut file with its SLE
    offset grown by exactly the named effects at the file's own cut (minus the radius error, the
    path offset at its feed speed), which `posedyn sweep` adds to its SLE; the coefficients
    untouched. A named cutting-coefficient error scales k_t and k_n instead."""
    import json
    from types import SimpleNamespace

    from posedyn.io.cut import read_cut, read_sle_cut
    from service.cli.gap import _write_updated_cut

    cut_file = ROOT / "datasets/cuts/walls_geometric_cut.toml"
    done = run_cli("gap", "--measured", str(ROOT / "datasets/campaigns/sle_walls.csv"), "--twin",
                           "--cut", str(cut_file), "--out", str(tmp_path / "gap"), "--json")
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout)
    fitted = {e["name"]: next(iter(e["parameters"].values())) for e in doc["effects"]}
    assert doc["updated_cut"] == str(tmp_path / "gap/cut.toml")
    before, after = read_sle_cut(cut_file), read_sle_cut(tmp_path / "gap/cut.toml")
    speed_m_min = 0.05 * 3 * 2000.0 / 1000.0  # the file's feed per tooth x teeth x rpm
    assert after[0] == before[0] and read_cut(tmp_path / "gap/cut.toml") == read_cut(cut_file)
    assert after[1] * 1e6 == pytest.approx(before[1] * 1e6 - fitted["tool_radius_error"] + fitted["path_following_offset"] * speed_m_min, rel=1e-12)
    assert after[0].engagement == "geometric"  # the updated cut keeps the file's engagement

    result = SimpleNamespace(effects=[{"name": "tool_radius_error", "parameters": {"radius_error_um": -6.0}},
                                      {"name": "path_following_offset", "parameters": {"offset_um_per_m_per_min": 4.0}}])
    (tmp_path / "both").mkdir()
    written = _write_updated_cut(tmp_path / "both", result, cut_file, Path("meas.csv"))
    assert read_sle_cut(written)[1] * 1e6 == pytest.approx(before[1] * 1e6 + 6.0 + 4.0 * speed_m_min, rel=1e-12)

    result = SimpleNamespace(effects=[{"name": "cutting_coefficient_error", "parameters": {"force_error_pct": 25.0}}])
    written = _write_updated_cut(tmp_path, result, cut_file, Path("meas.csv"))
    cut, nominal = read_cut(written)[0], read_cut(cut_file)[0]
    assert cut.kt_pa == pytest.approx(1.25 * nominal.kt_pa, rel=1e-12) and cut.kn_pa == pytest.approx(1.25 * nominal.kn_pa, rel=1e-12)
    assert read_sle_cut(written)[1] == 0.0


def test_a_bad_campaign_row_is_named_by_file_and_line(tmp_path):
    """A row the baseline refuses (up_milling 0.5) is named by the campaign file, its row and line
    and the column, as the reader's own errors are; and a number reads as written (-1.3, not
    np.float64(-1.3))."""
    header = "pose_id,x_mm,y_mm,z_mm,beta_deg,quantity,direction,mode,value,std,rpm,teeth,tool_diameter_mm,radial_depth_mm,axial_depth_mm,feed_per_tooth_mm,up_milling"
    row = "front,1450.0,-150.0,600.0,-30.0,sle_um,x,,17.651,{std},3000.0,4,12.7,1.0,2.0,0.15,{up}"
    cut = ROOT / "datasets/cuts/sweep_demo_cut.toml"
    campaign = tmp_path / "walls.csv"
    for std, up, expected in (("1.3", "0.5", "row 2 (line 3), column 'up_milling': expected up_milling 0 (down milling) or 1 (up milling), got 0.5"),
                              ("-1.3", "0", "row 2 (line 3), column 'std': expected std > 0, got -1.3")):
        campaign.write_text("\n".join([header, row.format(std="1.3", up="0"), row.format(std=std, up=up)]) + "\n")
        done = run_cli("gap", "--measured", campaign, "--twin", "--cut", cut, "--out", tmp_path / "gap")
        assert done.returncode == 2 and done.stderr.strip() == f"error: {campaign}, {expected}"
        assert not (tmp_path / "gap").exists()
