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

from absorber.coupling import with_absorber
from posedyn.dynamics import ToolTipDynamics
from posedyn.stability import Cut, floquet
from posedyn.stability.cutting import force_matrix

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
    flow = scipy.integrate.solve_ivp(lambda t, y: (generator(t) @ y.reshape(2 * n, 2 * n)).ravel(), (t_in, t_out), np.eye(2 * n).ravel(),
                                     method="DOP853", rtol=1e-10, atol=1e-12).y[:, -1].reshape(2 * n, 2 * n)
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
    island, _ = floquet._coarse_islands(char, char, scans, [0], np.array([depth_m]), np.array([tau]), [0])
    assert covered[0]
    assert island[0] == (depth_m > 3e-3) == floquet.flip_islands(char, [depth_m], [tau])[0][0]
