"""Surface location error (seed 001): frequency domain against time domain, limits, compensation."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from posedyn.dynamics import ToolTipDynamics, combine
from posedyn.io import read_modal_table
from posedyn.sle import SleCut, compensate, sle_m, sle_quasi_static_m, sle_time_domain_m
from tests.cli_helpers import run_cli

CUT = SleCut(teeth=3, kt_pa=597.3e6, kn_pa=59.8e6, tool_diameter_m=12.7e-3, helix_rad=math.radians(40), radial_depth_m=2e-3, axial_depth_m=2.5e-3, feed_per_tooth_m=0.25e-3)


@pytest.fixture(scope="module")
def robot(datasets):
    return ToolTipDynamics.from_table(read_modal_table(datasets / "seeds/swan_spindle_robot.csv"))


def test_frequency_and_time_domain_agree_with_a_slow_robot_mode_and_fast_spindle_modes(robot):
    """Seed 001 Table 4: robot modes from 7.8 Hz and spindle modes up to 6.6 kHz in one FRF."""
    assert robot.fn_hz.min() < 10 and robot.fn_hz.max() > 3000
    for cut, rpm in ((CUT, 10700.0), (replace(CUT, milling="up", radial_depth_m=1e-3), 6000.0), (replace(CUT, helix_rad=0.0), 2500.0)):
        freq = sle_m(robot, cut, rpm)[0]
        time = sle_time_domain_m(robot, cut, rpm)
        assert freq == pytest.approx(time, rel=0.01)


def test_quasi_static_limit(robot):
    """At very low speed the tool simply deflects under the instantaneous force, y = G(0) F_y: the
    SLE approaches it linearly in the speed (the first correction is the damping's phase lag)."""
    static = sle_quasi_static_m(robot, CUT)
    errors = [abs(sle_m(robot, CUT, rpm)[0] / static - 1) for rpm in (5.0, 1.0, 0.1)]
    assert errors[0] > errors[1] > errors[2] and errors[2] < 5e-4
    assert errors[1] / errors[2] > 4  # ten times slower, several times closer
    # and a stiffer structure deflects proportionally less
    stiff = ToolTipDynamics(robot.fn_hz, robot.zeta, robot.shapes / math.sqrt(10))
    assert sle_quasi_static_m(stiff, CUT) == pytest.approx(sle_quasi_static_m(robot, CUT) / 10, rel=1e-12)


def test_converges_in_harmonics_and_slices(robot):
    by_harmonics = [sle_m(robot, CUT, 10700.0, harmonics=h)[0] for h in (25, 50, 100, 200)]
    assert abs(by_harmonics[-1] - by_harmonics[-2]) < 1e-3 * abs(by_harmonics[-1])
    by_slices = [sle_m(robot, CUT, 10700.0, slices=s)[0] for s in (5, 10, 20, 40, 80)]
    changes = np.abs(np.diff(by_slices))
    assert changes[-1] < 0.3 * changes[0] and changes[-1] < 2e-3 * abs(by_slices[-1])


def test_compensation_converges_in_a_few_steps(robot):
    history = compensate(robot, CUT, 10700.0, tolerance_m=2e-6, offset_m=32e-6)
    assert 2 <= len(history) <= 5 and abs(history[-1][2]) < 2e-6
    assert history[-1][0] > CUT.radial_depth_m  # deeper command to make up for the undercut


def test_seed001_conditions_robot_versus_machine_tool(datasets, capsys):
    """Seed 001 Table 7 with the modes of Tables 4-6 (robot + fixture summed, machine tool alone;
    x and y square sides): reported for every condition. Independent facts checked: the robot's
    SLE is an order of magnitude above the machine tool's (the seed's Figs. 10 and 12), and
    twice the feed roughly doubles it (the force is linear in the feed)."""
    tables = {name: read_modal_table(datasets / f"seeds/swan_{name}.csv") for name in ("spindle_robot", "fixture", "machine_tool")}
    robot = combine(ToolTipDynamics.from_table(tables["spindle_robot"]), ToolTipDynamics.from_table(tables["fixture"]))
    machine = ToolTipDynamics.from_table(tables["machine_tool"])
    rows = []
    for rpm in (10700.0, 10950.0):
        for depth in (1.5e-3, 2.5e-3):
            for feed in (0.125e-3, 0.25e-3):
                cut = replace(CUT, axial_depth_m=depth, feed_per_tooth_m=feed)
                values = {}
                for name, dyn in (("robot", robot), ("machine", machine)):
                    for side, turn in (("y", 0.0), ("x", -math.pi / 2)):
                        values[f"{name}_{side}"] = sle_m(dyn.rotated(turn), cut, rpm)[0] * 1e6
                rows.append((rpm, depth * 1e3, feed * 1e3, values))
    for row in rows:
        print("seed 001 condition rpm %g, b %.1f mm, ft %.3f mm:" % row[:3], {k: round(v, 2) for k, v in row[3].items()})
    for _, _, _, v in rows:
        assert abs(v["robot_x"]) > 10 * abs(v["machine_x"]) and abs(v["robot_y"]) > 10 * abs(v["machine_y"])
    assert rows[1][3]["robot_y"] == pytest.approx(2 * rows[0][3]["robot_y"], rel=0.05)


def test_sle_cli_contract(datasets):
    args = ["--modes", datasets / "seeds/swan_spindle_robot.csv", "--direction", "y", "--teeth", 3, "--kt-mpa", 597.3, "--kn-mpa", 59.8,
            "--tool-diameter-mm", 12.7, "--helix-deg", 40, "--radial-depth-mm", 2, "--axial-depth-mm", 2.5, "--feed-per-tooth-mm", 0.25, "--milling", "down"]

    def run(*extra):
        result = run_cli("sle", *map(str, extra), *map(str, args), "--json")
        assert result.returncode == 0, result.stderr
        return json.loads(result.stdout)

    assert set(run("--rpm", 10700)) == {"sle_um", "stability_checked", "note"}  # (not checked for chatter: says so)
    sweep = run("--rpm-min", 10000, "--rpm-max", 11000, "--rpm-steps", 5)
    assert set(sweep) == {"rpm", "sle_um", "stability_checked", "note"} and len(sweep["sle_um"]) == 5
    steps = run("compensate", "--rpm", 10700, "--tolerance-um", 2)["iterations"]
    assert set(steps[0]) == {"radial_depth_mm", "sle_um", "part_error_um"} and abs(steps[-1]["part_error_um"]) < 2


# --- issue 19: conventions checked against a geometric simulation that shares none of them -----------
# tests/independent_sle_sim.py (written blind to posedyn.sle) cuts the wall as the envelope of every
# slice's edge path with the tool-tip vibration, so the surface instant, the direction of the helix lag
# and the surface normal follow from the geometry. Compared like with like: its nominal (fixed-angle)
# engagement and the deepest point of each feed mark, Richardson-extrapolated in its time step
# (M = 360, 720 steps/rev; first-order force coupling). Full Table 7 runs (M up to 1440, 0.4-0.8 s)
# agree with sle_m to <= 0.3 um / 0.8 %; the shortened runs here reproduce those to ~0.03 um.

TABLE7_POINTS = [  # (machine, face, axial depth m, feed/tooth m) at 10,700 rpm
    ("machine_tool", "x", 2.5e-3, 0.25e-3),
    ("machine_tool", "y", 2.5e-3, 0.25e-3),
    ("spindle_robot", "x", 1.5e-3, 0.125e-3),
    ("spindle_robot", "y", 2.5e-3, 0.25e-3),
]


def _geometric_sle_um(machine, face, depth, feed, rpm=10700.0):
    import independent_sle_sim as sim

    bottoms = [sim.simulate(machine, face, rpm, depth, feed, M=m, T_sim=0.15, engagement="nominal")["sle_bottoms_um"] for m in (360, 720)]
    return 2 * bottoms[1] - bottoms[0]


def _frequency_domain_sle_um(datasets, machine, face, depth, feed, rpm=10700.0, engagement="nominal"):
    tables = {name: read_modal_table(datasets / f"seeds/swan_{name}.csv") for name in ("spindle_robot", "fixture", "machine_tool")}
    if machine == "machine_tool":
        dyn = ToolTipDynamics.from_table(tables["machine_tool"])
    else:
        dyn = combine(ToolTipDynamics.from_table(tables["spindle_robot"]), ToolTipDynamics.from_table(tables["fixture"]))
    if face == "x":
        dyn = dyn.rotated(-math.pi / 2)  # x-face normal -> y, as `posedyn sle --direction x`
    return sle_m(dyn, replace(CUT, axial_depth_m=depth, feed_per_tooth_m=feed, engagement=engagement), rpm, slices=50)[0] * 1e6


@pytest.mark.parametrize("machine,face,depth,feed", TABLE7_POINTS)
def test_seed001_table7_agrees_with_independent_geometric_simulation(datasets, machine, face, depth, feed):
    """Issue 19 target: 0.2 um or 2 %. Tighter here (0.05 um + 1 %): the genuine residual is the
    deepest point of the edge path versus the exact phi = pi sample (<= 0.8 % at Table 7)."""
    reference = _geometric_sle_um(machine, face, depth, feed)
    value = _frequency_domain_sle_um(datasets, machine, face, depth, feed)
    assert abs(value - reference) <= 0.05 + 0.01 * abs(reference), (value, reference)


@pytest.mark.parametrize("face,depth,feed", [p[1:] for p in TABLE7_POINTS if p[0] == "spindle_robot"])
def test_the_geometric_engagement_agrees_with_the_simulation_that_cuts_the_deflected_strip(datasets, face, depth, feed):
    """engagement = "geometric" (the strip the deflected tool really cuts, the chip entering at zero
    thickness) against the simulation's geometric engagement (its edge clipped at the stock's
    surface, the tool where its vibration puts it), written blind to posedyn.sle: within 0.05 um +
    1.5 % on seed 001's spindle-robot Table 7 points (24.7 and 35.6 um), where the fixed angles
    are 3.4 % and 6.5 % above it (outside the band)."""
    import independent_sle_sim as sim

    bottoms = [sim.simulate("spindle_robot", face, 10700.0, depth, feed, M=m, T_sim=0.15, engagement="geometric")["sle_bottoms_um"] for m in (360, 720)]
    reference = 2 * bottoms[1] - bottoms[0]
    band = 0.05 + 0.015 * abs(reference)
    nominal = _frequency_domain_sle_um(datasets, "spindle_robot", face, depth, feed)
    geometric = _frequency_domain_sle_um(datasets, "spindle_robot", face, depth, feed, engagement="geometric")
    assert abs(geometric - reference) <= band and abs(nominal - reference) > band, (geometric, nominal, reference)


def test_the_geometric_engagement_is_read_from_the_cut_file_and_checked(tmp_path, datasets):
    """`[sle] engagement = "geometric"` reaches the SleCut; another word is refused by its key."""
    from posedyn.errors import InputError
    from posedyn.io.cut import read_sle_cut

    assert read_sle_cut(datasets / "cuts/walls_geometric_cut.toml")[0].engagement == "geometric"
    assert read_sle_cut(datasets / "cuts/sweep_demo_cut.toml")[0].engagement == "nominal"
    bad = tmp_path / "bad.toml"
    bad.write_text((datasets / "cuts/walls_geometric_cut.toml").read_text().replace('engagement = "geometric"', 'engagement = "deflected"'))
    with pytest.raises(InputError, match="engagement"):
        read_sle_cut(bad)


def test_single_instant_sampling_is_rejected_by_the_geometric_simulation(datasets, monkeypatch):
    """The reading that samples every slice at the bottom slice's exit (no helix lag in the
    sampling) gives 3.6 um where the geometry gives 1.0 um (machine tool, x face, Table 7 TC4)."""
    import posedyn.sle as sle

    reference = _geometric_sle_um("machine_tool", "x", 2.5e-3, 0.25e-3)
    monkeypatch.setattr(sle, "_exit_phases", lambda cut, slices: np.full(slices, math.pi))
    wrong = _frequency_domain_sle_um(datasets, "machine_tool", "x", 2.5e-3, 0.25e-3)
    assert abs(wrong - reference) > 1.0


def test_up_milling_surface_normal_is_plus_y(robot):
    """Up milling cuts the wall at entry, phi = 0, where the edge points to +y: a tool displaced
    by +y cuts deeper (overcut), so SLE (+ = undercut) = -y; down milling (exit, phi = pi, wall at -y)
    SLE = +y. Checked in the quasi-static limit, y = G(0) F_y at the surface instants."""
    from posedyn.sle import normal_force

    compliance = float(robot.frf(np.array([0.0]))[0, 1, 1].real)
    for milling, surface, sign in (("down", math.pi, 1.0), ("up", 0.0, -1.0)):
        cut = replace(CUT, milling=milling, radial_depth_m=1e-3)
        chi = 2 * cut.axial_depth_m / 20 * math.tan(cut.helix_rad) / cut.tool_diameter_m
        y = compliance * np.mean(normal_force(cut, surface + chi * np.arange(20), 20))
        assert sle_quasi_static_m(robot, cut) == pytest.approx(sign * y, rel=1e-12)
        assert sle_m(robot, cut, 0.1)[0] == pytest.approx(sign * y, rel=1e-3)


def test_sle_says_when_the_cut_chatters(tmp_path):
    """A new user's SLE at 5 mm axial depth where the cut's critical depth is 0.43 mm (a 10 Hz
    robot mode, 600 rpm, 2 teeth): 'SLE 61.318 um' with no warning. `--stability` adds the
    critical depth and the verdict; without it the text says the SLE assumes a stable cut."""
    modes = tmp_path / "b.csv"
    modes.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg,direction,mode,fn_hz,zeta,k_n_per_m\n"
                     "B,1500,0,700,0,x,1,10,0.04,8e5\nB,1500,0,700,0,x,2,1450,0.06,3.3e7\nB,1500,0,700,0,x,3,5200,0.015,2.5e7\n"
                     "B,1500,0,700,0,y,1,10.8,0.035,1.1e6\nB,1500,0,700,0,y,2,1480,0.05,6e7\nB,1500,0,700,0,y,3,5400,0.012,2.8e7\n")
    args = ["sle", "--modes", str(modes), "--direction", "y", "--rpm", "600", "--teeth", "2", "--kt-mpa", "700", "--kn-mpa", "210", "--tool-diameter-mm", "6",
            "--helix-deg", "30", "--radial-depth-mm", "3", "--feed-per-tooth-mm", "0.05", "--milling", "down"]
    out = json.loads(run_cli(*args, "--axial-depth-mm", "5", "--stability", "--json").stdout)
    assert out["stable"] is False and out["critical_depth_mm"] == pytest.approx(0.4263, rel=0.02)
    assert out["converged"] is True and 0 <= out["rel_error_estimate"] <= 0.02  # the depth says how accurate it is
    assert "CHATTERS" in run_cli(*args, "--axial-depth-mm", "5", "--stability").stdout
    assert json.loads(run_cli(*args, "--axial-depth-mm", "0.3", "--stability", "--json").stdout)["stable"] is True
    assert "stable cut" in run_cli(*args, "--axial-depth-mm", "5").stdout
    unchecked = json.loads(run_cli(*args, "--axial-depth-mm", "5", "--json").stdout)  # the JSON says so too (it said nothing)
    assert unchecked["stability_checked"] is False and "--stability" in unchecked["note"] and "stable" not in unchecked
    ranged = [a for a in args if a not in ("--rpm", "600")] + ["--rpm-min", "600", "--rpm-max", "610", "--rpm-steps", "2", "--axial-depth-mm", "5", "--stability"]
    out = json.loads(run_cli(*ranged, "--json").stdout)  # per speed as at one speed (the critical depths were left out)
    assert out["stable"] == [False, False] and out["critical_depth_mm"][0] == pytest.approx(0.4263, rel=0.02)
    assert out["converged"] == [True, True] and all(0 <= e <= 0.02 for e in out["rel_error_estimate"])
    assert "SLE from" not in run_cli(*ranged).stdout  # no range of SLEs where none applies


