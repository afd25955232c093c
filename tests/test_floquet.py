"""Issue 17: the exact Floquet characteristic (posedyn.stability.floquet) against an
independent time-domain simulation (/work/indep17, bracket of the critical depth), a refined
semi-discretization, and seed 004."""

import math

import numpy as np
import pytest

from posedyn.dynamics import ToolTipDynamics
from posedyn.io import read_modal_table
from posedyn.stability import Cut, Discretization, StabilityModel
from posedyn.stability import floquet as converged
from posedyn.table import Mode

TABLE = [
    ("x", 12.5909, 0.0300342, 2.11684e06), ("x", 13.1342, 0.0305178, 9.91928e09),
    ("x", 1443.92, 0.068509, 3.37558e07), ("x", 5438.87, 0.0109756, 2.89553e07),
    ("y", 12.6066, 0.0298721, 1.70046e07), ("y", 13.1265, 0.030316, 910188.0),
    ("y", 1479.59, 0.048235, 6.7942e07), ("y", 5418.99, 0.0109107, 2.75146e07),
]
ROBOT = ToolTipDynamics.from_modes(
    x=[Mode(f, z, k) for d, f, z, k in TABLE if d == "x"], y=[Mode(f, z, k) for d, f, z, k in TABLE if d == "y"]
)
CUT = Cut(teeth=3, kt_pa=796e6, kn_pa=169e6, radial_immersion=0.5, milling="down")

FN, ZETA, MASS = 922.0, 0.011, 0.03993
ONE_DOF = ToolTipDynamics.from_modes(x=[Mode(FN, ZETA, MASS * (2 * math.pi * FN) ** 2)])

# independent time-domain simulation: (rpm, stable depth mm, unstable depth mm, growing Hz)
SIMULATION = [(1000.0, 1.8621, 1.8737, 5437.4), (2000.0, 1.5115, 1.5228, 5456.9), (5000.0, 1.2880, 1.2937, 5421.7), (12000.0, 4.6067, 4.6454, 5553.3)]


@pytest.mark.parametrize("rpm, lo, hi, hz", SIMULATION)
def test_issue17_table_inside_two_percent_of_the_time_domain_bracket(rpm, lo, hi, hz):
    r = converged.critical_depth(ROBOT, CUT, rpm, verify=rpm == 1000.0)
    assert r.converged and r.rel_error_estimate <= 0.02
    assert 0.98 * lo <= r.depth_m * 1e3 <= 1.02 * hi
    # the simulation's growing line is a member of the Floquet family
    assert min(abs(f - hz) for f, _ in r.family) <= 5.0
    if rpm == 1000.0:  # the spindle branch, not the robot one (the prototype's miss)
        assert r.verified and r.chatter_hz == pytest.approx(5437.0, abs=5.0)


def test_2000_rpm_low_lines_are_aliases_of_the_spindle_branch():
    """The simulation's 1357 / 1457 Hz lines are 5456.7 Hz - 41 / 40 x 100 Hz (tooth frequency):
    members of the same Floquet family, not a second branch."""
    r = converged.critical_depth(ROBOT, CUT, 2000.0, verify=False)
    assert r.chatter_hz == pytest.approx(5456.7, abs=2.0)
    for line in (1356.9, 1456.9):
        j = (r.chatter_hz - line) / 100.0
        assert abs(j - round(j)) < 0.01


@pytest.mark.parametrize("immersion, rpm", [(1.0, 7500.0), (0.05, 8400.0), (0.5, 6300.0)])
def test_single_mode_benchmark_agrees_with_refined_sdm(immersion, rpm):
    cut = Cut(teeth=2, kt_pa=6e8, kn_pa=2e8, radial_immersion=immersion, milling="down")
    fine = StabilityModel(ONE_DOF, cut, Discretization(steps=160, order=1), workers=1).critical_depths([rpm], rel_tol=1e-5)
    r = converged.critical_depth(ONE_DOF, cut, rpm)
    assert r.verified
    assert r.depth_m == pytest.approx(fine.depth_m[0], rel=0.02)
    assert r.chatter_hz == pytest.approx(fine.dominant_chatter_hz[0], rel=0.01, abs=1.0)


