"""Stability engine: each result against an independent calculation.

The classic single-mode benchmark (Insperger and Stepan): fn = 922 Hz, zeta = 0.011,
m = 0.03993 kg, Kt = 6e8, Kn = 2e8 N/m^2, 2 teeth, down milling.
"""

import math

import numpy as np
import pytest
import scipy.linalg

from posedyn.dynamics import ToolTipDynamics
from posedyn.io import read_modal_table
from posedyn.stability import Cut, Discretization, StabilityModel, force_matrix, interval_force_matrices, mean_force_matrix
from posedyn.stability import reference, sdm, zoa
from posedyn.stability.timesim import simulate
from posedyn.table import Mode

FN, ZETA, MASS = 922.0, 0.011, 0.03993
K = MASS * (2 * math.pi * FN) ** 2
BENCH_MODE = Mode(FN, ZETA, K)
ONE_DOF = ToolTipDynamics.from_modes(x=[BENCH_MODE])
PLANAR = ToolTipDynamics.from_modes(x=[BENCH_MODE], y=[BENCH_MODE])


def bench_cut(immersion, milling="down"):
    return Cut(teeth=2, kt_pa=6e8, kn_pa=2e8, radial_immersion=immersion, milling=milling)


# --- cutting-force matrices -----------------------------------------------------------------


@pytest.mark.parametrize("immersion, milling", [(1.0, "down"), (0.05, "down"), (0.3, "up"), (0.5, "down")])
def test_interval_averages_match_quadrature_of_the_instantaneous_matrix(immersion, milling):
    cut = bench_cut(immersion, milling)
    steps = 12
    averaged = interval_force_matrices(cut, steps)
    dphi = 2 * math.pi / (cut.teeth * steps)
    for i in (0, 5, 11):
        phi = np.linspace(i * dphi, (i + 1) * dphi, 20001)
        h = force_matrix(cut, phi)
        assert np.allclose(averaged[i], np.trapezoid(h, phi, axis=0) / dphi, rtol=1e-6, atol=1e-3 * cut.kt_pa)


@pytest.mark.parametrize("immersion, milling", [(1.0, "down"), (0.25, "up"), (0.5, "down"), (0.05, "down")])
def test_mean_force_matrix_is_altintas_directional_matrix(immersion, milling):
    """H0 = -(N Kt / 4 pi) [alpha] with Altintas-Budak's closed-form directional coefficients."""
    cut = bench_cut(immersion, milling)
    st, ex = cut.engagement_rad
    kr = cut.kn_pa / cut.kt_pa

    def bracket(f):
        return f(ex) - f(st)

    alpha = 0.5 * np.array(
        [
            [bracket(lambda p: math.cos(2 * p) - 2 * kr * p + kr * math.sin(2 * p)), bracket(lambda p: -math.sin(2 * p) - 2 * p + kr * math.cos(2 * p))],
            [bracket(lambda p: -math.sin(2 * p) + 2 * p + kr * math.cos(2 * p)), bracket(lambda p: -math.cos(2 * p) - 2 * kr * p - kr * math.sin(2 * p))],
        ]
    )
    assert np.allclose(mean_force_matrix(cut), -cut.teeth * cut.kt_pa / (4 * math.pi) * alpha, rtol=1e-12, atol=1e-6)


# --- step matrices and monodromy ------------------------------------------------------------


def test_single_mode_closed_form_exponentials_match_scipy():
    kappa = np.array([3.0e7, 1.0e5, -2.0e6, 4.0e8])
    dt = np.array([1e-4, 3e-4, 2e-4, 5e-5])
    c = 120.0
    for order in (0, 1):
        p, g0, g1 = sdm._exponentials_sdof(kappa, c, dt, order)
        for j in range(len(kappa)):
            M = np.zeros((4, 4))
            M[0, 1], M[1, 0], M[1, 1], M[1, 2], M[2, 3] = 1.0, -kappa[j], -c, 1.0, 1.0 / dt[j]
            E = scipy.linalg.expm(M * dt[j])
            assert np.allclose(p[j], E[:2, :2], rtol=1e-10, atol=1e-14)
            assert np.allclose(g0[j, :, 0], E[:2, 2], rtol=1e-9, atol=1e-16)
            if order:
                assert np.allclose(g1[j, :, 0], E[:2, 3], rtol=1e-9, atol=1e-16)


@pytest.mark.parametrize("dyn, immersion", [(ONE_DOF, 1.0), (ONE_DOF, 0.05), (PLANAR, 0.5)])
def test_structured_monodromy_equals_the_dense_product_of_seed004_step_matrices(dyn, immersion):
    cut = bench_cut(immersion)
    model = StabilityModel(dyn, cut, Discretization(steps=20))
    for rpm, depth in ((6000.0, 2e-4), (9300.0, 1.5e-3)):
        fast = model.step_matrices(rpm, depth).monodromy()[0]
        dense = reference.monodromy(dyn, cut, rpm, depth, 20)
        assert np.allclose(fast, dense, rtol=1e-9, atol=1e-9 * np.abs(dense).max())