def test_sle_options_out_of_range_are_refused_by_their_flags(tmp_path):
    """--axial-slices 0 was a ZeroDivisionError traceback (-3: empty-slice warnings and a null
    SLE); --offset-um nan printed 'SLE nan um (overcut)'; --helix-deg 90 (tan = 1.6e16) and a
    tolerance of -1 ran; --rpm beside a range silently won."""
    modes = tmp_path / "stiff.csv"
    modes.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg,direction,mode,fn_hz,zeta,k_n_per_m\nS,0,0,0,0,y,1,20000,0.05,1e8\n")
    base = ("sle", "--modes", modes, "--kt-mpa", 796, "--kn-mpa", 169, "--teeth", 3, "--tool-diameter-mm", 10, "--axial-depth-mm", 2,
            "--feed-per-tooth-mm", 0.05, "--radial-depth-mm", 3)
    for extra, flag in ((("--rpm", 3000, "--axial-slices", 0), "--axial-slices"), (("--rpm", 3000, "--offset-um", "nan"), "--offset-um"),
                        (("--rpm", 3000, "--helix-deg", 90), "--helix-deg"), (("--rpm", 3000, "--helix-deg", -30), "--helix-deg"),
                        (("compensate", "--rpm", 3000, "--tolerance-um", -1), "--tolerance-um"),
                        (("--rpm", 3000, "--rpm-min", 1000, "--rpm-max", 2000), "--rpm")):
        args = base[:1] + extra[:1] + base[1:] + extra[1:] if extra[0] == "compensate" else base + extra
        result = run_cli(*args)
        assert result.returncode == 2 and flag in result.stderr + result.stdout and "Traceback" not in result.stderr, (extra, result.stderr)
    assert "got -30.0" in run_cli(*base, "--rpm", 3000, "--helix-deg", -30).stderr  # (not -29.999999999999996)
    assert run_cli(*base, "--rpm", 3000, "--helix-deg", 45).returncode == 0


