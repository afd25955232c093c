"""Hopf islands (issue 17): a complex pair of Floquet multipliers that leaves the unit circle at
one depth and comes back at a larger one makes the cut unstable only inside that interval; the
winding count above the island is 0, so an answer above it looks verified. The case: a sweep
pose of the shipped twin with seed 004's MRF absorber (tests/data/hopf_island_pose.json), 2000
rpm, where the cut chatters from 4.0 mm (theta 1.27: 20 Hz plus tooth-passing harmonics), is
stable again above an island under 0.5 mm wide and chatters once more from 6.04 mm. The engine once reported 6.04 mm "verified" here, two
ways: the count at half the answer's resolution (below the answer instead of below the branch's
own depth there) sent the 4.0 mm answer back to the seeds at 32 sub-steps a radian, and there
the band projection lost the seed that leads to the island (a Newton on the whole structure
finds it at every resolution).

The check of the island's bottom is independent of the engine's numerics: the characteristic
equation det(I - nu M(a (1 - nu))) = 0 with M integrated by scipy's DOP853 through the exact
time-varying cutting force (no segment averages, no Taylor exponentials), solved by Newton with
finite differences from the engine's point."""

from __future__ import annotations

import json
import math
from pathlib import Path

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

DOC = json.loads((Path(__file__).parent / "data" / "hopf_island_pose.json").read_text())
STRUCTURE = ToolTipDynamics(np.array(DOC["fn_hz"]), np.array(DOC["zeta"]), np.array(DOC["shapes"]),
                            coupling=(np.array(DOC["stiffness"]), np.array(DOC["damping"])))
CUT = Cut(**DOC["cut"])
RPM = DOC["rpm"]
TAU = float(CUT.tooth_period_s(RPM))

#: A random robot-plus-spindle structure with an absorber (blind island search, 2026-12-03):
#: host rows (direction, fn_hz, zeta, k_n_per_m), absorber (kg, N/m, zeta), cut, rpm.
RANDOM_HOST = [
    ("x", 12.442679591415466, 0.03620277682177345, 505941.219817937), ("x", 53.069614500255554, 0.009576978786108432, 8846879.601643812),
    ("x", 1122.7446622737098, 0.07211448141921101, 6681848.696870184), ("x", 8890.612025233964, 0.059534913630756366, 16344599.261869505),
    ("y", 27.7955228196534, 0.06324662033777198, 12576857.958449354), ("y", 106.42579881956344, 0.06123234959591703, 653622.806893307),
    ("y", 2031.267694897134, 0.023955498905746758, 12521562.250690142), ("y", 4592.8850790641145, 0.04908931849475501, 13858607.324305397),
]
RANDOM_ABSORBER = (4.0674382465050085, 800981.0564214671, 0.057960419156117424)
RANDOM_CUT = Cut(teeth=5, kt_pa=619571634.7892177, kn_pa=114744593.6302568, radial_immersion=0.6451622969930663, milling="down")
RANDOM_RPM = 10359.715885937554


def absorber_structure(rows, absorber) -> ToolTipDynamics:
    """The host of (direction, fn_hz, zeta, k_n_per_m) rows with the absorber (kg, N/m, zeta)."""
    host = ToolTipDynamics.from_modes(x=[Mode(f, z, k) for d, f, z, k in rows if d == "x"], y=[Mode(f, z, k) for d, f, z, k in rows if d == "y"])
    return with_absorber(host, *absorber)


def exact_log(dyn: ToolTipDynamics, cut: Cut, rpm: float, depth_m: float, theta: float) -> complex:
    """ln(nu mu) for the multiplier mu of the period map (`exact_multipliers`) nearest 1 / nu."""
    nu = np.exp(-1j * theta)
    mu = exact_multipliers(dyn, cut, rpm, depth_m, theta)
    return complex(np.log(nu * mu[np.argmin(np.abs(mu - 1.0 / nu))]))


