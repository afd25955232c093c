"""The absorber on the structure: coupling, schedules, and the time-domain proof at seed 004's
position 5; the absorber and schedule CLIs."""

import json
import math

import numpy as np
import pytest

from absorber.coupling import with_absorber
from dataclasses import replace

from absorber.chain import ScheduleConfig, coupled, schedule_poses, table_pose_modes
from absorber.tuning import Tuning
from posedyn.dynamics import ToolTipDynamics
from posedyn.io import read_modal_table
from posedyn.io.cut import read_cut

from posedyn.stability import Cut, critical_points
from posedyn.stability.timesim import simulate
from posedyn.table import Mode
from tests.cli_helpers import run_cli


def test_coupled_structure_reproduces_the_tmd_receptance():
    """Host mode plus an absorber coordinate (non-proportional damping) gives exactly the
    closed-form host receptance with a TMD, K G = 1 / (s^2 + 2 zeta s + 1 + mu s^2 Z / (mu s^2 + Z))."""
    fn, k, zeta = 129.29, 1.34e7, 0.0134
    host = ToolTipDynamics.from_modes(y=[Mode(fn, zeta, k)])
    mass = k / (2 * math.pi * fn) ** 2
    mu, gamma, zeta_a = 0.0055, 1.03, 0.047
    structure = with_absorber(host, mu * mass, mu * mass * (gamma * 2 * math.pi * fn) ** 2, zeta_a, directions=("y",))
    lam = np.linspace(0.8, 1.2, 41)
    G = structure.frf(lam * 2 * math.pi * fn)[:, 1, 1] * k
    assert np.allclose(G, Tuning("tmd", mu, gamma, zeta_a).receptance(lam, zeta), rtol=1e-10)


def test_an_absorber_damper_across_a_light_spindle_mode_is_a_valid_structure():
    """5 kg at 40 Hz with zeta 0.2 (1005 N s/m) on a tool whose 6 kHz mode has 2.2 g of modal
    mass: the damping matrix's diagonal is 1.4x critical for that mode, which the structure once
    refused ('damping ratios in (0, 1)'). Its receptance is the direct solve of the matrices."""
    host = ToolTipDynamics.from_modes(x=[Mode(12.0, 0.03, 3.0e5), Mode(6000.0, 0.02, 3.2e6)])
    structure = with_absorber(host, 5.0, 5.0 * (2 * math.pi * 40.0) ** 2, 0.2, directions=("x",))
    assert structure.zeta.max() > 1.0
    K, C = structure.coupling
    w = 2 * math.pi * np.array([10.0, 40.0, 6000.0])
    direct = [structure.shapes[0] @ np.linalg.solve(K - x**2 * np.eye(3) + 1j * x * C, structure.shapes[0]) for x in w]
    assert np.allclose(structure.frf(w)[:, 0, 0], direct, rtol=1e-10)


SPINDLE_CHATTER = """pose_id,x_mm,y_mm,z_mm,beta_deg,direction,mode,fn_hz,zeta,k_n_per_m,k_xy_n_per_m,k_yx_n_per_m
A,1500,0,700,0,x,1,10,0.04,8.0e5,2.0e6,
A,1500,0,700,0,y,1,10,0.04,5.0e6,,2.0e6
A,1500,0,700,0,x,2,5200,0.015,2.5e7,,
A,1500,0,700,0,y,2,5400,0.012,2.8e7,,
"""


