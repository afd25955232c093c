"""Period-doubling islands (issue 17): a real Floquet multiplier that passes -1 at one depth and
comes back at a larger one makes the cut unstable only inside that interval, so the winding
count at one depth above it is 0 and a search that misses the lower flip point reports a depth
that is far too large yet "verified". The case: a sweep pose of the shipped twin with the MRF
absorber at 0.6 T (seed 004's absorber), where the island exists only with a cut model finer
than the engine's coarse level (at 4 sub-steps a radian the multiplier just touches -1). Before
the engine scanned for islands at the answer's resolution, the seeds reported 5.51 mm here and
continuation 5.99 / 9.19 mm on neighbouring poses; the structure chatters from about 2.07 mm.

The check is independent of the engine's numerics: the monodromy at nu = -1 (delay term
q(t - tau) = -q(t), the period-doubling condition) integrated with scipy's DOP853 through the
exact time-varying cutting force (no segment averages, no Taylor exponentials, no balanced
coordinates) in the structure's own mass-normalised coordinates."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg

import independent_milling_sim as sim
from absorber.coupling import with_absorber
from posedyn.dynamics import ToolTipDynamics
from posedyn.stability import Cut, floquet
from posedyn.stability.cutting import force_matrix
from posedyn.table import Mode
from test_stability_multiscale import TABLE, structure

BARE = ToolTipDynamics(
    np.array([13.349513937132706, 16.10584527590849, 18.39279996082013, 48.643461493152095, 67.65722018951783, 98.78340076507274, 1443.5, 5434.3, 1480.0, 5418.8]),
    np.array([0.03, 0.03, 0.03, 0.03, 0.03, 0.03, 0.069, 0.011, 0.048, 0.011]),
    np.array([[0.06579190431467828, -0.026504934083754948, 0.04799684567474127, -0.008558503205611495, 0.010776384744614294, 0.19741372331900386, 1.5788456926968413, 6.362491782149103, 0.0, 0.0],
              [-0.00815680209214334, -0.09010917831782807, -0.026595442464808116, -0.12344359091728084, 0.10020106268148767, 0.19587947155442198, 0.0, 0.0, 1.1560841404200763, 6.4807974675507305]]),
    None, None,
)
STRUCTURE = with_absorber(BARE, 3.0, 477684.88790825976, 0.07475337355756533)
CUT = Cut(teeth=3, kt_pa=796e6, kn_pa=169e6, radial_immersion=0.5, milling="down")
RPM = 2000.0


def flip_multipliers(depth_m: float) -> np.ndarray:
    """Eigenvalues of the period map of q'' + C q' + K q = -2 a W(t) q (nu = -1), by DOP853
    through the cutting interval and scipy's expm through free flight."""
    dyn = STRUCTURE
    n = dyn.n_modes
    K, C = dyn.stiffness_matrix, dyn.damping_matrix
    shapes, force_shapes = dyn.shapes, dyn.force_shapes
    tau = float(CUT.tooth_period_s(RPM))
    omega = 2.0 * math.pi * RPM / 60.0
    st, ex = CUT.engagement_rad

    def generator(t):
        W = force_shapes.T @ force_matrix(CUT, np.array(omega * t)) @ shapes
        A = np.zeros((2 * n, 2 * n))
        A[:n, n:] = np.eye(n)
        A[n:, :n] = -K - 2.0 * depth_m * W
        A[n:, n:] = -C
        return A

    t_in, t_out = st / omega, ex / omega  # tooth 0 cuts from st to ex; the other teeth are a tooth period apart
    inner = 1e-9 * (t_out - t_in)  # the force jumps at entry and exit: inside the cut it is the cut's
    solution = scipy.integrate.solve_ivp(lambda t, y: (generator(min(max(t, t_in + inner), t_out - inner)) @ y.reshape(2 * n, 2 * n)).ravel(), (t_in, t_out),
                                         np.eye(2 * n).ravel(), method="DOP853", rtol=1e-10, atol=1e-12)
    assert solution.success, solution.message
    flow = solution.y[:, -1].reshape(2 * n, 2 * n)
    free = generator(0.5 * (t_out + tau + t_in))  # no tooth in the cut
    assert not np.any(free[n:, :n] + K)
    period = scipy.linalg.expm(free * (tau - (t_out - t_in))) @ flow
    return np.linalg.eigvals(period)