def test_nonlinear_eigenproblem_has_the_monodromy_eigenvalues():
    model = StabilityModel(PLANAR, bench_cut(0.5), Discretization(steps=16))
    steps = model.step_matrices(7000.0, 6e-5)
    eig = np.linalg.eigvals(steps.monodromy()[0])
    top = eig[np.argsort(-np.abs(eig))[:6]]
    residual = np.abs(steps.characteristic(top)) / np.abs(steps.characteristic(top * 1.01))
    assert residual.max() < 1e-8


@pytest.mark.parametrize("immersion, depth_max", [(1.0, 2e-3), (0.05, 8e-3)])
def test_krylov_spectral_radius_equals_dense_lapack_over_a_map(immersion, depth_max):
    model = StabilityModel(ONE_DOF, bench_cut(immersion), Discretization(steps=40))
    rpm, depth = np.meshgrid(np.linspace(5000, 10000, 40), np.linspace(0, depth_max, 40))
    rho = model.spectral_radius(rpm, depth).ravel()
    steps = model.step_matrices(rpm.ravel(), depth.ravel())
    dense = np.abs(np.linalg.eigvals(steps.monodromy())).max(axis=1)
    assert np.max(np.abs(rho - dense) / dense) < 1e-9


# --- zeroth-order approximation ---------------------------------------------------------------


@pytest.mark.parametrize("immersion", [1.0, 0.5, 0.05])
def test_zoa_absolute_limit_matches_closed_form_for_one_mode(immersion):
    """a_lim = 1 / (2 h_xx (-Re G)) at its best frequency (seed 002 eq. 12): with min Re G =
    -1 / (4 k zeta (1 + zeta)) and max Re G = 1 / (4 k zeta (1 - zeta)), a_lim = 2 k zeta (1 + zeta) / h_xx
    for h_xx > 0 and 2 k zeta (1 - zeta) / |h_xx| for h_xx < 0 (the seed's remark on the sign of a_yy)."""
    cut = bench_cut(immersion)
    h = mean_force_matrix(cut)[0, 0]
    expected = 2 * K * ZETA * (1 + ZETA) / h if h > 0 else 2 * K * ZETA * (1 - ZETA) / abs(h)
    got = zoa.absolute_limit_m(ONE_DOF, cut)
    assert got == pytest.approx(expected, rel=1e-9)


def test_zoa_lobe_bottoms_touch_the_absolute_limit():
    cut = bench_cut(1.0)
    rpm = np.linspace(5000, 10000, 4001)
    lobes = zoa.lobes(PLANAR, cut, rpm)
    assert lobes.min() == pytest.approx(zoa.absolute_limit_m(PLANAR, cut), rel=1e-3)
    assert np.all(lobes >= zoa.absolute_limit_m(PLANAR, cut) * (1 - 1e-9))


# --- convergence and agreement --------------------------------------------------------------


@pytest.mark.parametrize("immersion, rpm", [(1.0, 7500.0), (0.05, 8400.0)])
def test_critical_depth_converges_as_steps_grow(immersion, rpm):
    depths = []
    for steps in (20, 40, 80, 160):
        model = StabilityModel(ONE_DOF, bench_cut(immersion), Discretization(steps=steps))
        depths.append(model.critical_depths([rpm], frequencies=False).depth_m[0])
    changes = np.abs(np.diff(depths))
    assert changes[1] < 0.6 * changes[0] and changes[2] < 0.6 * changes[1]
    first_order = StabilityModel(ONE_DOF, bench_cut(immersion), Discretization(steps=160, order=1))
    assert first_order.critical_depths([rpm], frequencies=False).depth_m[0] == pytest.approx(depths[-1], rel=3e-3)


def test_sdm_matches_zoa_lobe_bottoms_and_absolute_limit_at_full_immersion():
    """The benchmark mode in both directions (a planar tool), slotting: every SDM lobe bottom in
    5000-10000 rpm lies within 2 % of the ZOA closed-form absolute limit, at a speed within 1 % of
    the ZOA lobe bottom, and so does the SDM absolute limit. (The lobe peaks differ more: there
    the time-varying part of H(t), which the ZOA drops, matters.)"""
    cut = bench_cut(1.0)
    model = StabilityModel(PLANAR, cut, Discretization(steps=80))
    a_zoa = zoa.absolute_limit_m(PLANAR, cut)
    assert model.absolute_limit_m()[0] == pytest.approx(a_zoa, rel=0.02)
    rpm = np.linspace(5000, 10000, 401)
    sdm_lobes = model.critical_depths(rpm, frequencies=False).depth_m
    zoa_lobes = zoa.lobes(PLANAR, cut, rpm)

    def bottoms(y):
        return [i for i in range(1, len(y) - 1) if y[i] < y[i - 1] and y[i] <= y[i + 1]]

    sdm_bottoms, zoa_bottoms = bottoms(sdm_lobes), bottoms(zoa_lobes)
    assert len(sdm_bottoms) == len(zoa_bottoms) == 2
    for i, j in zip(sdm_bottoms, zoa_bottoms):
        assert sdm_lobes[i] == pytest.approx(a_zoa, rel=0.02)
        assert rpm[i] == pytest.approx(rpm[j], rel=0.01)