def exact_multipliers(dyn: ToolTipDynamics, cut: Cut, rpm: float, depth_m: float, theta: float) -> np.ndarray:
    """Eigenvalues of the period map of q'' + C q' + K q = c W(t) q with c = -a (1 - nu),
    nu = exp(-i theta), integrated by DOP853 (rtol 1e-10) over one tooth period, piece by piece
    between the teeth's entries and exits (several teeth may cut at once), and by scipy's expm
    where none cuts."""
    n = dyn.n_modes
    K, C = dyn.stiffness_matrix, dyn.damping_matrix
    nu = np.exp(-1j * theta)
    c = depth_m * (1.0 - nu)
    omega = 2.0 * math.pi * rpm / 60.0
    tau = float(cut.tooth_period_s(rpm))
    st, ex = cut.engagement_rad

    def generator(t):
        W = dyn.force_shapes.T @ force_matrix(cut, np.array(omega * t)) @ dyn.shapes
        A = np.zeros((2 * n, 2 * n), complex)
        A[:n, n:] = np.eye(n)
        A[n:, :n] = -K - c * W
        A[n:, n:] = -C
        return A

    # one tooth period from tooth 0's entry, in pieces between every tooth's entry and exit:
    # DOP853 where a tooth cuts, scipy's expm where none does
    t_in = st / omega
    edges = np.mod(np.array([[st, ex]]) - 2.0 * np.pi * np.arange(cut.teeth)[:, None] / cut.teeth - st, 2.0 * np.pi) / omega
    times = np.unique(np.concatenate([[0.0, tau], edges[(edges > 0) & (edges < tau)]])) + t_in
    period = np.eye(2 * n, dtype=complex)
    for t0, t1 in zip(times[:-1], times[1:]):
        A_mid = generator(0.5 * (t0 + t1))
        if not np.any(A_mid[n:, :n] + K):  # free flight
            period = scipy.linalg.expm(A_mid * (t1 - t0)) @ period
            continue
        # the force jumps at a piece's ends: inside the piece it is the piece's (evaluated at an end,
        # a tooth that exits there still cuts, and DOP853 then fails at the first step)
        inner = 1e-9 * (t1 - t0)
        flow = scipy.integrate.solve_ivp(lambda t, y: (generator(min(max(t, t0 + inner), t1 - inner)) @ y.reshape(2 * n, 2 * n)).ravel(), (t0, t1),
                                         np.eye(2 * n, dtype=complex).ravel(), method="DOP853", rtol=1e-10, atol=1e-12)
        assert flow.success, flow.message
        period = flow.y[:, -1].reshape(2 * n, 2 * n) @ period
    return np.linalg.eigvals(period)


def exact_boundary_point(dyn, cut, rpm, depth_m: float, theta: float, iterations: int = 4):
    """Newton on (Re, Im) ln(nu mu) = 0 in (depth, theta), Jacobian by forward differences."""
    g_of = lambda x: exact_log(dyn, cut, rpm, *x)  # noqa: E731
    x = np.array([depth_m, theta])
    for _ in range(iterations):
        g = g_of(x)
        ga, gt = (g_of([x[0] * (1 + 1e-6), x[1]]) - g) / (x[0] * 1e-6), (g_of([x[0], x[1] + 1e-6]) - g) / 1e-6
        J = np.array([[ga.real, gt.real], [ga.imag, gt.imag]])
        x = x - np.linalg.solve(J, [g.real, g.imag])
    return x, abs(g_of(x))


def test_the_reported_depth_is_the_bottom_of_the_hopf_island():
    r = floquet.critical_depth(STRUCTURE, CUT, RPM)
    assert r.verified and r.converged
    (depth, theta), residual = exact_boundary_point(STRUCTURE, CUT, RPM, r.depth_m, r.theta_rad)
    assert residual < 1e-8
    # the exact model loses stability there (a boundary point bounds the critical depth from
    # above: the 6.04 mm once reported is 50 % too deep), and the engine is within its tolerance
    assert abs(r.depth_m / depth - 1.0) < 0.02 and abs(theta - r.theta_rad) < 0.01
    assert 3.9e-3 < r.depth_m < 4.1e-3


@pytest.mark.parametrize("substeps_per_rad", [8.0, 32.0])
def test_the_island_is_found_from_any_resolution(substeps_per_rad):
    """At 32 sub-steps a radian the band projection's Newton from the 18.6 Hz seed did not
    converge and nothing else led below the 6.04 mm branch; such a seed is now tried once more on
    the whole structure."""
    r = floquet.critical_depth(STRUCTURE, CUT, RPM, substeps_per_rad=substeps_per_rad)
    assert 3.9e-3 < r.depth_m < 4.1e-3 and r.verified