def test_the_reported_depth_is_below_the_flip_island():
    r = floquet.critical_depth(STRUCTURE, CUT, RPM, verify=True)
    assert r.verified and r.converged
    assert r.theta_rad == pytest.approx(np.pi)
    # independent: inside the island a real multiplier is below -1, below it none
    inside, below = flip_multipliers(2.2e-3), flip_multipliers(1.9e-3)
    real = lambda mu: mu[np.abs(mu.imag) < 1e-6].real  # noqa: E731
    assert real(inside).min() < -1.0005
    assert np.all(real(below) > -1.0)  # (only an eigenvalue -1 of this map is a multiplier)
    assert 1.9e-3 < r.depth_m < 2.2e-3


def test_the_island_scan_sees_what_one_count_above_it_cannot():
    char = floquet.FloquetCharacteristic(STRUCTURE, CUT, 2 * floquet.SUBSTEPS_PER_RAD)
    tau = float(CUT.tooth_period_s(RPM))
    count, resolved, _ = floquet.unstable_count(char, 5.0e-3, tau)
    assert count == 0 and resolved  # stable again above the island
    island, _ = floquet.flip_islands(char, [5.0e-3], [tau])
    assert island[0]


@pytest.mark.parametrize("scale", [0.7, 2.5, 6.0])
@pytest.mark.parametrize("depth_m", [5.0e-3, 3.5e-3, 1.5e-3])
def test_the_island_check_from_the_seed_scan_finds_the_island_below_an_answer(depth_m, scale):
    """The engine reuses the flip seeds' scan (same cut model and spacing, other depths) for the
    island check below a coarse-level answer, plus one monodromy at 0.995 x the answer and, where
    the seeds' depth scale lies above the answer (scale 2.5; at 6 the island lies below the
    scan), the points from 0.1 x the answer up to the scan's first; where it sees an island or a
    multiplier near -1, a refined scan decides. Above the island (3.5 and 5 mm) it is found;
    below it (1.5 mm) there is none."""
    char = floquet.FloquetCharacteristic(STRUCTURE, CUT, 2 * floquet.SUBSTEPS_PER_RAD)
    tau = float(CUT.tooth_period_s(RPM))
    _, scans = floquet.flip_seeds(char, [scale * depth_m], [tau], [0])
    _, _, covered = floquet._islands_from_seed_scan(char, scans, [0], [depth_m], [tau])
    island, *_ = floquet._coarse_islands(lambda level: char, char, scans, [0], np.array([depth_m]), np.array([tau]), [0])
    assert covered[0]
    assert island[0] == (depth_m > 3e-3) == floquet.flip_islands(char, [depth_m], [tau])[0][0]


#: A random uncoupled robot-plus-spindle structure (blind island search of 2026-12-03): rows
#: (direction, fn_hz, zeta, k_n_per_m); 4 teeth in up milling at a/D 0.91 (overlapping teeth),
#: 12,667 rpm. At the coarse cut model a real multiplier passes -1 at 0.508 mm and comes back at
#: 0.530 mm, under a Hopf branch near theta = pi at 0.544 mm, which the engine reported verified
#: (the 13-point island scan, 1.21 apart, stepped over the island).
NARROW_ROWS = [
    ("x", 8.72310526980056, 0.024134557825149488, 848602.8121639595), ("x", 41.58559241743729, 0.009281454663474197, 12128040.88351615),
    ("x", 1447.3393889787512, 0.05299194246972928, 11323997.468931561), ("x", 6070.497380731933, 0.05170720213855041, 13194812.261337144),
    ("y", 19.73161356271489, 0.015898965611073894, 3227946.477643925), ("y", 105.43461241965382, 0.062059047320902595, 7313446.752968607),
    ("y", 1163.6903952114458, 0.06621951266898629, 28519689.992760517), ("y", 3699.599491085007, 0.00801376839955356, 4859764.649600249),
]
NARROW = ToolTipDynamics.from_modes(x=[Mode(f, z, k) for d, f, z, k in NARROW_ROWS if d == "x"], y=[Mode(f, z, k) for d, f, z, k in NARROW_ROWS if d == "y"])
NARROW_CUT = Cut(teeth=4, kt_pa=1957699435.8537712, kn_pa=305965113.8356096, radial_immersion=0.9094603940645208, milling="up")
NARROW_RPM = 12667.025157470403


