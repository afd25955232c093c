"""The winding count behind every verified critical depth (`floquet.unstable_count`): the number
of Floquet multipliers outside the unit circle, from an interpolant of the monodromy on the unit
circle (`monodromy_polynomial`), checked against the multipliers of the dense
semi-discretization written as seed 004 states it (`reference`, scipy's expm and LAPACK
eigenvalues: nothing shared with the Floquet characteristic but the cut's force integrals) and
against the count from direct samples."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import independent_milling_sim as sim
from posedyn.dynamics import ToolTipDynamics
from posedyn.stability import Cut, floquet, reference
from posedyn.table import Mode

CASES = [  # (modes x, modes y, cut, rpm): a few vibration periods per tooth period, where 100 steps are plenty
    ([Mode(922.0, 0.011, 3.35e6)], [Mode(922.0, 0.011, 3.35e6)], Cut(teeth=2, kt_pa=6e8, kn_pa=2e8, radial_immersion=1.0, milling="down"), 9000.0),
    ([Mode(700.0, 0.02, 8e6), Mode(1600.0, 0.03, 2e7)], [Mode(850.0, 0.015, 1e7)], Cut(teeth=3, kt_pa=7e8, kn_pa=2e8, radial_immersion=0.3, milling="up"), 7000.0),
    ([Mode(1200.0, 0.01, 2e7)], [Mode(1350.0, 0.012, 1.5e7), Mode(60.0, 0.04, 5e7)], Cut(teeth=4, kt_pa=8e8, kn_pa=2.5e8, radial_immersion=0.6, milling="down"), 12000.0),
]


def _reference_count(dyn, cut, rpm, depth):
    mu = np.abs(np.linalg.eigvals(reference.monodromy(dyn, cut, rpm, depth, 100)))
    return int(np.sum(mu > 1.0)), float(np.min(np.abs(mu - 1.0)))


@pytest.mark.parametrize("case", range(len(CASES)))
def test_the_count_is_the_number_of_multipliers_outside_the_circle(case):
    x, y, cut, rpm = CASES[case]
    dyn = ToolTipDynamics.from_modes(x=x, y=y)
    char = floquet.FloquetCharacteristic(dyn, cut, 16.0)
    tau = float(cut.tooth_period_s(rpm))
    seen = []
    for depth in np.geomspace(2e-5, 2e-2, 10):
        expected, margin = _reference_count(dyn, cut, rpm, depth)
        if margin < 0.01:  # a multiplier on the circle: the discretizations may disagree
            continue
        count, resolved, _ = floquet.unstable_count(char, depth, tau)
        assert resolved and count == expected, (depth, count, expected)
        seen.append(count)
    assert len(seen) >= 6 and seen[0] == 0 and max(seen) >= 2  # stable, then one and more pairs outside


def test_the_interpolated_count_is_the_directly_sampled_one(monkeypatch):
    """Forcing the fallback (no segment interpolant converges with 2 nodes) samples M directly; both paths
    give the same count on the robot-plus-spindle structure of issue 17 below and above its
    critical depth (1.516 mm at 2000 rpm), where the count is 0 and then grows."""
    from test_stability_multiscale import CUT, TABLE, structure

    char = floquet.FloquetCharacteristic(structure(TABLE), CUT, 4.0)
    tau = float(CUT.tooth_period_s(2000.0))
    depths = [0.5e-3, 1.48e-3, 1.6e-3, 3e-3, 6e-3]
    interpolated = [floquet.unstable_count(char, a, tau)[:2] for a in depths]
    monkeypatch.setattr(floquet, "SUBSTEP_NODES", (2, 2))
    direct = [floquet.unstable_count(char, a, tau)[:2] for a in depths]
    assert interpolated == direct
    assert [c for c, _ in interpolated][:2] == [0, 0] and all(c > 0 for c, _ in interpolated[2:])
    assert all(r for _, r in interpolated)


#: A robot with four lightly damped modes at 4-112 Hz and a spindle to 8.6 kHz (a random case of
#: the blind island search, 2026-12-03): direction, fn_hz, zeta, k_n_per_m.
ROBOT_ROWS = [
    ("x", 3.8012758934076913, 0.07702027193887312, 14148267.774466194), ("x", 79.56628167719816, 0.07525207027053424, 9951742.687501732),
    ("x", 1829.6070580408639, 0.07386340410443817, 5388494.904582684), ("x", 3381.116660376485, 0.03449923262284177, 9571208.035941876),
    ("y", 4.5392775553926725, 0.060391333420281634, 15646079.483703842), ("y", 112.06036658568266, 0.05043521772913321, 3412041.108889614),
    ("y", 1835.6204255556706, 0.041335215841747625, 5587955.840883304), ("y", 8554.38235320967, 0.03936104457410703, 23737076.14876527),
]
ROBOT_CUT = Cut(teeth=6, kt_pa=1034231816.7058289, kn_pa=170304724.38159108, radial_immersion=0.5732450350099244, milling="up")


def test_robot_modes_close_to_the_circle_do_not_alias_the_count():
    """At 6962 rpm and 6 teeth the robot modes' free multipliers lie within 2.5e-3 of the unit
    circle, several zeros of h inside the first step of the 64-point grid: their half turns of
    phase added up to a whole one the step test could not see, and the count said 2 unstable
    multipliers (resolved) at a twentieth of the critical depth, where the independent
    simulation (tests/independent_milling_sim.py) decays. The count now always samples the free
    multipliers' angles."""
    dyn = ToolTipDynamics.from_modes(x=[Mode(f, z, k) for d, f, z, k in ROBOT_ROWS if d == "x"], y=[Mode(f, z, k) for d, f, z, k in ROBOT_ROWS if d == "y"])
    rpm = 6961.76149699935
    result = floquet.critical_depth(dyn, ROBOT_CUT, rpm)
    tau = float(ROBOT_CUT.tooth_period_s(rpm))
    char = floquet.FloquetCharacteristic(dyn, ROBOT_CUT, result.substeps_per_rad)
    for fraction in (0.05, 0.5, 0.9):
        assert floquet.unstable_count(char, fraction * result.depth_m, tau)[:2] == (0, True)
    assert sim.grows_either_side(ROBOT_ROWS, ROBOT_CUT, rpm, result.depth_m, below=0.9) == (False, True)