def test_the_count_above_the_island_cannot_see_it():
    char = floquet.FloquetCharacteristic(STRUCTURE, CUT, 32.0)
    assert floquet.unstable_count(char, 0.995 * 6.04e-3, TAU)[:2] == (0, True)  # stable again
    assert floquet.unstable_count(char, 4.1e-3, TAU)[:2] == (2, True)  # inside: a complex pair
    assert floquet.unstable_count(char, 4.5e-3, TAU)[:2] == (0, True)  # above it


def test_hills_seeds_lead_to_an_island_the_zeroth_order_misses():
    """A random absorber-coupled structure at 10,360 rpm (5 teeth, a/D 0.65): unstable from 4.40
    mm in an island, stable again, unstable from 10.40 mm. The zeroth-order and flip seeds led
    only to the 10.40 mm branch, reported verified; Hill's boundary points (two harmonics) are
    now seeds of every coupled structure. The island's bottom is a boundary point of the DOP853
    characteristic."""
    dyn = absorber_structure(RANDOM_HOST, RANDOM_ABSORBER)
    r = floquet.critical_depth(dyn, RANDOM_CUT, RANDOM_RPM)
    assert r.verified and r.converged and r.depth_m < 5e-3
    (depth, theta), residual = exact_boundary_point(dyn, RANDOM_CUT, RANDOM_RPM, r.depth_m, r.theta_rad)
    assert residual < 1e-8 and abs(r.depth_m / depth - 1.0) < 0.02


#: Another random absorber-coupled structure of the blind search (2 teeth, up milling a/D 0.56,
#: 11,916 rpm): an island of complex multipliers from 5.96 mm that exists only with a finer cut
#: model (none at 4 sub-steps a radian, from 6.15 mm at 8, from 5.96 mm at 16), under a 9.88 mm
#: answer the engine reported verified.
FINE_HOST = [
    ("x", 10.2127009057723, 0.03728300580608988, 653476.2287403669), ("x", 44.78024501520054, 0.07815885073197382, 432311.0867128087),
    ("x", 1679.2232418482226, 0.04038428872244494, 7808958.828663263), ("x", 7931.957943391557, 0.04916432951890052, 27541331.169412237),
    ("y", 17.29987447293256, 0.049850686759838954, 3251287.475134527), ("y", 48.81930339954994, 0.06935844224709932, 4088394.975860864),
    ("y", 665.2724974685877, 0.055534000923961026, 24432825.49411955), ("y", 3482.0968562662842, 0.0383734360967785, 54038615.5519196),
]
FINE_ABSORBER = (4.845756264648422, 1068811.6802897346, 0.08958282099375106)
FINE_CUT = Cut(teeth=2, kt_pa=1936175782.7479324, kn_pa=287855714.0924721, radial_immersion=0.5629524006183383, milling="up")
FINE_RPM = 11916.151694649065


def test_an_island_only_a_finer_cut_model_has_is_found_from_hills_seeds_there():
    """Hill's lowest boundary point (6.30 mm, theta 0.91) reaches no boundary point on the coarse
    cut model, where the island does not exist; such a seed below the answer is tried once more at
    the answer's resolution. The bottom is a boundary point of the DOP853 characteristic."""
    dyn = absorber_structure(FINE_HOST, FINE_ABSORBER)
    coarse = floquet.FloquetCharacteristic(dyn, FINE_CUT, floquet.SUBSTEPS_PER_RAD)
    assert floquet.unstable_count(coarse, 6.5e-3, float(FINE_CUT.tooth_period_s(FINE_RPM)))[:2] == (0, True)  # no island there
    r = floquet.critical_depth(dyn, FINE_CUT, FINE_RPM)
    assert r.verified and r.converged and r.depth_m < 6.5e-3
    (depth, theta), residual = exact_boundary_point(dyn, FINE_CUT, FINE_RPM, r.depth_m, r.theta_rad)
    assert residual < 1e-8 and abs(r.depth_m / depth - 1.0) < 0.02