def test_seed004_position5(datasets):
    table = read_modal_table(datasets / "seeds/hou2023_positions.csv")
    dyn = ToolTipDynamics.from_table(table, "P5")
    fine = StabilityModel(dyn, CUT, Discretization(steps=80), workers=1).critical_depths([2000.0], rel_tol=1e-4)
    r = converged.critical_depth(dyn, CUT, 2000.0)
    assert r.verified
    assert r.depth_m == pytest.approx(fine.depth_m[0], rel=0.02)
    assert r.depth_m * 1e3 == pytest.approx(0.891, rel=0.02)
    assert 19.0625 < r.chatter_hz < 1.15 * 19.0625


def test_batched_api_matches_single_calls():
    rs = converged.critical_depths([ROBOT, ONE_DOF, ROBOT], CUT, [5000.0, 5000.0, 12000.0])
    for dyn, rpm, r in zip([ROBOT, ONE_DOF, ROBOT], [5000.0, 5000.0, 12000.0], rs):
        single = converged.critical_depth(dyn, CUT, rpm, verify=False)
        assert r.depth_m == pytest.approx(single.depth_m, rel=1e-6)


def _with_absorber(dyn):
    from absorber.coupling import with_absorber

    return with_absorber(dyn, 3.0, 3.0 * (2 * math.pi * 13.0) ** 2, 0.1)


def test_eigen_frf_matches_the_structure_frf():
    for dyn in (ROBOT, _with_absorber(ROBOT)):
        char = converged.FloquetCharacteristic(dyn, CUT, 4.0)
        w = np.linspace(10.0, 40000.0, 301)
        ref = dyn.rotated(np.deg2rad(CUT.feed_angle_deg)).frf(w)
        assert np.abs(char.frf(w) - ref).max() <= 1e-10 * np.abs(ref).max()


@pytest.mark.parametrize("coupled, rpm", [(False, 1000.0), (False, 12000.0), (True, 5000.0)])
def test_band_seed_search_matches_the_whole_structure_search(monkeypatch, coupled, rpm):
    """The band projections only choose Newton's starting points: every candidate is re-solved
    on the whole structure, so the result equals the whole-structure search."""
    dyn = _with_absorber(ROBOT) if coupled else ROBOT
    fast = converged.critical_depth(dyn, CUT, rpm, verify=False)
    monkeypatch.setattr(converged, "PROJECT_SEEDS", False)
    whole = converged.critical_depth(dyn, CUT, rpm, verify=False)
    assert fast.depth_m == pytest.approx(whole.depth_m, rel=1e-6)
    assert fast.chatter_hz == pytest.approx(whole.chatter_hz, abs=0.1)


def test_a_flip_lobe_peak_is_found_where_the_seeds_give_nothing():
    """Seed 002's host with its TMD (down milling, half immersion, 4 teeth, Kt 660 MPa) at
    1890-1910 rpm: the limit is a period-doubling lobe (chatter at 1.5 x the tooth frequency)
    that no seed starts on; at 1900 rpm the bisection's Newton root sits 0.8 % above the bracket
    and was once refused (the engine said "never chatters"). Checked against the
    semi-discretization at 160 steps, a different method, within 2 %."""
    from absorber.coupling import with_absorber

    fn, k, zeta, mu, gamma, zeta_a = 129.29, 1.34e7, 0.0134, 0.0055, 1.0325086752647734, 0.04730332455745828
    host = ToolTipDynamics.from_modes(y=[Mode(fn, zeta, k)])
    m = mu * k / (2 * math.pi * fn) ** 2
    dyn = with_absorber(host, m, m * (gamma * 2 * math.pi * fn) ** 2, zeta_a, directions=("y",))
    cut = Cut(teeth=4, kt_pa=660e6, kn_pa=180e6, radial_immersion=0.5, milling="down")
    from posedyn.stability import critical_points

    for rpm in (1890.0, 1900.0, 1910.0):
        point = converged.critical_depth(dyn, cut, rpm, rel_tol=0.02)
        assert point.converged and point.verified
        assert point.chatter_hz == pytest.approx(1.5 * 4 * rpm / 60, rel=1e-6)
        sdm = critical_points([dyn], cut, rpm, steps=160)[0]
        assert point.depth_m == pytest.approx(sdm.depth_m, rel=0.02)