#: A blind check's table (2026-12-07): x and y robot modes paired within 0.1 % (16.70 / 16.71 Hz,
#: 30.10 / 30.12 Hz), spindle modes at 1-2 kHz; 5 teeth, full immersion, up milling, 22,919 rpm.
PAIRED_ROWS = [("x", 16.7005, 0.03339, 15119000.0), ("x", 30.1003, 0.06992, 7686200.0), ("x", 28.5974, 0.0187, 7397900.0),
               ("x", 6.18145, 0.04048, 11436000.0), ("x", 2090.27, 0.05924, 8940000.0), ("x", 988.578, 0.04056, 529040000.0),
               ("y", 16.7146, 0.05003, 18698000.0), ("y", 30.1172, 0.01617, 45041000.0), ("y", 1709.82, 0.0201, 6841000.0),
               ("y", 2021.58, 0.04222, 5800000.0), ("y", 2091.72, 0.0364, 139410000.0)]
PAIRED_CUT = Cut(teeth=5, kt_pa=1980.2e6, kn_pa=862.2e6, radial_immersion=1.0, milling="up")
PAIRED_RPM = 22918.6


def test_free_zeros_narrower_than_the_grid_are_sampled_either_side():
    """With a tooth period of 0.52 ms the robot modes' zeros of h lie 1.8e-3 to 4e-3 inside the
    circle, five of them (the paired modes and 28.6 Hz) between two samples of the uniform grid
    even with their own angles sampled: the count said 2 unstable multipliers, 'resolved', at
    1e-9 m, the answer (0.3499 mm, converged) was reported not verified, after 47 s of repairs
    that found nothing below it. The count now also samples each such zero's angle +- its width:
    0 down there, and the answer verified; the independent simulation decays 5 % below it and
    grows 5 % above."""
    dyn = ToolTipDynamics.from_modes(x=[Mode(f, z, k) for d, f, z, k in PAIRED_ROWS if d == "x"], y=[Mode(f, z, k) for d, f, z, k in PAIRED_ROWS if d == "y"])
    tau = float(PAIRED_CUT.tooth_period_s(PAIRED_RPM))
    char = floquet.FloquetCharacteristic(dyn, PAIRED_CUT, 8.0)
    assert floquet.unstable_count(char, 1e-9, tau)[:2] == (0, True)
    result = floquet.critical_depth(dyn, PAIRED_CUT, PAIRED_RPM)
    assert result.converged and result.verified
    assert result.depth_m == pytest.approx(0.3499e-3, rel=1e-3) and result.chatter_hz == pytest.approx(1714.0, rel=1e-3)
    for fraction in (0.05, 0.5, 0.9):
        assert floquet.unstable_count(char, fraction * result.depth_m, tau)[:2] == (0, True)
    assert sim.grows_either_side(PAIRED_ROWS, PAIRED_CUT, PAIRED_RPM, result.depth_m) == (False, True)


def test_the_inverse_norm_screen_agrees_with_the_inverse():
    """Every sample's Rouche check needs |D^-1|_F below a limit; a bound from det D and |D|_F
    (AM-GM on the other singular values) decides most samples without an inverse. It must give
    exactly the answer of the inverse, on well-conditioned, nearly singular and large matrices."""
    rng = np.random.default_rng(7)
    m = 24
    D = rng.normal(size=(300, m, m)) + 1j * rng.normal(size=(300, m, m))
    D[:100] = np.eye(m) + 0.05 * D[:100]  # well conditioned: decided by the bound
    u, s, vh = np.linalg.svd(D[100:200])
    s[:, -1] *= 10.0 ** rng.uniform(-14, 0, size=100)  # nearly singular
    D[100:200] = u @ (s[:, :, None] * vh)
    D[200:] *= 10.0 ** rng.uniform(-3, 3, size=(100, 1, 1))
    _, logdet = np.linalg.slogdet(D)
    exact = np.linalg.norm(np.linalg.inv(D), axis=(1, 2))
    for limit in (1e2, 1e6, 1e12):
        assert np.array_equal(floquet._inverse_norms_below(D, logdet, limit), exact < limit)


