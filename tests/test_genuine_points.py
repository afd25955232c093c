"""Boundary points are zeros of det(I - nu M) (`floquet._genuine`, `floquet.floquet_vectors`).

Where the modes die out between cuts (a few percent immersion at 200-400 rpm: 100-160 e-folds
of free flight), M is graded (singular values from 20 down to 1e-54) and far from normal:
LAPACK's eigenvectors of it can be wrong (residual |M z - mu z| = |z|), its eigenvalues are
known to about 1e-3, and Newton on them settled where det D is regular. A blind check (an
independent C time stepper with exact modal propagators, the delay an integer number of steps,
ARPACK on its tooth-period map and time simulations at 0.95 / 1.05 x, written without reading
the engine; 88 random cases) found three such cases; its figures are the references here.
"""

from __future__ import annotations

import numpy as np
import pytest

from posedyn.stability import Cut, critical_points, floquet
from test_stability_multiscale import structure

# (direction, fn_hz, zeta, k_n_per_m) as the blind check wrote them
H008 = [
    ("x", 19.50616989187957, 0.026522984876427257, 46923974.97023674),
    ("x", 9620.292442546719, 0.026106892208372943, 25053799.871852383),
    ("x", 1859.5672816981566, 0.014316728353885713, 1545149147.0912375),
    ("y", 7.882033389416155, 0.04537098484162097, 5851637.491423887),
    ("y", 23.021793045744722, 0.03241727076578171, 3531411.8646450066),
    ("y", 1846.2915284818835, 0.025129392700198396, 52906332.727856316),
]
G013 = [
    ("x", 5.804586837210627, 0.02628325847038132, 4901954.09152376),
    ("x", 4.174233767441931, 0.039140817617342095, 2072822.4716744144),
    ("x", 8063.046383605552, 0.016011093336554927, 81212228.2703585),
    ("x", 2405.557214838238, 0.021000071742775475, 1135900732.3912227),
    ("y", 17.97210946477643, 0.025931725699132088, 26616862.36849693),
    ("y", 9.357543740821978, 0.03928743108728835, 17537489.81955023),
    ("y", 7043.750454955649, 0.01520248236222554, 15306242.109292574),
    ("y", 9086.669701638719, 0.02811119968640343, 6501506568.176783),
]
G025 = [
    ("x", 9492.578263619322, 0.021171243828241117, 26706455.183057748),
    ("y", 7.425703810839614, 0.03797889563967048, 5279342.65618404),
    ("y", 19.97341998955579, 0.021327286659789724, 23615882.282039583),
    ("y", 9709.154404278132, 0.02687217518426349, 60568103.91649865),
    ("y", 5326.259198033834, 0.012249882321233845, 19244393.777959332),
]


def test_depth_does_not_depend_on_the_order_of_the_modes():
    """h008 (264.3 rpm, 2 teeth, a/D 0.0351, down): the blind check's boundary is 11.363 mm (its
    simulation decays at 0.95 x and grows at 1.05 x of 11.368). Before: 10.67 mm, 'converged',
    with the x modes first, 11.37 mm with the table's order."""
    cut = Cut(teeth=2, kt_pa=665.2e6, kn_pa=179.7e6, radial_immersion=0.0351, milling="down")
    a, b = critical_points([structure(H008), structure(H008[::-1])], cut, 264.3)
    assert a.converged and b.converged
    assert a.depth_m == pytest.approx(b.depth_m, rel=5e-3)
    assert a.depth_m == pytest.approx(11.363e-3, rel=0.02)


def test_chatter_frequency_of_a_graded_monodromy():
    """g013 (394.8 rpm, 2 teeth, a/D 0.0232, down): the blind check's eigenvector and its
    simulation at 1.05 x both chatter at 7089.1 Hz, by the soft 7044 Hz y mode; the engine said
    9084.6 Hz, beside a y mode of k = 6.5e9 N/m that carries 0.1 % of that amplitude."""
    cut = Cut(teeth=2, kt_pa=1979.9e6, kn_pa=548.7e6, radial_immersion=0.0232, milling="down")
    r = critical_points([structure(G013)], cut, 394.8)[0]
    assert r.converged
    assert r.depth_m == pytest.approx(1.5729e-3, rel=0.02)
    assert r.chatter_hz == pytest.approx(7089.1, abs=13.2)  # within one tooth-passing frequency