def test_sle_checks_its_action_and_speeds_before_reading_anything(tmp_path):
    """A misspelt action was reported only once every option was given and the tables were read
    (a user typing `posedyn sle compenstae` was asked for --modes first); a bad speed range after
    the tables were read. Both are now refused first, named by their argument."""
    missing = tmp_path / "absent.csv"  # never read: the checks come first
    result = run_cli("sle", "compenstae")
    assert result.returncode == 2 and "ACTION" in result.stderr and "compenstae" in result.stderr, result.stderr
    base = ("sle", "--modes", missing, "--kt-mpa", 796, "--kn-mpa", 169, "--teeth", 3, "--tool-diameter-mm", 10, "--axial-depth-mm", 2,
            "--feed-per-tooth-mm", 0.05, "--radial-depth-mm", 3)
    for extra in (("--rpm-min", 3000, "--rpm-max", 1000), ("--rpm-min", 1000), ()):
        result = run_cli(*base, *extra)
        assert result.returncode == 2 and "--rpm" in result.stderr and "absent.csv" not in result.stderr, (extra, result.stderr)
    result = run_cli("sle", "compensate", *base[1:])
    assert result.returncode == 2 and "--rpm for compensate" in result.stderr and "absent.csv" not in result.stderr, result.stderr
    result = run_cli(*base, "--rpm", 3000)  # a good command line: now the file is read, and named
    assert result.returncode == 2 and "absent.csv" in result.stderr, result.stderr