def test_one_dof_full_immersion_zoa_is_optimistic_and_time_domain_sides_with_sdm():
    """With flexibility in x only, slotting with 2 teeth gives a strongly time-varying h_xx(t)
    (mean Kn/2, second harmonic sqrt(Kt^2 + Kn^2) / 2): the ZOA limit is ~6 % low. The
    time-domain simulation at 1.03 times the ZOA limit decays, as the SDM predicts."""
    cut = bench_cut(1.0)
    model = StabilityModel(ONE_DOF, cut, Discretization(steps=80))
    a_zoa = zoa.absolute_limit_m(ONE_DOF, cut)
    sdm_limit, rpm = model.absolute_limit_m()
    assert 1.04 < sdm_limit / a_zoa < 1.09
    depth = 1.03 * a_zoa
    assert model.spectral_radius(rpm, depth) < 1.0
    sim = simulate(ONE_DOF, cut, rpm, [depth], periods=400)
    assert sim.growth_rate()[0] < 0


CASES = [
    (ONE_DOF, bench_cut(1.0), 7500.0),
    (ONE_DOF, bench_cut(0.05), 8400.0),
    (PLANAR, bench_cut(0.5, "up"), 6300.0),
]


@pytest.mark.parametrize("dyn, cut, rpm", CASES)
def test_time_domain_agrees_ten_percent_inside_and_outside_and_on_the_frequency(dyn, cut, rpm):
    model = StabilityModel(dyn, cut, Discretization(steps=80))
    critical = model.critical_depths([rpm]).depth_m[0]
    depths = critical * np.array([0.9, 1.1])
    sim = simulate(dyn, cut, rpm, depths, periods=400, steps_per_delay=160)
    growth = sim.growth_rate()
    assert growth[0] < 0 < growth[1]
    # growth per second from the multiplier, ln(rho) / tau, of a converged (first-order) SDM
    fine = StabilityModel(dyn, cut, Discretization(steps=160, order=1))
    predicted = np.log(fine.spectral_radius(rpm, depths)) / float(cut.tooth_period_s(rpm))
    assert growth == pytest.approx(predicted, rel=0.1, abs=0.3)
    at = model.chatter_at(np.full(2, rpm), depths)
    for j in range(2):
        expected = at.dominant_chatter_hz[j]
        assert abs(sim.peak_hz(j) - expected) <= max(0.01 * expected, 0.5)


def test_flip_lobe_at_low_immersion_chatters_at_half_the_tooth_frequency():
    cut = bench_cut(0.05)
    model = StabilityModel(ONE_DOF, cut, Discretization(steps=40))
    rpm = np.linspace(5000, 10000, 201)
    result = model.critical_depths(rpm)
    flips = np.flatnonzero(np.abs(np.angle(result.multiplier) - np.pi) < 1e-6)
    assert len(flips) > 0
    for j in flips[:3]:
        tooth_hz = rpm[j] * cut.teeth / 60.0
        ratio = result.dominant_chatter_hz[j] / tooth_hz
        assert abs(ratio - round(ratio - 0.5) - 0.5) < 1e-9


# --- seed 004 ----------------------------------------------------------------------------------


def test_seed004_position5_chatters_near_the_robot_mode(datasets):
    """Seed 004 section 4: position 5 (19.06 Hz, 1.06 MN/m, 725 Ns/m in x and y), 2000 rpm,
    3 teeth, 6 mm tool, 3 mm radial depth (immersion 0.5), Kt 796 MPa, Kn 169 MPa. The tooth
    passes at 100 Hz, five times the mode, so the delay is short against the vibration period:
    the critical depth is 0.89 mm (zeroth-order lobe value 0.87 mm) and the dominant member of
    the family |f_b + j 100 Hz| is the one next to the robot mode, 21.1 Hz, 11 % above it as
    regenerative chatter frequencies are. The seed's Fig. 8 shows chatter near the natural
    frequency at this position."""
    table = read_modal_table(datasets / "seeds/hou2023_positions.csv")
    dyn = ToolTipDynamics.from_table(table, "P5")
    cut = Cut(teeth=3, kt_pa=796e6, kn_pa=169e6, radial_immersion=0.5, milling="down")
    model = StabilityModel(dyn, cut, Discretization(steps=40))
    result = model.critical_depths([2000.0])
    depth_mm, chatter_hz = result.depth_m[0] * 1e3, result.dominant_chatter_hz[0]
    assert depth_mm == pytest.approx(0.891, abs=0.005)
    assert depth_mm == pytest.approx(zoa.lobes(dyn, cut, np.array([2000.0]))[0] * 1e3, rel=0.05)
    assert 19.0625 < chatter_hz < 1.15 * 19.0625
    assert result.family[0][0][0] == chatter_hz
    sim = simulate(dyn, cut, 2000.0, result.depth_m * np.array([0.9, 1.1]), periods=300, steps_per_delay=100)
    assert sim.growth_rate()[0] < 0 < sim.growth_rate()[1]
