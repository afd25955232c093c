"""Hill's method (the multi-frequency solution of Budak and Altintas 1998, `posedyn.stability.hill`)
as the second method beside the Floquet engine, on a case the zeroth order cannot seed: a pose of
the demo's trained model (robot modes at 14-16 Hz, spindle modes at 1.4 and 5.4 kHz) with seed
004's MRF absorber tuned to 63 Hz, at the demo's cut (2000 rpm, tooth passing at 100 Hz). The
lowest boundary point lies between the robot modes and the absorber (9.9 mm at 25.9 Hz), where
the mean force has no crossing at all; the sweep found it only through the winding count's
bisection (0.5-5 s a pose, 6 of the 12 poses of the model sweep test)."""

from __future__ import annotations

import numpy as np
import pytest

from absorber.coupling import with_absorber
from posedyn.dynamics import ToolTipDynamics
from posedyn.stability import Cut, floquet, hill
from posedyn.stability.cutting import force_matrix, mean_force_matrix

BARE = ToolTipDynamics(
    np.array([14.3394, 14.2458, 16.0893, 16.1314, 1439.795, 1479.5917, 5438.8756, 5418.9906]),
    np.array([0.030031, 0.029873, 0.03052, 0.030119, 0.068509, 0.048236, 0.010976, 0.010912]),
    np.array([[0.061678, 0.0, 0.004654, 0.0, 1.568499, 0.0, 6.344076, 0.0], [0.0, 0.037366, 0.0, 0.086957, 0.0, 1.146673, 0.0, 6.491078]]),
)
STRUCTURE = with_absorber(BARE, 3.0, 477700.0, 0.0748)
CUT = Cut(teeth=3, kt_pa=796e6, kn_pa=169e6, radial_immersion=0.5, milling="down")
RPM = 2000.0


@pytest.mark.parametrize("cut", [CUT, Cut(1, 6e8, 2e8, 0.05, "up"), Cut(4, 6e8, 2e8, 1.0, "down"), Cut(2, 6e8, 2e8, 0.3, "up", feed_angle_deg=30.0)])
def test_force_harmonics_are_the_mean_force_and_the_sampled_fourier_series(cut):
    """H_0 is the zeroth order's closed-form mean; H_k agrees with the FFT of 2^16 samples of the
    instantaneous force matrix over one tooth pitch (the force jumps, so the samples alias at
    about 1e-4)."""
    harmonics = hill.force_harmonics(cut, 4)
    scale = np.abs(mean_force_matrix(cut)).max()
    assert np.allclose(harmonics[4], mean_force_matrix(cut), rtol=0, atol=1e-12 * scale)
    samples = 2**16
    phi = np.arange(samples) * (2.0 * np.pi / cut.teeth) / samples
    fft = np.fft.fft(force_matrix(cut, phi), axis=0) / samples
    for k in range(-4, 5):
        assert np.allclose(harmonics[k + 4], fft[k % samples], rtol=0, atol=1e-3 * np.abs(harmonics).max()), k


def test_the_lowest_boundary_point_between_the_modes_agrees_with_hills_method():
    char = floquet.FloquetCharacteristic(STRUCTURE, CUT, floquet.SUBSTEPS_PER_RAD)
    tau = float(CUT.tooth_period_s(RPM))
    zeroth = floquet.zoa_seeds(STRUCTURE, CUT, tau)[0]
    depth, theta = hill.hill_seeds(char.frf, char.free_eig()[0], CUT, tau)

    point = floquet.critical_depth(STRUCTURE, CUT, RPM)
    assert point.verified and point.converged
    assert point.depth_m == pytest.approx(9.94e-3, rel=0.01) and point.chatter_hz == pytest.approx(25.9, rel=0.01)
    assert zeroth.min() > 1.4 * point.depth_m  # the zeroth order has no boundary point near it
    assert depth[0] == pytest.approx(point.depth_m, rel=0.02)  # two methods, two harmonics either side
    assert theta[0] == pytest.approx(point.theta_rad, abs=0.01)


def test_hills_method_with_no_mode_within_reach_gives_no_points():
    spindle = ToolTipDynamics(np.array([5400.0, 5420.0]), np.array([0.011, 0.011]), np.array([[6.3, 0.0], [0.0, 6.5]]))
    char = floquet.FloquetCharacteristic(spindle, CUT, floquet.SUBSTEPS_PER_RAD)
    depth, theta = hill.hill_seeds(char.frf, char.free_eig()[0], CUT, float(CUT.tooth_period_s(RPM)))
    assert len(depth) == 0 and len(theta) == 0


def test_an_undamped_mode_on_the_grid_does_not_break_the_seeds():
    """A grid point exactly on an undamped resonance gives an infinite receptance: it is left out
    (the repair that calls this must not fail where the bisection would have succeeded)."""
    char = floquet.FloquetCharacteristic(STRUCTURE, CUT, floquet.SUBSTEPS_PER_RAD)
    tau = float(CUT.tooth_period_s(RPM))

    def frf(omega):
        out = char.frf(omega)
        out[np.abs(np.asarray(omega) - omega.flat[len(omega) // 2]) == 0] = np.inf
        return out

    depth, _ = hill.hill_seeds(frf, char.free_eig()[0], CUT, tau)
    assert depth[0] == pytest.approx(hill.hill_seeds(char.frf, char.free_eig()[0], CUT, tau)[0][0], rel=1e-3)