def test_the_absorbers_loss_is_not_credited_as_a_dashpot_at_a_kilohertz_chatter_mode(tmp_path):
    """The MRF absorber's loss is hysteretic (a force eta k x at any frequency); as a dashpot
    with its resonance damping (c = 2 zeta sqrt(k m), 180 N s/m) it gave a 5.4 kHz spindle mode
    85 times the damping, and the schedule reported 44.1 mm with an absorber that cannot reach
    that mode (3.58 mm bare; a new user's table, 3000 rpm, 2 teeth, 30 %, up). At the chatter
    frequency the dashpot now gives the hysteretic force: c w = 2 zeta k (closed form), and the
    depth with the absorber stays near the depth with an undamped one."""
    from absorber.chain import absorber_zeta

    table = tmp_path / "modes.csv"
    table.write_text(SPINDLE_CHATTER)
    cut = Cut(teeth=2, kt_pa=700e6, kn_pa=210e6, radial_immersion=0.3, milling="up")
    config = ScheduleConfig(cut, 3000.0)
    a, field = config.absorber, 0.6
    k, m, f_a = a.stiffness_n_per_m(field), a.mass_kg, a.natural_frequency_hz(field)
    c = 2.0 * absorber_zeta(config, field, f_a, 5367.0) * math.sqrt(k * m)
    assert c * 2 * math.pi * 5367.0 == pytest.approx(2.0 * a.damping_ratio(field) * k, rel=1e-12)
    assert absorber_zeta(config, field, f_a, 0.5 * f_a) == absorber_zeta(config, field, f_a, None) == a.damping_ratio(field)
    entry, = schedule_poses(table_pose_modes(read_modal_table(table)), config)
    assert entry.dominant_chatter_hz == pytest.approx(5367.0, rel=0.01) and not entry.absorber.feasible
    undamped = critical_points([with_absorber(entry.pose.dyn, m, k, 1e-6)], cut, 3000.0)[0].depth_m
    assert entry.critical_depth_m == pytest.approx(3.58e-3, rel=0.01)
    assert entry.critical_depth_with_absorber_m < 1.2 * undamped < 1.5 * entry.critical_depth_m  # was 44.1 mm


@pytest.fixture(scope="module")
def position5(datasets):
    table = read_modal_table(datasets / "seeds/hou2023_positions.csv")
    cut, rpm, steps = read_cut(datasets / "seeds/hou2023_cut.toml")
    pose = table_pose_modes(table.select_poses([table.poses.index("P5")]))[0]
    return replace(pose, rows=tuple(r[:5] + (0.1,) for r in pose.rows)), cut, rpm, steps


def test_position5_absorber_suppresses_chatter_in_the_time_domain(position5, capsys):
    """Seed 004 Figs. 8-9: at position 5 (2000 rpm) a cut 10 % deeper than the critical depth
    chatters without the absorber and decays with the absorber set by either policy."""
    pose, cut, rpm, steps = position5
    dyn = pose.dyn
    results = {p: schedule_poses([pose], ScheduleConfig(cut, rpm, policy=p, steps=steps))[0].to_json() for p in ("match", "sims")}
    depth = 1.1 * results["match"]["critical_depth_mm"] * 1e-3
    bare = simulate(dyn, cut, rpm, [depth], periods=300, steps_per_delay=100)
    assert bare.growth_rate()[0] > 0
    config = ScheduleConfig(cut, rpm, steps=steps)
    for policy, entry in results.items():
        structure = coupled(dyn, config, entry["absorber"]["field_mt"] * 1e-3)
        assert entry["critical_depth_with_absorber_mm"] > 1.2 * entry["critical_depth_mm"]
        sim = simulate(structure, cut, rpm, [depth], periods=300, steps_per_delay=100)
        assert sim.growth_rate()[0] < 0, policy
    match, sims = results["match"], results["sims"]
    print({p: {k: v for k, v in r.items() if k != "modes"} for p, r in results.items()})
    # sims maximises the speed-independent limit, and does raise it above match
    assert sims["absolute_limit_with_absorber_mm"] > match["absolute_limit_with_absorber_mm"]
    assert match["absorber"]["target_hz"] == pytest.approx(match["dominant_chatter_hz"])
    lo, hi = match["absorber"]["field_mt_interval"]
    assert lo < match["absorber"]["field_mt"] < hi


def posedyn(*args):
    return run_cli(*args)