def test_a_point_where_det_d_is_regular_is_moved_to_its_zero():
    """g025 (319.2 rpm, 2 teeth, a/D 0.0517, down): the engine's point had theta 0.768 where
    det(I - nu M) is 0.42 in modulus; the zero at that depth is at theta 1.805. The blind check:
    boundary 1.6706 mm, chatter 5359.5 Hz (eigenvector and simulation alike)."""
    cut = Cut(teeth=2, kt_pa=1536.5e6, kn_pa=524.7e6, radial_immersion=0.0517, milling="down")
    r = critical_points([structure(G025)], cut, 319.2)[0]
    assert r.converged
    assert r.depth_m == pytest.approx(1.6706e-3, rel=0.02)
    assert r.chatter_hz == pytest.approx(5359.5, abs=10.7)


def test_floquet_vector_is_the_eigenvector_where_m_is_well_conditioned():
    """On an ordinary structure the SVD's null vector of I - nu M is M's eigenvector for 1 / nu."""
    dyn = structure([("x", 600.0, 0.03, 2e7), ("y", 650.0, 0.03, 2.5e7)])
    cut = Cut(teeth=3, kt_pa=800e6, kn_pa=200e6, radial_immersion=0.5, milling="down")
    p = floquet.critical_depth(dyn, cut, 6000.0)
    char = floquet.FloquetCharacteristic(dyn, cut, p.substeps_per_rad)
    tau = float(cut.tooth_period_s(6000.0))
    z, ok = floquet.floquet_vectors(char, np.array([p.depth_m]), np.array([p.theta_rad]), np.array([tau]))
    nu = np.exp(-1j * p.theta_rad)
    M = char.monodromy(np.array([p.depth_m * (1 - nu)]), np.array([tau]))[0]
    assert ok[0]
    assert np.linalg.norm(M @ z[0] - z[0] / nu) < 1e-6 * np.abs(M).max()


@pytest.mark.parametrize("order", [(3, 2, 1, 0), (2, 3, 0, 1), (1, 2, 3, 0), (3, 1, 2, 0), (3, 1, 0, 2)])
def test_a_higher_zero_is_not_the_answer_in_any_order(order):
    """g025 with its y rows in other orders: the engine gave 4.26 and 3.73 mm (not converged),
    where the second blind check's multiplier is 2.29 and 2.01 (chattering hard); its boundary
    lies between 1.6664 and 1.6764 mm. A zero of det D whose count shows a branch below is
    replaced by the lowest zero under it (`_count_bracket`, Newton on det D). In three more of
    the 24 orders the engine gave 1.549 and 1.606 mm 'converged' and 1.107 mm not converged: none
    of them a zero of det D (the count is 0 from below them up to 1.65 mm); a point whose
    null-vector gap is not decisive must now be a crossing (`_crossings_confirmed`), and where
    the count at the point is 0 the crossing is bracketed upward."""
    cut = Cut(teeth=2, kt_pa=1536.5e6, kn_pa=524.7e6, radial_immersion=0.0517, milling="down")
    ys = [r for r in G025 if r[0] == "y"]
    rows = [r for r in G025 if r[0] == "x"] + [ys[i] for i in order]
    r = critical_points([structure(rows)], cut, 319.2)[0]
    assert r.converged
    assert 1.6664e-3 * 0.99 <= r.depth_m <= 1.6764e-3 * 1.01
    assert r.chatter_hz == pytest.approx(5359.5, abs=10.7)


# A blind row-order check (random graded tables, each in 5 orders, through `posedyn chatter`):
# o37 (211.95 rpm, 2 teeth, a/D 0.0765, down, Kt 850.3, Kn 181.5 MPa) in its table's order
O37_X = [("x", 6.521, 0.0315, 3435000.0), ("x", 5267.62, 0.0116, 58030000.0), ("x", 9669.6, 0.0106, 16930000.0), ("x", 9672.83, 0.0288, 10670000.0)]
O37_Y = [("y", 3.206, 0.0439, 41510000.0), ("y", 8.031, 0.0411, 7924000.0), ("y", 20.046, 0.0288, 2320000.0), ("y", 5464.26, 0.0157, 1146000000.0),
         ("y", 9120.05, 0.0123, 18080000.0)]