#: A random uncoupled structure of the blind search (seed 5, case 1348): rows (direction, fn_hz,
#: zeta, k_n_per_m); 6 teeth in up milling at a/D 0.23, 3127 rpm. A complex pair is outside the
#: circle from about 0.5 to 0.8 of 5.54 mm and inside again up to it; the engine reported 5.54 mm,
#: verified, and the count at 0.995 x that is 0.
WIDE_ROWS = [
    ("x", 5.53633551098822, 0.013943193444801622, 11866110.469663233), ("x", 76.79554808254386, 0.04628044815725871, 498562.251531207),
    ("x", 1759.6983660393676, 0.020526963573863313, 30813663.169850037), ("x", 7042.337090983038, 0.0680749094835634, 6034980.025930906),
    ("y", 28.034343921894838, 0.02538749461374983, 10043706.030383682), ("y", 116.57130105967398, 0.06574423891352693, 10383607.468590379),
    ("y", 666.821046370839, 0.02237580116879269, 6263405.543131326), ("y", 3353.411043997595, 0.07374094143338566, 24221238.250454765),
]
WIDE = ToolTipDynamics.from_modes(x=[Mode(f, z, k) for d, f, z, k in WIDE_ROWS if d == "x"], y=[Mode(f, z, k) for d, f, z, k in WIDE_ROWS if d == "y"])
WIDE_CUT = Cut(teeth=6, kt_pa=381954714.1274106, kn_pa=70749907.6231721, radial_immersion=0.23298624678930002, milling="up")
WIDE_RPM = 3126.7927050531944


def test_the_hopf_rungs_find_an_island_the_count_above_it_cannot_see():
    """The counts at HOPF_RUNGS x the answer on the verification count's interpolant
    (`hopf_rung`) see the island under the old answer; the reported depth is its bottom: the
    independent time-domain simulation (tests/independent_milling_sim.py) decays 5 % below it
    and grows 5 % above."""
    char = floquet.FloquetCharacteristic(WIDE, WIDE_CUT, floquet.SUBSTEPS_PER_RAD)
    tau = float(WIDE_CUT.tooth_period_s(WIDE_RPM))
    poly: list = []
    a0 = floquet.VERIFY_FRACTION * 5.54e-3
    assert floquet.unstable_count(char, a0, tau, polynomial=poly)[:2] == (0, True) and poly  # blind above the island
    rung = floquet.hopf_rung(char, a0, *poly[0], tau)
    assert rung is not None and floquet.unstable_count(char, rung, tau)[0] > 0  # the rung's count on M itself
    r = floquet.critical_depth(WIDE, WIDE_CUT, WIDE_RPM)
    assert r.verified and r.converged and r.depth_m < rung
    assert sim.grows_either_side(WIDE_ROWS, WIDE_CUT, WIDE_RPM, r.depth_m) == (False, True)


#: A random absorber structure of the blind search (seed 6, case 312): reported 17.72 mm, not
#: verified (the count at 8 sub-steps a radian is 2 from 12.3 mm up), because the bisection's
#: Newton from the four multipliers nearest the boundary at the top of its bracket reached
#: nothing: the crossing's multiplier is the fifth.
FIFTH_HOST = [
    ("x", 10.190453787720594, 0.06668682086037708, 5244835.205723401), ("x", 37.793396689543954, 0.036989571846542085, 15666954.660580318),
    ("x", 1204.616449264388, 0.014264277121138539, 89878536.75896703), ("x", 7682.6049582013065, 0.07937978812167323, 19126655.603107583),
    ("y", 6.584977459208876, 0.07141193559986256, 1584695.3365706208), ("y", 95.61502874513835, 0.06899771070777252, 12866890.881527511),
    ("y", 2287.6548336353108, 0.07749409465579879, 36151330.14741055), ("y", 8089.146677598521, 0.051096471720321404, 18805530.932410877),
]
FIFTH_ABSORBER = (1.3441874054521734, 161615.01495205573, 0.07161004433027829)
FIFTH_CUT = Cut(teeth=5, kt_pa=773233678.3424386, kn_pa=133065048.39556548, radial_immersion=0.4507039641248607, milling="down")
FIFTH_RPM = 4959.0006634184665


def test_the_repair_tries_every_multiplier_where_the_nearest_few_reach_nothing():
    """The bisection's Newton starts from every local minimum of the multipliers' distance to the
    boundary where the nearest four reach nothing; the answer is verified, repaired, and a
    boundary point of the DOP853 characteristic (overlapping teeth: two cut at once for a sixth
    of the tooth period)."""
    dyn = absorber_structure(FIFTH_HOST, FIFTH_ABSORBER)
    r = floquet.critical_depth(dyn, FIFTH_CUT, FIFTH_RPM)
    assert r.verified and r.converged and r.repaired and r.depth_m < 13e-3
    (depth, theta), residual = exact_boundary_point(dyn, FIFTH_CUT, FIFTH_RPM, r.depth_m, r.theta_rad, iterations=2)
    assert residual < 1e-6 and abs(r.depth_m / depth - 1.0) < 0.02