def test_no_boundary_point_found_is_unknown_not_never_chatters(monkeypatch):
    """Where the engine finds no boundary point (here: its seeds and repair both taken away) the
    depth is NaN and not converged, never inf, which would read as "never chatters"."""
    from posedyn.stability import critical_points

    monkeypatch.setattr(converged, "zoa_seeds_batch", lambda dyn, cut, taus, char=None: [(np.zeros(0), np.zeros(0), np.zeros(0, int))] * len(taus))
    monkeypatch.setattr(converged, "_repair", lambda *a, **k: None)
    result = critical_points([ONE_DOF], CUT, 9000.0)[0]
    assert math.isnan(result.depth_m) and result.converged is False


@pytest.mark.parametrize("dtype", [float, complex])
def test_batched_exponential_matches_scipy_across_norms_and_sizes(dtype):
    """`sdm.expm_batched` (degree-18 Taylor in five products, scaling and squaring, blocks of the
    stack) against scipy's Pade expm: oscillators of 12 Hz to 10 kHz over 1 ms steps (norms up
    to 60) with a random coupling, and general random stacks, to 1e-12 of the largest entry."""
    import scipy.linalg

    from posedyn.stability import sdm

    rng = np.random.default_rng(7)
    stacks = []
    for n, count, scale in [(8, 5, 0.0), (16, 40, 0.5), (20, 200, 60.0), (24, 33, 8.0)]:
        A = rng.standard_normal((count, n, n)) * scale / math.sqrt(n)
        if dtype is complex:
            A = A + 1j * rng.standard_normal((count, n, n)) * scale / math.sqrt(n)
        stacks.append(A)
    w = 2 * math.pi * np.geomspace(12.0, 1e4, 8) * 1e-3  # rad per 1 ms step, balanced oscillators
    osc = np.zeros((16, 16))
    osc[:8, 8:], osc[8:, :8], osc[8:, 8:] = np.diag(w), -np.diag(w), -np.diag(0.02 * w)
    stacks.append((osc + 0.3 * rng.standard_normal((30, 16, 16))).astype(dtype))
    for A in stacks:
        got = sdm.expm_batched(A)
        want = np.array([scipy.linalg.expm(a) for a in A])
        assert got.dtype == A.dtype
        assert np.max(np.abs(got - want)) <= 1e-12 * max(np.max(np.abs(want)), 1.0)
        buffer = np.full(A.shape, np.nan, dtype=A.dtype)  # written in place, block by block
        assert sdm.expm_batched(A, out=buffer) is buffer
        assert np.array_equal(buffer, got)


def test_the_repairs_newton_starts_skip_a_monodromy_that_overflows():
    """Far past every boundary (10 km here; a blind search reached such depths on a structure
    the cut barely touches) the monodromy overflows for every nu but 1: the repair's starts come
    back empty instead of the eigen-solver raising and taking the result down."""
    char = converged.FloquetCharacteristic(ROBOT, CUT, 8.0)
    tau = float(CUT.tooth_period_s(2000.0))
    with np.errstate(all="ignore"):
        M = char.monodromy(1e4 * (1.0 - np.exp(-1j * np.linspace(0.0, np.pi, 5))), np.full(5, tau))
    assert not np.all(np.isfinite(M))  # the case is the overflow
    depths, thetas = converged._newton_from_nearest(char, tau, 1e4, 16, 4)
    assert np.all(np.isfinite(depths)) and len(depths) == len(thetas)


def test_a_period_doubling_familys_mirror_members_are_one_frequency():
    """At theta = pi every member +w of the Floquet family has its mirror -w, the same frequency
    of the real motion: `chatter` listed '10 (100%), 10 (100%) Hz' (a 10 Hz robot mode, 600 rpm,
    2 teeth). Each frequency is listed once, its members' powers added."""
    dyn = ToolTipDynamics.from_modes(x=[Mode(10.0, 0.04, 8e5), Mode(1450.0, 0.06, 3.3e7), Mode(5200.0, 0.015, 2.5e7)],
                                     y=[Mode(10.8, 0.035, 1.1e6), Mode(1480.0, 0.05, 6e7), Mode(5400.0, 0.012, 2.8e7)])
    point = converged.critical_depth(dyn, Cut(teeth=2, kt_pa=700e6, kn_pa=210e6, radial_immersion=0.5, milling="down"), 600.0)
    assert point.theta_rad == pytest.approx(np.pi) and point.chatter_hz == pytest.approx(10.0)
    frequencies = [hz for hz, _ in point.family]
    assert len(frequencies) == len(set(np.round(frequencies, 6))) and point.family[0] == (point.chatter_hz, 1.0)