def test_the_count_interpolant_ladder_finds_an_island_the_sparse_scan_steps_over():
    """The level-0 winding count's interpolant of M(a0 (1 - nu)) holds on the whole disk, so nu =
    1 - 2 a / a0 gives the flip condition at every depth below a0 (`ladder_islands`), here 2 %
    apart instead of the scan's 21 %."""
    char = floquet.FloquetCharacteristic(NARROW, NARROW_CUT, floquet.SUBSTEPS_PER_RAD)
    tau = float(NARROW_CUT.tooth_period_s(NARROW_RPM))
    answer = 0.544e-3
    poly: list = []
    count, resolved, _ = floquet.unstable_count(char, floquet.VERIFY_FRACTION * answer, tau, polynomial=poly)
    assert count == 0 and resolved and poly  # stable again above the island
    assert not floquet.flip_islands(char, [answer], [tau])[0][0]  # the sparse scan: nothing
    island, _, inside = floquet.ladder_islands(char, floquet.VERIFY_FRACTION * answer, *poly[0], answer, tau)
    assert island and 0.50e-3 < inside < 0.515e-3  # the bracket of its lower flip point
    # the island on the monodromy itself (not the interpolant): det(I + M(2 a)) < 0 inside it
    M = char.monodromy(2.0 * np.array([0.52e-3, 0.5e-3, 0.535e-3]), np.full(3, tau)).real
    assert list(np.sign(np.linalg.det(np.eye(M.shape[-1]) + M))) == [-1.0, 1.0, 1.0]


def test_the_answer_under_a_narrow_island_is_its_bottom_by_an_independent_simulation():
    """Reported once as 0.544 mm, verified; the independent time-domain simulation
    (tests/independent_milling_sim.py) grows at 0.95 x that. Now the island's bottom, a flip
    point: decays 5 % below it and grows 5 % above."""
    r = floquet.critical_depth(NARROW, NARROW_CUT, NARROW_RPM, verify=True)
    assert r.verified and r.converged
    assert r.theta_rad == pytest.approx(np.pi)
    assert sim.grows_either_side(NARROW_ROWS, NARROW_CUT, NARROW_RPM, r.depth_m) == (False, True)


HIGH_SPEED_ROWS = [("x", 9.5, 0.04, 8.0e5), ("x", 22.0, 0.05, 3.0e6), ("x", 1450.0, 0.06, 3.3e7), ("x", 5200.0, 0.015, 2.5e7),
                   ("y", 10.8, 0.035, 1.1e6), ("y", 25.0, 0.05, 4.0e6), ("y", 1480.0, 0.05, 6.0e7), ("y", 5400.0, 0.012, 2.8e7)]


