"""Two boundary points of one structure within a fraction of a per cent of each other (issue 17,
the dominant chatter frequency "stable under refinement"): which one is the lowest decides the
reported chatter frequency, and the sweep tunes the absorber to it. A coarse cut model can rank
them the other way round from the converged one, and continuation from the neighbouring poses
can miss one just above the answer, where the winding count below the answer cannot see it."""

from __future__ import annotations

import numpy as np
import pytest

from absorber.chain import twin_pose_modes
from posedyn.io.shipped import DATASETS
from posedyn.io.twin_file import load_twin
from posedyn.stability import Cut, critical_points, floquet
from posedyn.table import PoseSet
from test_stability_multiscale import CUT, TABLE, structure  # the issue-17 pose's modes and the sweep's cut


def test_of_two_nearly_tied_branches_the_converged_lowest_gives_the_frequency():
    """At 6775.9 rpm (a speed of the benchmark's 300-speed lobes) two spindle branches are 0.6 %
    apart converged: 3.3722 mm at 5376.9 Hz and 3.3928 mm at 5524.5 Hz. At 8 sub-steps a radian
    their order is swapped, 0.03 % apart with error estimates of 0.8 %; the engine reported
    5524.0 Hz there. Now the job refines until the two error intervals part (or both are below
    TIE_TOL), and the answer is the converged branch's."""
    dyn = structure(TABLE)
    rpm = 6775.919732441472
    fine = floquet.critical_depth(dyn, CUT, rpm, substeps_per_rad=64.0)
    assert fine.chatter_hz == pytest.approx(5376.9, rel=1e-4) and fine.depth_m * 1e3 == pytest.approx(3.3722, rel=1e-4)
    result = critical_points([dyn], CUT, rpm)[0]
    assert result.converged
    assert result.chatter_hz == pytest.approx(fine.chatter_hz, rel=1e-4)
    assert result.depth_m == pytest.approx(fine.depth_m, rel=1e-3)


def test_continuation_finds_the_branch_just_above_the_answer_that_converges_below_it():
    """Three twin poses of the 10,000-pose bench grid, solved as the sweep solves them (each from
    its neighbours' boundary points). At x1425_y-225_z600_b52 a robot branch (18.8 Hz) and a
    spindle branch (5456.5 Hz) are 0.1 % apart at 8 sub-steps a radian and 0.3 % the other way
    converged; the neighbours lead only to the robot branch, so the sweep reported 18.8 Hz and
    tuned the absorber there (2.69 mm with it, against 1.63 mm tuned to the converged 5456.5 Hz).
    The count at rel_tol above the answer shows two more crossings than the robot branch brings;
    Newton from the multipliers nearest the circle there finds the spindle branch, and the
    ranking refines both."""
    robot, params = load_twin(DATASETS / "robots/kr_r2700_twin.toml")
    poses = PoseSet(
        ("x1425_y-225_z600_b20", "x1425_y-225_z600_b52", "x1425_y-200_z600_b-44"),
        np.array([[1425.0, -225.0, 600.0], [1425.0, -225.0, 600.0], [1425.0, -200.0, 600.0]]),
        "beta",
        np.array([[20.0], [52.0], [-44.0]]),
    )
    modes = twin_pose_modes(robot, params, poses)
    dyns = [modes[i].dyn for i in range(3)]
    fine = floquet.critical_depth(dyns[1], CUT, 2000.0, substeps_per_rad=64.0)
    assert fine.chatter_hz == pytest.approx(5456.5, rel=1e-4)
    assert any(abs(hz - 18.83) < 0.01 for _, hz, _ in fine.branches)  # the robot branch, 0.3 % above
    swept = critical_points(dyns, CUT, 2000.0, continuation=True)
    assert swept[1].converged
    assert swept[1].chatter_hz == pytest.approx(fine.chatter_hz, rel=1e-4)
    assert swept[1].depth_m == pytest.approx(fine.depth_m, rel=2e-3)


#: A blind check's case c028 (2026-12-07): 4 teeth at 277.01 rpm, up milling, a/D 0.0232, Kt 973.4
#: / Kn 476.1 MPa; robot modes 4-22 Hz under 4.4-9.1 kHz spindle modes.
C028 = [("x", 18.3578, 0.02919, 3024100.0), ("x", 9.45668, 0.03438, 1683700.0), ("x", 4395.85, 0.01395, 16258000.0), ("x", 6606.37, 0.02261, 86097000.0),
        ("y", 17.3783, 0.04447, 19591000.0), ("y", 3.97487, 0.03509, 25486000.0), ("y", 4.37042, 0.02732, 1542200.0), ("y", 21.8289, 0.03111, 2247400.0),
        ("y", 5319.7, 0.01751, 49248000.0), ("y", 7658.24, 0.01122, 293900000.0), ("y", 9132.78, 0.02216, 27099000.0)]
C028_CUT = Cut(teeth=4, kt_pa=973.4e6, kn_pa=476.1e6, radial_immersion=0.0232, milling="up")


def test_a_tie_at_the_finest_level_that_changes_nothing_is_converged():
    """c028 ends at the finest cut model (628 sub-steps a radian) with two boundary points 0.013 %
    apart, 6.0279 and 6.0287 mm, at 9339.8 and 9394.6 Hz, the lowest's estimate 0.16 %: too near
    to rank (`TIE_TOL`), with no finer level to part them. Either is the answer within 0.6 % in
    frequency, so the answer is converged (it was flagged not converged in every row order). A
    tie whose frequencies differ more stays open, and one that decides nothing is settled."""
    r = floquet.critical_depths([structure(C028)], C028_CUT, 277.01, verify=True)[0]
    assert r.substeps_per_rad == pytest.approx(floquet.coarsest_substeps(C028_CUT) * 2.0 ** floquet._top_level(floquet.coarsest_substeps(C028_CUT)))
    (a0, f0, _), (a1, f1, _) = r.branches[:2]
    assert abs(a1 - a0) <= 1e-3 * a0 and r.rel_error_estimate > floquet.TIE_TOL  # a tie the rule cannot rank
    assert r.converged and r.verified and r.depth_m * 1e3 == pytest.approx(6.0279, rel=1e-3) and r.chatter_hz == pytest.approx(f0)
    branch = lambda a, hz, er: (a, hz, 0.0, (), er)
    assert floquet._tie_immaterial([branch(a0, f0, 1.6e-3), branch(a1, f1, 1.6e-3)], True)
    assert not floquet._tie_immaterial([branch(a0, f0, 1.6e-3), branch(a1, 18.8, 1.6e-3)], True)  # a robot branch against a spindle one
    assert not floquet._tie_immaterial([branch(a0, f0, 1.6e-3), branch(a1, np.nan, 1.6e-3)], True)  # a frequency not known
    assert floquet._tie_immaterial([branch(a0, f0, 1.6e-3), branch(a1, 18.8, 1.6e-3)], False)  # the depth alone: either
    assert floquet._tie_immaterial([branch(a0, f0, 1.6e-3), branch(1.01 * a0, 18.8, 1.6e-3)], True)  # ranked: not a tie