def test_absorber_cli_contracts():
    result = posedyn("absorber", "field", "--target-hz", "18.61", "--json")
    out = json.loads(result.stdout)
    assert set(out) == {"target_hz", "field_mt", "storage_modulus_pa", "feasible", "range_hz"}
    assert out["feasible"] and 79 < out["field_mt"] < 80
    assert posedyn("absorber", "field", "--target-hz", "90", "--json").returncode == 0
    assert json.loads(posedyn("absorber", "field", "--target-hz", "90", "--json").stdout)["feasible"] is False
    result = posedyn(
        "absorber", "tune", "--host-fn-hz", 129.29, "--host-k-n-per-m", 1.34e7, "--host-zeta", 0.0134, "--mass-ratio", 0.0055,
        "--layout", "tmd", "--teeth", 4, "--kt-mpa", 660, "--kn-mpa", 180, "--radial-immersion", 0.5, "--milling", "down", "--json",
    )
    out = json.loads(result.stdout)
    assert set(out) == {"layout", "gamma", "zeta_a", "delta", "eta", "absolute_limit_mm", "uncontrolled_limit_mm", "at_search_bound"}
    assert out["delta"] is None and out["absolute_limit_mm"] > 2.5 * out["uncontrolled_limit_mm"]
    assert out["at_search_bound"] == [] and result.stderr == ""
    # a mass ratio of 50 put gamma on its search bound (0.5) without a word: said now
    result = posedyn(
        "absorber", "tune", "--host-fn-hz", 129.29, "--host-k-n-per-m", 1.34e7, "--host-zeta", 0.0134, "--mass-ratio", 50,
        "--layout", "tmd", "--teeth", 4, "--kt-mpa", 660, "--kn-mpa", 180, "--radial-immersion", 0.5, "--milling", "down", "--json",
    )
    assert json.loads(result.stdout)["at_search_bound"] == ["gamma"] and "the optimum lies beyond it" in result.stderr


def test_schedule_cli_from_a_table_and_from_a_model(datasets, tmp_path):
    poses = tmp_path / "poses.csv"
    poses.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nP5,1400,0,800,0\n")
    result = posedyn("schedule", "--modes", datasets / "seeds/hou2023_positions.csv", "--poses", poses, "--cut", datasets / "seeds/hou2023_cut.toml", "--out", tmp_path / "s.json", "--json")
    assert result.returncode == 0, result.stderr
    entry = json.loads(result.stdout)[0]
    assert set(entry) >= {"pose_id", "modes", "critical_depth_mm", "dominant_chatter_hz", "absorber", "critical_depth_with_absorber_mm"}
    assert set(entry["absorber"]) == {"policy", "target_hz", "field_mt", "current_a", "feasible", "field_mt_interval"}
    assert json.loads((tmp_path / "s.json").read_text()) == [entry]
    assert posedyn("train", datasets / "seeds/hou2023_positions.csv", "--out", tmp_path / "m", "--cv", "0").returncode == 0
    result = posedyn("schedule", tmp_path / "m", "--poses", poses, "--cut", datasets / "seeds/hou2023_cut.toml", "--policy", "sims", "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)[0]["absorber"]["policy"] == "sims"


def test_a_pose_asked_of_a_modal_table_must_be_where_the_table_has_it(datasets, tmp_path):
    """`--modes` picks a table's poses by pose_id: a pose file's P5 at x = 1450 mm silently got
    the table's P5 (x = 1400) in schedule, control schedule and tool-change. A pose whose
    columns differ from the table's is an error naming the file, row and column."""
    poses = tmp_path / "p5.csv"
    poses.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nP3,1600,0,800,0\nP5,1450,0,800,0\n")
    table = datasets / "seeds/hou2023_positions.csv"
    for command in (["schedule", "--cut", datasets / "seeds/hou2023_cut.toml"], ["control", "schedule"]):
        done = posedyn(*command, "--modes", table, "--poses", poses)
        assert done.returncode == 2 and done.stderr.strip() == (
            f"error: {poses}, row 2 (line 3), column 'x_mm': expected pose P5 where {table} has it, x_mm = 1400, got 1450.0")
    poses.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nP3,1600,0,800,0\nP5,1400,0,800,0\n")
    assert posedyn("control", "schedule", "--modes", table, "--poses", poses).returncode == 0