def test_an_island_found_at_the_finest_level_is_solved_there_not_left_unverified():
    """A new user's case (30,000 rpm, 8 teeth, 2 % immersion, robot plus spindle modes): a
    period-doubling island at 41-48 mm lies under the seeds' 57.0 mm answer on every cut model,
    and the answer ends at the finest level, where the engine used to give up ('an island no
    finer model can be asked about': 57.0 mm, not verified, printed NOT converged). It is solved
    there from the island's lower end: 40.68 mm at 6000 Hz (half the tooth-passing frequency
    plus one), verified; the independent simulation decays 5 % below and grows at 6000 Hz 5 % above."""
    dyn = ToolTipDynamics.from_modes(x=[Mode(f, z, k) for d, f, z, k in HIGH_SPEED_ROWS if d == "x"],
                                     y=[Mode(f, z, k) for d, f, z, k in HIGH_SPEED_ROWS if d == "y"])
    cut = Cut(teeth=8, kt_pa=700e6, kn_pa=210e6, radial_immersion=0.02, milling="down")
    point = floquet.critical_depth(dyn, cut, 30000.0)
    assert point.verified is not False and point.converged and point.rel_error_estimate < 0.01
    assert point.depth_m == pytest.approx(40.68e-3, rel=0.01) and point.chatter_hz == pytest.approx(6000.0, rel=1e-6)
    args = (HIGH_SPEED_ROWS, 8, 700e6, 210e6, 0.02, "down", 30000.0)
    below, above = (sim.analyse(*args, f * point.depth_m, t_sim=0.6) for f in (0.95, 1.05))
    assert below["sigma"] < 0 < above["sigma"] and above["fdom"] == pytest.approx(6000.0, rel=1e-3)


STIFF_SPINDLE_ROWS = [("y", 2102.25, 0.03451, 7.6248e8), ("y", 11.7769, 0.0685, 3.2028e6), ("y", 17.8524, 0.07248, 3.9854e6),
                      ("y", 10.0161, 0.05297, 2.3005e6), ("y", 6494.12, 0.0581, 2.5554e8), ("y", 2798.54, 0.0515, 1.2267e9),
                      ("y", 4873.05, 0.02946, 7.0415e8), ("y", 24.532, 0.02706, 2.3067e6), ("x", 1746.81, 0.03375, 5.1897e6),
                      ("x", 500.414, 0.04107, 1.2642e8), ("x", 6685.25, 0.03893, 3.6447e8), ("x", 8532.45, 0.03429, 7.7042e7)]


def test_a_flip_lobe_of_a_stiff_spindle_mode_is_searched_with_that_mode():
    """A blind check's case (7 teeth, full immersion, down milling, 14,082 rpm): the 2.8 kHz y mode
    (1.2e9 N/m) has 0.099 % of the 24.5 Hz robot mode's peak compliance, and the search used to
    leave it out as irrelevant; with it goes the flip point at 8.719 mm, so the full structure's
    point could not be followed to a finer cut model (Newton ran to 10.435 mm) and the answer was
    flagged not converged, estimate 16-20 %. Its own FRF term is 7.5 % of the FRF at 2.8 kHz: kept
    now. Converged, and the independent simulation decays 5 % below and grows 5 % above."""
    dyn = structure(STIFF_SPINDLE_ROWS)
    kept = dyn.fn_hz[floquet.relevant_modes(dyn)]
    assert 2798.54 in kept
    cut = Cut(teeth=7, kt_pa=579.2e6, kn_pa=120.7e6, radial_immersion=1.0, milling="down")
    point = floquet.critical_depth(dyn, cut, 14082.4)
    assert point.converged and point.verified and point.rel_error_estimate < 0.01
    assert point.theta_rad == pytest.approx(np.pi) and point.depth_m == pytest.approx(8.719e-3, rel=2e-3)
    assert sim.grows_either_side(STIFF_SPINDLE_ROWS, cut, 14082.4, point.depth_m) == (False, True)


def test_a_mode_invisible_in_the_frf_is_left_out_of_the_search():
    """The issue-17 pose's 13.13 Hz x mode (9.9e9 N/m beside a 2.1e6 N/m mode at 12.59 Hz) is a
    millionth of the FRF everywhere: left out; every other mode of that table is kept."""
    dyn = structure(TABLE)
    dropped = sorted(set(range(dyn.n_modes)) - set(floquet.relevant_modes(dyn)))
    assert [round(float(dyn.fn_hz[i]), 4) for i in dropped] == [13.1342]