#: A random absorber structure of the blind search (seed 6, case 2708): 3 teeth in down milling at
#: a/D 0.08, 10,439 rpm. A complex pair meets on the negative axis at -0.994 and splits; one
#: real multiplier passes -1 at 3.97 mm. Newton on one eigenvalue from the top of the
#: bisection's bracket reached nothing there, and refinement ended on a higher flip point
#: (6.20 mm, not verified).
SPLIT_HOST = [
    ("x", 5.459632985714472, 0.06292582422384294, 455009.24086028), ("x", 40.428305847149666, 0.06185953700377809, 5837968.124892279),
    ("x", 2107.4929431843693, 0.03930034757756002, 4188272.10370656), ("x", 8884.891685559614, 0.05902140883086698, 57286417.52683269),
    ("y", 16.586215246204613, 0.011268920075337889, 2232261.1574659576), ("y", 81.17549343181349, 0.07484330724630181, 898436.4279264886),
    ("y", 1179.8396308037268, 0.02405116349396992, 17068310.439825293), ("y", 7637.272959971531, 0.009995246526318776, 95022699.16683482),
]
SPLIT_ABSORBER = (2.224603639767833, 507003.94098809926, 0.05215085665356857)
SPLIT_CUT = Cut(teeth=3, kt_pa=1878930414.5749757, kn_pa=227782739.82535964, radial_immersion=0.07706160206548808, milling="down")
SPLIT_RPM = 10439.205006564764


def test_a_flip_point_just_after_a_complex_pair_splits_is_found_on_the_flip_condition():
    """Where Newton fails in the bisection's bracket and det(I + M(2 a)) changes sign there, the
    root of that real determinant (Brent) is the boundary point. Independent: the DOP853 period
    map at nu = -1 has every multiplier inside the circle 2 % below the reported depth and a real
    one below -1 2 % above it."""
    dyn = absorber_structure(SPLIT_HOST, SPLIT_ABSORBER)
    r = floquet.critical_depth(dyn, SPLIT_CUT, SPLIT_RPM)
    assert r.verified and r.converged and r.theta_rad == pytest.approx(np.pi, abs=1e-3)
    below, above = (exact_multipliers(dyn, SPLIT_CUT, SPLIT_RPM, f * r.depth_m, np.pi) for f in (0.98, 1.02))
    assert np.abs(below).max() < 1.0
    assert np.any((np.abs(above.imag) < 1e-9) & (above.real < -1.0))


#: A random absorber structure of the blind search (seed 8, case 1339): 3 teeth in up milling at
#: a/D 0.06, 917 rpm. No seed converged; the repair's doubling search stepped from 6.4 mm (stable
#: on the coarse cut model) to 12.8 mm (stable, an island below) to 25.6 mm, its probes went down
#: to 9.7 mm (unstable), and the bisection then started from 12.8 mm, above that: no answer at all.
NO_SEED_HOST = [
    ("x", 13.352144835534185, 0.05330175319294395, 912648.4837365033), ("x", 43.7958968192143, 0.015272408637895809, 374768.6034371061),
    ("x", 554.3795908677484, 0.04604988890394385, 3168917.457361659), ("x", 5631.872106466029, 0.056961353227355356, 7180602.047305715),
    ("y", 24.21206938436628, 0.0240792892970544, 9154556.51430362), ("y", 66.32607937588783, 0.014570224413748181, 745378.3270339412),
    ("y", 2494.359421113129, 0.06105921556228734, 9190958.079607882), ("y", 6010.610611391484, 0.07090334537266171, 3340988.322166338),
]
NO_SEED_ABSORBER = (4.021247878206059, 112694.03627428255, 0.14746839384983068)
NO_SEED_CUT = Cut(teeth=3, kt_pa=1888505315.3505561, kn_pa=542625365.3029354, radial_immersion=0.05824687901066746, milling="up")
NO_SEED_RPM = 917.487621691842