O37_CUT = Cut(teeth=2, kt_pa=850.3e6, kn_pa=181.5e6, radial_immersion=0.0765, milling="down")


def test_newton_does_not_stop_where_its_secant_derivative_jumped():
    """From the coarse models' boundary point (0.9936 mm, theta 2.7921) Newton on the finest
    model (685 sub-steps a radian, where that point is no zero: the count is 0 from 0.95 to
    1.066 mm) jumped to another eigenvalue (|g| = 87, then 101): the secant G_c made every step
    tiny and it stopped there, 'converged' (floquet.LAST_G)."""
    tau = 60.0 / (211.95 * 2)
    base = floquet.coarsest_substeps(O37_CUT)
    fine = floquet.FloquetCharacteristic(structure(O37_X + O37_Y), O37_CUT, base * 2.0**6)
    a, theta, ok, _, _ = floquet._newton(fine, np.array([0.9936041595834282e-3]), np.array([2.7921]), np.array([tau]), tol=floquet.REFINE_TOL)
    if ok[0]:  # where it converges, on a zero
        g, _ = floquet._critical_log(fine, a, theta, np.array([tau]))
        assert np.abs(g[0]) < floquet.LAST_G


def test_levels_that_agree_on_an_aliased_mode_are_not_converged():
    """o37: the engine gave 0.9936 mm 'converged' (two coarse models, 43 and 86 sub-steps a radian,
    10 and 5 periods of the 9.4-9.7 kHz modes a sub-step, agreed to 5e-4) and 1.0706 mm with the
    modes in descending order. The independent simulation (tests/independent_milling_sim.py,
    6 and 12 s records) decays at 1.03 mm and grows at 1.11 mm; its default 3 s record grows from
    0.75 mm (the robot modes' transient). The look-ahead across several levels is now Newton to
    the root there, not one step from the coarse point."""
    r = critical_points([structure(O37_X + O37_Y)], O37_CUT, 211.95)[0]
    assert r.converged
    assert 1.03e-3 <= r.depth_m <= 1.11e-3
    assert r.chatter_hz == pytest.approx(9406.7, abs=2 * 7.07)


# c097 of a blind check: 7-12 Hz robot modes under 8.1-9.0 kHz spindle modes, 2 teeth at 239 rpm
C097_ROWS = [("x", 7.17259, 0.02451, 1709100.0), ("x", 9018.76, 0.0161, 43448000.0), ("y", 7.17014, 0.02499, 3426200.0),
             ("x", 10.3141, 0.04999, 32873000.0), ("y", 8148.3, 0.01732, 1989500000.0), ("y", 8153.64, 0.02066, 4813100.0),
             ("y", 8586.77, 0.02072, 141420000.0), ("y", 11.6522, 0.03203, 4446100.0)]
C097_CUT = Cut(teeth=2, kt_pa=1088.8e6, kn_pa=421.5e6, radial_immersion=0.0958, milling="down")


def test_a_point_lost_twice_in_place_skips_the_aliased_levels(monkeypatch):
    """c097: the 8.15 kHz y mode is 9 times as stiff as the cut and vibrates 1000 times a tooth
    period. Newton cannot follow its branch from one level to the next (0.4421 mm at 19 sub-steps
    a radian, 0.4399 at 38, ...: the branch stays put), and each loss solved the job again from
    the seeds one level up, level by level to the finest (70 s at the default finest level). A
    second loss in place now goes on at the first level that resolves that mode (here the
    finest, lowered to 76 a radian to keep the test short): the answer the level-by-level chain
    gives (0.43948792 mm, measured with the code before), without the solve at 38."""
    monkeypatch.setattr(floquet, "MAX_SUBSTEPS_PER_RAD", 64.0)
    resolutions = []
    solve = floquet._solve

    def counted(*args, **kwargs):
        resolutions.append(args[4])
        return solve(*args, **kwargs)

    monkeypatch.setattr(floquet, "_solve", counted)
    p = floquet.critical_depth(structure(C097_ROWS), C097_CUT, 238.93)
    assert p.converged and p.verified
    assert p.depth_m == pytest.approx(0.4394879238e-3, rel=1e-6)
    base = floquet.coarsest_substeps(C097_CUT)
    assert resolutions == [None, pytest.approx(2 * base), pytest.approx(8 * base)]