def test_segment_blocks_change_the_memory_not_the_numbers(monkeypatch):
    """Per-segment arrays are built in blocks of SEGMENT_BLOCK_BYTES (a full cut at 512 sub-steps a
    radian has thousands of segments; at once they took 3.7 GB on one pose): blocks of a few
    segments give the count the same interpolants, product and error bound, bit for bit, as one
    block, and the same monodromies (to rounding: expm scales each block of its stack by its
    own norm) and chatter families, on the issue-17 structure at 64 sub-steps a radian."""
    from test_stability_multiscale import CUT, TABLE, structure

    char = floquet.FloquetCharacteristic(structure(TABLE), CUT, 64.0)
    tau = float(CUT.tooth_period_s(2000.0))
    E = floquet.segment_samples(char, 1.5e-3, tau, 16)
    assert len(E) > 40  # enough segments for several blocks

    c = 1.5e-3 * (1.0 - np.exp(-1j * np.linspace(0.0, np.pi, 9)))

    def count_parts():
        coef, error = floquet.segment_interpolants(E, 16)
        return coef, error, *floquet.circle_monodromies(coef, error, 32)

    def families():
        return floquet.floquet_families(char, [1.5e-3, 1.6e-3], [1.9, 2.3], tau)

    whole, M, fam = count_parts(), char.monodromy(c, np.full(len(c), tau)), families()
    per_segment = 16 * E[0, 0].size * 16  # the FFT's bytes a segment (16 roots)
    monkeypatch.setattr(floquet, "SEGMENT_BLOCK_BYTES", 7 * per_segment)  # 7 segments a block there, 6 in the products (17 roots)
    assert len(floquet._blocks(len(E), 17 * E[0, 0].size * 16)) > 5
    for w, b in zip(whole, count_parts()):
        np.testing.assert_array_equal(w, b)
    assert len(floquet._blocks(len(c), len(E) * E[0, 0].size * 16)) == len(c)  # a monodromy a block
    np.testing.assert_allclose(char.monodromy(c, np.full(len(c), tau)), M, rtol=0, atol=1e-12 * np.abs(M).max())
    for (hz, family), (hz_b, family_b) in zip(fam, families()):
        assert hz == hz_b and len(family) == len(family_b)
        np.testing.assert_allclose(np.array(family_b), np.array(family), rtol=1e-9)


def test_a_count_whose_monodromy_overflows_is_unresolved_without_a_warning(monkeypatch):
    """Far past every boundary (the repair of an absorber case that reads 452 mm counted at
    metres) M overflows: the direct count says it is not resolved, prints no RuntimeWarning, and
    does not refine its grid up to 4096 samples for a count no sample can resolve (that case's
    repair spent 270 of its 400 s there)."""
    from test_stability_multiscale import CUT, TABLE, structure

    char = floquet.FloquetCharacteristic(structure(TABLE), CUT, 4.0)
    tau = float(CUT.tooth_period_s(2000.0))
    with warnings.catch_warnings():  # the interpolants first: their products overflow too
        warnings.simplefilter("error")
        assert not floquet.unstable_count(char, 1e6, tau)[1]
    monkeypatch.setattr(floquet, "SUBSTEP_NODES", (2, 2))  # the direct samples
    sampled = []
    monodromy = char.monodromy
    monkeypatch.setattr(char, "monodromy", lambda c, t: sampled.append(len(c)) or monodromy(c, t))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        count, resolved, _ = floquet.unstable_count(char, 1e6, tau)
    assert not resolved
    assert len(sampled) == 1 and sampled[0] <= 2 * floquet.VERIFY_POINTS  # the first grid only


def test_a_count_beyond_double_precision_is_unresolved_without_direct_samples(monkeypatch):
    """Where M's entries pass MONODROMY_LIMIT (finite, no overflow) the LU of I - nu M cannot see
    the factors near the circle: the count is not resolved, and no monodromy is sampled directly
    (before: 13 and 22 s of direct samples for counts of 67 and -30 at 0.1 and 0.5 m on the
    issue-17 structure; on a 300 rpm, one-tooth structure 60-80 s a count inside a repair's
    bisection). Below the limit (20 mm, |M| ~ 1e8) the count is taken as before."""
    from test_stability_multiscale import CUT, TABLE, structure

    char = floquet.FloquetCharacteristic(structure(TABLE), CUT, 8.0)
    tau = float(CUT.tooth_period_s(2000.0))
    sampled = []
    monodromy = char.monodromy
    monkeypatch.setattr(char, "monodromy", lambda c, t: sampled.append(len(c)) or monodromy(c, t))
    for depth in (0.1, 0.5):
        count, resolved, theta = floquet.unstable_count(char, depth, tau)
        assert (count, resolved) == (0, False) and np.isnan(theta) and not sampled
    count, resolved, _ = floquet.unstable_count(char, 0.02, tau)
    assert resolved and count > 0