def test_the_repair_bisects_below_its_probes_when_every_probe_is_unstable():
    """The bisection's floor stays below the probes' lowest unstable depth; the answer is
    verified, converged and a boundary point of the DOP853 characteristic. (From 4 sub-steps a
    radian, where the case was found: the default for this narrow cut, `coarsest_substeps`, takes
    another path to the same 6.29 mm, through the rungs on M below, in about a minute.)"""
    dyn = absorber_structure(NO_SEED_HOST, NO_SEED_ABSORBER)
    r = floquet.critical_depth(dyn, NO_SEED_CUT, NO_SEED_RPM, substeps_per_rad=floquet.SUBSTEPS_PER_RAD)
    assert r.verified and r.converged and r.repaired
    (depth, theta), residual = exact_boundary_point(dyn, NO_SEED_CUT, NO_SEED_RPM, r.depth_m, r.theta_rad, iterations=2)
    assert residual < 1e-6 and abs(r.depth_m / depth - 1.0) < 0.02


def test_the_rungs_are_read_where_the_count_samples_m_directly():
    """With 6 sub-steps in the engagement at the coarsest level (`coarsest_substeps`) the same job's
    bisection ends at 23.1 mm, above the Hopf island at 6.3-14 mm. The verification at 49 a
    radian samples M directly (its interpolants fail there) and used to skip the rungs: 23.26 mm
    was reported verified, 3.7 times the exact 6.29 mm. The rungs now count on M as well."""
    dyn = absorber_structure(NO_SEED_HOST, NO_SEED_ABSORBER)
    base = floquet.coarsest_substeps(NO_SEED_CUT)
    char = floquet.FloquetCharacteristic(dyn, NO_SEED_CUT, 4.0 * base)
    tau = float(NO_SEED_CUT.tooth_period_s(NO_SEED_RPM))
    count, resolved, rung, ladder, _ = floquet._verify_count(char, 0.995 * 23.26e-3, tau, [1.59])
    assert (count, resolved, ladder) == (0, True, None)  # blind above the island, no interpolant
    assert rung is not None and 6.3e-3 < rung < 14e-3 and floquet.unstable_count(char, rung, tau)[0] > 0


#: A random absorber structure of a blind search with low immersion (2026-12-03, seed 23, case
#: 954): 3 teeth in down milling at a/D 0.13, 574 rpm. The seeds found no boundary point, the
#: repair found 1.26 mm on the coarse cut model (4 sub-steps a radian) and verified it there, where
#: no island lies below; the answer refined to 1.254 mm at 8 sub-steps a radian, where a Hopf
#: island spans 0.79-0.85 of it, holding the 0.8 rung. The count at the answer's resolution did not
#: read the rungs: 1.254 mm was reported verified, 28 % too deep.
RUNG_HOST = [
    ("x", 38.34602243071863, 0.02642052716949262, 4042041.991557958), ("x", 178.2845136200903, 0.02738780375703568, 1355937.0266659951),
    ("x", 2324.4210424205053, 0.008830439870548405, 45795877.97567631), ("x", 3540.538831660363, 0.06127718789515482, 13163642.79888466),
    ("y", 16.628441312925286, 0.01080175216676321, 5960500.676589123), ("y", 78.31707199588604, 0.025106032645655047, 2828444.9340007766),
    ("y", 2189.456505955548, 0.051200250526955246, 26685201.660250325), ("y", 5073.54917224549, 0.007914231925120998, 31366342.6952848),
]
RUNG_ABSORBER = (3.8846123517912714, 6559113.709577325, 0.054097543443953525)
RUNG_CUT = Cut(teeth=3, kt_pa=546470907.1182313, kn_pa=210621773.7717388, radial_immersion=0.12807367392845512, milling="down")
RUNG_RPM = 574.2311648919588


def test_the_hopf_rungs_are_read_again_at_the_answers_resolution():
    """Where the answer's resolution is finer than the verification's, the count there reads the
    Hopf rungs too; the job is solved again at that resolution and the answer is the island's
    bottom, a boundary point of the DOP853 characteristic (to 0.02 % when written)."""
    dyn = absorber_structure(RUNG_HOST, RUNG_ABSORBER)
    r = floquet.critical_depth(dyn, RUNG_CUT, RUNG_RPM)
    assert r.verified and r.converged and r.depth_m < 1.1e-3
    (depth, theta), residual = exact_boundary_point(dyn, RUNG_CUT, RUNG_RPM, r.depth_m, r.theta_rad, iterations=2)
    assert residual < 1e-6 and abs(r.depth_m / depth - 1.0) < 0.01
