"""Critical depth and chatter frequency without a resolution knob (issue 17): the exact Floquet
characteristic equation of the milling delay equation, solved on the stability boundary.

Why not more semi-discretization steps
--------------------------------------
The semi-discretization (`sdm`) approximates the delayed position q(t - tau) inside each step by
a constant or a line. A spindle mode at 5.4 kHz with a tooth period of 10 ms (2000 rpm, 3 teeth)
oscillates 55 times per delay, so the history needs several steps per vibration period (the
project measured 3.30 / 3.99 / 2.31 / 1.68 mm at 40 / 80 / 160 / 320 steps, 1.51 mm converged),
and the monodromy matrix grows with it (N = 2n + n m).

The characteristic equation
---------------------------
A Floquet solution with multiplier mu != 0 satisfies q(t - tau) = nu q(t), nu = 1 / mu, for all t
(the delay equals the period). Substituted into

    q'' + C q' + K q = a Phi_R^T H(t) Phi_L (q(t - tau) - q(t))

this leaves an ordinary periodic ODE for z = [q; q'] with the complex parameter c = a (1 - nu),

    z' = A(t, c) z,   A = [[0, I], [-(K + c W(t)), -C]],   W = Phi_R^T H Phi_L,

and mu is a multiplier exactly when det(I - nu M(c)) = 0, M(c) the 2n x 2n monodromy matrix of
that ODE over one tooth period. No history is discretized: every mode, however fast, is
propagated by exact matrix exponentials. The only approximation is W(t): the tooth period is
cut at every tooth entry and exit (so H is smooth on each segment), free-flight segments are one
exponential of the free structure, and each cutting segment is split into sub-steps on which W
is replaced by its exact average (the same closed-form integrals as `sdm`). The error of that
comes from the variation of H with the tool angle, not from the modes: it needs a few sub-steps
per radian of engagement whatever the spindle speed or the mode frequencies.

On the stability boundary |mu| = 1, mu = exp(i theta), and the critical depth is the smallest
a > 0 for which F(a, theta) = det(I - exp(-i theta) M(a (1 - exp(-i theta)))) = 0 for some
theta (D-subdivision: at a = 0 all multipliers are the free structure's, inside the unit circle;
h(nu) = det(I - nu M(c(nu))) is entire in nu with h(0) = 1, so multipliers enter |mu| >= 1 only
through the circle). Two real unknowns (a, theta), one complex equation, solved as
g(a, theta) = ln(nu sigma) = 0 for one eigenvalue sigma of M(c) followed by its eigenvector
(dg/dnu = 1/nu exactly; d ln sigma / dc by one difference, then secant updates: one monodromy
per Newton iteration, batched over seeds, speeds and structures). Seeds: the zeroth-order
crossings (Altintas-Budak) at the given speed, the lowest MAX_SEEDS plus the lowest
SEEDS_PER_MODE of every mode band, each starting on the eigenvector that lives on its mode
(following "the eigenvalue nearest 1" instead jumps to robot-mode multipliers, which sit near
the unit circle at low delay; that was the prototype's 1000 rpm miss). Once picked, the
eigenvalue is followed by inverse iteration from the predicted one (a full eigen-decomposition
only where that does not settle on the same eigenvector). The zeroth order never gives
period-doubling branches (theta = pi); `flip_seeds` adds them: at nu = -1, c = 2 a is real, M(2 a)
is real, and a flip crossing is where one of its real eigenvalues passes -1, found on a scan of
FLIP_POINTS depths (one real batch per structure).

Cost. The seed search runs on band projections (`ProjectedCharacteristic`, `mode_bands`): the
free structure's eigen-pairs are grouped where their frequencies are separated by more than
BAND_GAP, and a seed of one band is refined on the pairs within BAND_WIDEN of it (spindle seeds
without the robot modes and vice versa; free flight is diagonal there), which makes the matrix
exponentials several times cheaper. Every candidate is then re-solved on the whole structure
(Newton from the lifted eigenvector) before anything is compared, verified or reported, so the
projection only decides where Newton starts. Seeds are pruned while they iterate (`_prune`,
STALL): one heading to a point already converged, one PRUNE_ABOVE x above its job's lowest
converged point, one whose |g| stays large. The refinement after the search (levels, full
structure) is batched over all jobs (`_finish_all`).

Verification (`verify=True`): the number of multipliers outside the unit circle at
VERIFY_FRACTION x the depth is the number of zeros of h(nu) = det(I - nu M(a (1 - nu))) in
|nu| < 1 (argument principle, `unstable_count`, adaptive theta grid). Count 0 with every grid
step resolved (< pi/4 in phase, < x4 in modulus) means no boundary point lies below 0.995 x the
reported depth, up to the resolution of the phase sampling (a zero pair closer to the circle
than the sampling can see is not excluded). The count runs on the cut model of the first refined
level (where 9 in 10 sweep answers end) and, where the answer needed a finer one, once more at
the answer's own resolution (where not 0 there, the job is solved again from the seeds at that
resolution): a branch that a coarser model puts above the answer can lie below it with the
answer's (blind search: 3-8 % too deep, verified on the coarse level). A continued job that is
still refining at the first refined level is counted at its answer's resolution only (a count
there that is not 0, or that shows more crossings up to rel_tol above than its points bring,
sends it back to the seeds): the coarse count would be repeated finer anyway.
h is sampled on an interpolant (`segment_interpolants`, `circle_monodromies`,
`monodromy_polynomial`: M(a (1 - nu)) is entire in nu, each segment's exponential needs 8-16
Taylor terms), every sample with a Rouche bound on the interpolant's error, else directly. A
non-zero count triggers `_repair`: Newton from the boundary points of Hill's method (`hill`,
two harmonics: the branches an interrupted cut puts between modes at or below a few
tooth-passing frequencies, which the zeroth order cannot seed), else from the thetas where an
eigenvalue of M comes nearest 1 / nu at that depth (`_descend`; before the flip seeds,
period-doubling branches were the usual misses), else bisection in depth on the count, then
Newton from the nearest multipliers; the result says `repaired=True`. The lowest point reached
is the one verified; the others the same Newton reached are kept and ranked with the job's points
(two branches 0.6 % apart at the coarse level swap at finer ones: keeping one left a 22-mode
answer 1.9 % too deep).

Flip islands. The count at one depth says nothing about depths below it where the unstable set
is not an interval from some depth upwards: a real multiplier can pass -1 and come back (a
period-doubling island), and a search that misses the lower flip point reports the depth above
the island with a count of 0 (the sweep's absorber poses: 5.5-9.2 mm reported where the cut
chatters from 1.7-2.2 mm). Below every verified answer the flip condition is checked first on
the verification count's cut model: on that count's interpolant, which holds on the whole disk
and so gives M(2 a) at every depth below the count's without an exponential (`ladder_islands`,
depths 2 % apart: the sign of det(I + M(2 a))), else on the flip seeds' own scan of that model
(`_islands_from_seed_scan`) or a scan (`flip_islands`); then, where a multiplier is below -1 or
within FLIP_NEAR of it, at the answer's own resolution (islands appear with a finer cut model;
after the ladder, densely where it came near -1 or found an island, `dense_flip`), and where a
multiplier's closest approach to -1 is shorter than it moved from the level before, at the finer
levels too, one at a time, until the approach is resolved (`flip_ahead`: a multiplier peaking at
-1.0002 made an island 3 % wide, 36 % under a 7.14 mm answer, that only 52 sub-steps a radian
and up have; the answer had converged at 26). Where one is found the job is solved again at
that resolution (the finest level too: a 41-48 mm island under a 57 mm answer at 30,000 rpm
had been left unverified there), from the seeds and the island's lower end, and an answer that
cannot be brought below the island is marked not verified. Hopf islands (complex
multipliers): the verification's count is also read at HOPF_RUNGS x the depth on the same
interpolant (`hopf_rung`: an island that holds one of them is found and repaired below it), and
a seed that leads to an island's lowest point finds it too (a band seed
whose Newton fails below the job's lowest point is tried again on the whole structure: the band
projection lost one; a coupled structure also gets HILL_SEEDS of Hill's boundary points, and
those that reach none on the coarse cut model below an answer at a finer resolution are tried
once more there: such an island can exist only with the finer model; all in
tests/test_hopf_islands.py), and any converged boundary point bounds the answer from above (a
re-solve never trades one for a higher point). A blind search over random robot-plus-spindle
structures found none silently off in 6455 cases after the Hopf rungs (README).

Continuation (`critical_depths(continuation=True)`): structures with similar modes (`modal_path`)
start Newton on the whole structure from the boundary points the neighbours either side converged
on, with their G_c and eigenvectors (`CriticalPoint.starts`), instead of the seeds; such a job is
always verified, and one whose count is not 0 is solved again from the seeds.

The critical depth is the smallest converged boundary point. Its resolution is chosen, not
given: the boundary point is found with `SUBSTEPS_PER_RAD` sub-steps per radian of cutting
(at least MIN_ENGAGED_SUBSTEPS in the engagement, `coarsest_substeps`), re-solved (Newton from
the coarse root) with twice as many, and the difference is the error estimate (the error
decreases at least linearly in the sub-step length, so the difference bounds the error of the
finer value); the resolution doubles until the estimate is below rel_tol / 2
and every mode at least 1 / SOFT_MODE as stiff as the cut is resolved (at most SUBSTEP_PERIODS
of its periods in a cutting sub-step: before that the error is not yet monotone in the sub-step
and two levels can agree by chance). Stiffer modes can alias too (a random absorber structure, 2
teeth at 524 rpm, spindle modes 14-90 times as stiff as the cut with 4-20 of their periods in a
sub-step: 4 and 8 a radian agreed to 0.15 %, 16 moved the depth 1.8 %), so a job's lowest point
is checked one level up when it converges (`look_ahead`: one Newton step there, one monodromy):
the estimate is the larger of the two steps, and a step up above rel_tol / 2 takes the job on.
Where a mode at most ALIAS_MODE times as stiff as the cut has more than ALIAS_PERIODS of its
periods in a sub-step (below the Nyquist rate), that step is taken at the first level that
resolves it so, and where that is more than one level up and the step could raise the estimate,
Newton goes to the root there (one step went 0.42 % where the root was 0.83 % away). Seen in the
independent checks: L00 (4 teeth at 243 rpm, a/D 0.027, 5.1-5.9 kHz modes 6.5-7.5 times as stiff
as the cut, 3 periods a sub-step at 73 a radian): 18, 37 and 73 agreed to 0.16 %, 147 took the
branch away, the answer was 2.4 % too shallow; H02 (6 teeth at 252 rpm, a 6.72 kHz mode 16 times
as stiff that chatters): its sub-step was near a whole number of its periods at the first five
levels (15.5 down to 0.97), which all converged to a depth 0.83 % too deep. Requiring the whole
convergence at such a level instead cost 32 % more on the bench sweep, whose rows it left alone.
A point Newton cannot follow to the next level is dropped where its job has others; a job none
of whose points follows is solved again from the seeds at that level (one lost there again, in
place, at the first level that resolves its stiff modes: `_unaliased_level`); a point at the finest level
with no estimate takes it from one level down. Which of two near points is the lowest (the
chatter frequency) counts as settled only where their intervals, depth x (1 +- estimate), are
apart or both estimates are below TIE_TOL; the verification's interpolant is made rel_tol above
the answer, and where the count there exceeds the crossings of the known points, the branch the
search missed is found (Newton from the nearest multipliers) and ranked with them.

Dominant chatter frequency: as `chatter.chatter_frequencies` defines it (Dombovari et al. 2011):
the Floquet solution at the critical point is exp(i theta t / tau) p(t) with p tau-periodic;
the members of the family |theta / tau + j w_T| are weighted by the tool-tip amplitude of the
j-th Fourier coefficient of p, here integrated exactly (segment by segment, in the eigenbasis of
each segment's constant A) instead of from samples.

Dynamically irrelevant modes: a mode whose own term of the tool-tip FRF stays below
`IRRELEVANT` times the whole FRF at every frequency is left out of the search (uncoupled tables
only); the final boundary point is then re-solved on the full structure by Newton from the
reduced one, so the reported depth and frequency are those of the full model either way.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np
import scipy.optimize

from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError
from posedyn.stability import hill, sdm
from posedyn.stability.cutting import Cut, engaged_integral, mean_force_matrix

#: Sub-steps per radian of tool angle in a cutting segment, coarsest level (`coarsest_substeps`),
#: and at least MIN_ENGAGED_SUBSTEPS in a tooth's engagement: with 3 there (a/D 0.08-0.11 at 4 a
#: radian) the first two levels are not yet in the asymptotic range and their difference is no
#: bound: the independent check's S27 and S22 (up milling, a/D 0.113 and 0.076) were 0.67 % and
#: 0.10 % off where the estimates said 0.23 % and 0.04 %; with 6, the errors of its 44 cases are
#: below their estimates (+0.003 % at most) at the same cost.
SUBSTEPS_PER_RAD = 4.0
MIN_ENGAGED_SUBSTEPS = 6
#: Finest level tried before giving up on rel_tol: the first at or above this many sub-steps per
#: radian (`_top_level`; the levels double from the coarsest, so 512-1023). A mode must fit in a
#: cutting sub-step at most once (SUBSTEP_PERIODS) before a level's estimate counts: 10 kHz at 200
#: rpm needs 480 a radian (at 128, 22 of 24 flagged low-speed answers of a blind search could not
#: converge; some were 75 % off). With the last level below it, 317 a radian was the finest from a
#: coarsest of 19.8, and an 8.65 kHz mode at 239 rpm (it needs 346) could never converge.
MAX_SUBSTEPS_PER_RAD = 512.0
#: Modes whose own FRF term stays below this fraction of the whole FRF's at every frequency
#: (`relevant_modes`) are left out of the search. Against the largest peak compliance instead, a
#: 2.8 kHz spindle mode 1,000 times less compliant than a 24 Hz robot mode was left out, and with
#: it the flip lobe it makes at 8.72 mm (7 teeth, full immersion, 14,082 rpm; a blind check).
IRRELEVANT = 1e-3
RELEVANCE_PER_DECADE = 10  # log-spaced frequencies a decade of that check, besides the modes' own
#: Seeds refined at the coarse level (lowest zeroth-order depths first), plus the lowest
#: SEEDS_PER_MODE of every mode's band.
MAX_SEEDS = 12
SEEDS_PER_MODE = 4
#: Seeds are refined at SUBSTEPS_PER_RAD / 2**SEED_LEVELS_BELOW (1: cheaper monodromies, but
#: Newton from a zeroth-order seed then lands on another branch more often; measured, not worth it).
SEED_LEVELS_BELOW = 0
#: A seed is dropped once it is this many times above its job's lowest converged boundary point.
PRUNE_ABOVE = 2.5
#: Seed search on bands of the free structure's eigen-pairs (`mode_bands`): a gap of more than
#: BAND_GAP in frequency separates bands, a band's projection keeps the pairs within BAND_WIDEN
#: of its frequency range. PROJECT_SEEDS = False searches on the whole structure.
PROJECT_SEEDS = True
BAND_GAP = 4.0
BAND_WIDEN = 3.0
#: Pre-asymptotic guard: a free mode whose tool-tip stiffness is at most SOFT_MODE x the cut's
#: (depth x |(Kt, Kn)|) has its vibration resolved at the accepted level, at most
#: SUBSTEP_PERIODS of its periods in a cutting sub-step. Below that the force average over a
#: sub-step aliases with the vibration and two levels can agree by chance: on an
#: absorber-coupled sweep pose (40 mm cuts, 6 kHz spindle modes as stiff as the cut, 2385-3000
#: rpm) 8 and 16 sub-steps a radian agreed to 0.4 % at a depth 2.2 % above the converged one.
#: Shallow chatter (issue 17: the cut a twentieth of the spindle's stiffness) is not affected.
SOFT_MODE = 5.0
SUBSTEP_PERIODS = 1.0
#: Aliasing guard of the look-ahead (`look_ahead`, `unresolved(look=True)`): a mode at most
#: ALIAS_MODE times as stiff as the cut, with more than ALIAS_PERIODS of its periods in a sub-step,
#: can make levels agree on a wrong depth (by 2.4 % at 7 times, 0.8 % at 16 in the independent checks).
ALIAS_MODE = 20.0
ALIAS_PERIODS = 0.5
#: Newton tolerance (relative step) of the refinements after the seed search.
REFINE_TOL = 1e-4
#: Seed pruning: (iteration, |g|) pairs; a seed with |g| above the bound at or after the
#: iteration is dropped (Newton from a good seed is in its quadratic basin by then).
STALL = ((3, 4.0), (5, 1.0), (8, 0.05))
#: Newton stops one monodromy early where its next step is below tol, but only where |g| there
#: is below LAST_G too: a secant G_c corrupted by a jump to another eigenvalue makes every step
#: tiny (seen: 'converged' at |g| = 1.1-1.8 on 5 of 304 such stops in a sweep chunk, and at
#: |g| = 101 on seed-search points of a 9.4 kHz mode aliased at 2 teeth, 212 rpm; the genuine
#: stops there had |g| <= 7e-4).
LAST_G = 1e-2
#: Boundary points within this fraction of the lowest are refined too and reported as branches.
NEAR_TIE = 0.10
#: Which of two near boundary points is the lowest (and so the chatter frequency) is settled only
#: where their error intervals, depth x (1 +- error estimate), do not overlap, or where both
#: estimates are below TIE_TOL (a tie to 0.2 %: either is the answer). Seen in the sweep: a robot
#: branch 0.1 % under a spindle branch at 8 sub-steps a radian, 0.3 % over it converged; the
#: report said 18.8 Hz where the converged answer chatters at 5456.5 Hz, and the absorber tuned to
#: it gave 2.69 mm where tuned to 5456.5 Hz it gives 1.63 mm.
TIE_TOL = 1e-3
#: Uniform theta samples of the winding count (plus the known boundary points' thetas and
#: the free structure's multiplier angles; the grid is then refined adaptively).
VERIFY_POINTS = 64
#: The winding count's interpolants (`segment_interpolants`, `monodromy_polynomial`): roots of
#: unity of the segments' exponentials (first, most) and the coefficient tail they must reach
#: (relative), roots of unity of M (first, most) and the tail below which its polynomial is
#: tried, and the largest sqrt(2n) |(I - nu M)^-1|_F |dM|_F a sample may have (Rouche: below
#: ln 2, |h_interpolated / h - 1| < 1).
SUBSTEP_NODES = (16, 64)
SUBSTEP_TOL = 1e-8
INTERP_NODES = (32, 256)
INTERP_TOL = 1e-6
INTERP_SAFE = 0.5
#: Bytes of the per-segment arrays built at once (the exponentials of a batch of monodromies, the
#: count's FFT input and output and its segments' values at M's roots of unity, the chatter
#: frequency's harmonic integrals): they run in blocks of this size. At 512 sub-steps a radian
#: a full cut has thousands of segments, and those arrays at once took 3.7 GB on one pose.
SEGMENT_BLOCK_BYTES = 1 << 27
#: The winding count is taken at this fraction of the reported depth.
VERIFY_FRACTION = 0.995
#: Largest |M| entry at which the winding count is taken: the LU of I - nu M has a backward error
#: of about 2n eps |M| (7e-5 at this limit), and the factors 1 - nu sigma near the circle that
#: decide the count drown in it beyond (an entry of 1e58, 18 mm on a 300 rpm, one-tooth, 9 kHz
#: structure whose answer is 3.25 mm: 60-80 s of direct samples a count, and counts of -46 and
#: -42). There the count is not resolved (the bisection then takes the depth as unstable, a
#: verification fails), without samples.
MONODROMY_LIMIT = 1e10
#: A structure's characteristic keeps the monodromies of its last call with at most this many
#: rows: the same batch asked again (a look-ahead's one-step estimate and the Newton to the root
#: from the same point; a flip scan's depths) is returned without its exponentials.
REPEAT_ROWS = 64
#: Frequency grid: half-width around each mode in units of zeta w, and points per w_T.
BAND_ZETAS = 8.0
POINTS_PER_TOOTH_FREQUENCY = 10


@dataclass(frozen=True, eq=False)
class CriticalPoint:
    """Critical depth (m; inf where no cutting force reaches the structure, NaN where no boundary
    point was found otherwise: unknown, not "never chatters"), dominant chatter frequency (Hz),
    theta = angle of the critical multiplier (rad, in [0, pi]; pi: flip), the chatter-frequency
    family ((hz, relative amplitude), largest first), the resolution used (sub-steps per radian),
    the relative error estimate and whether it is within rel_tol."""

    rpm: float
    depth_m: float
    chatter_hz: float
    theta_rad: float
    family: tuple
    substeps_per_rad: float
    rel_error_estimate: float
    converged: bool
    verified: bool | None = None
    branches: tuple = ()
    repaired: bool = False
    starts: tuple = ()  # (depth, theta, G_c, eigenvector or None) of every boundary point the search converged on and of the branches: where a similar structure starts (continuation)


@dataclass(frozen=True, eq=False)
class Lobes:
    rpm: np.ndarray
    depth_m: np.ndarray
    chatter_hz: np.ndarray
    theta_rad: np.ndarray
    rel_error_estimate: np.ndarray
    converged: np.ndarray
    verified: np.ndarray  # per speed: the multiplier count found no lower branch (True where not asked)


# --- structure and segments ---------------------------------------------------------------------


def relevant_modes(dyn: ToolTipDynamics) -> np.ndarray:
    """Indices of the modes kept in the search: all of them for a coupled structure, otherwise
    those whose own term of the tool-tip FRF, h_r(w) = phi_L,r phi_R,r^T / (w_r^2 - w^2 +
    2 i zeta_r w_r w), reaches IRRELEVANT x |H(w)| (Frobenius norms) somewhere on the modes' own
    frequencies and RELEVANCE_PER_DECADE frequencies a decade from a third of the lowest to three
    times the highest: a mode left out changes the FRF by less than that at every frequency."""
    if dyn.coupling is not None:
        return np.arange(dyn.n_modes)
    wn = dyn.wn_rad_s
    w = np.concatenate([wn, np.geomspace(wn.min() / 3.0, 3.0 * wn.max(), int(np.ceil(RELEVANCE_PER_DECADE * np.log10(9.0 * wn.max() / wn.min()))) + 1)])
    modal = 1.0 / (wn[None, :] ** 2 - w[:, None] ** 2 + 2j * dyn.zeta[None, :] * wn[None, :] * w[:, None])  # (frequency, mode)
    own = np.abs(modal) * (np.linalg.norm(dyn.shapes, axis=0) * np.linalg.norm(dyn.force_shapes, axis=0))[None, :]
    H = np.linalg.norm(dyn.frf(w), axis=(1, 2))
    return np.flatnonzero(np.any(own >= IRRELEVANT * H[:, None], axis=0))


def _subset(dyn: ToolTipDynamics, keep: np.ndarray) -> ToolTipDynamics:
    if len(keep) == dyn.n_modes:
        return dyn
    right = None if dyn.shapes_force is None else dyn.shapes_force[:, keep]
    return ToolTipDynamics(dyn.fn_hz[keep], dyn.zeta[keep], dyn.shapes[:, keep], None, right)


def coarsest_substeps(cut: Cut) -> float:
    """Sub-steps per radian of the coarsest level: SUBSTEPS_PER_RAD, or MIN_ENGAGED_SUBSTEPS over
    the engagement angle where that is more (a narrow cut)."""
    start, exit_ = cut.engagement_rad
    return max(SUBSTEPS_PER_RAD, MIN_ENGAGED_SUBSTEPS / (exit_ - start))


def segment_angles(cut: Cut, substeps_per_rad: float):
    """Tool-angle intervals of one tooth period cut at every tooth entry and exit, cutting
    intervals split into sub-steps: (lo, hi, H averages (s, 2, 2), cutting mask). Cached per
    (cut, resolution); the arrays are read-only."""
    try:
        return _segment_angles_cached(cut, float(substeps_per_rad))
    except TypeError:  # an unhashable cut
        return _segment_angles(cut, float(substeps_per_rad))


@functools.lru_cache(maxsize=64)
def _segment_angles_cached(cut: Cut, substeps_per_rad: float):
    out = _segment_angles(cut, substeps_per_rad)
    for x in out:
        x.setflags(write=False)
    return out


def _segment_angles(cut: Cut, substeps_per_rad: float):
    pitch = 2.0 * np.pi / cut.teeth
    st, ex = cut.engagement_rad
    events = np.mod(np.array([st - j * pitch for j in range(cut.teeth)] + [ex - j * pitch for j in range(cut.teeth)]), pitch)
    events = np.unique(np.concatenate([[0.0, pitch], events]))
    lo, hi, cutting = [], [], []
    for a, b in zip(events[:-1], events[1:]):
        if b - a < 1e-12 * pitch:
            continue
        mean = engaged_integral(cut, np.array(a), np.array(b))
        if np.abs(mean).max() <= 1e-12 * (abs(cut.kt_pa) + abs(cut.kn_pa)) * (b - a):
            lo.append(a)
            hi.append(b)
            cutting.append(False)
            continue
        k = max(2, int(np.ceil(substeps_per_rad * (b - a) - 1e-9)))
        edges = np.linspace(a, b, k + 1)
        lo += list(edges[:-1])
        hi += list(edges[1:])
        cutting += [True] * k
    lo, hi, cutting = np.array(lo), np.array(hi), np.array(cutting)
    H = engaged_integral(cut, lo, hi) / (hi - lo)[:, None, None]
    H[~cutting] = 0.0
    # merge adjacent free-flight intervals (one exponential)
    return lo, hi, H, cutting


def _complex_or_real(c) -> np.ndarray:
    """c as a flat array: float where every value is real (a real monodromy costs a quarter),
    complex otherwise."""
    c = np.asarray(c).reshape(-1)
    return c.astype(float) if not np.iscomplexobj(c) else c.astype(complex)


class FloquetCharacteristic:
    """det(I - nu M(c)) of one structure and cut at one resolution, batched over (c, nu, tau)."""

    def __init__(self, dyn: ToolTipDynamics, cut: Cut, substeps_per_rad: float):
        self.dyn, self.cut, self.substeps_per_rad = dyn, cut, substeps_per_rad
        turned = dyn.rotated(np.deg2rad(cut.feed_angle_deg))
        self.shapes = turned.shapes
        lo, hi, H, cutting = segment_angles(cut, substeps_per_rad)
        self.fraction = (hi - lo) / (2.0 * np.pi / cut.teeth)  # of the tooth period
        self.start = lo / (2.0 * np.pi / cut.teeth)
        self.cutting = cutting
        self.W = np.einsum("ir,sij,jq->srq", turned.force_shapes, H, turned.shapes)
        self.n = n = dyn.n_modes
        K, C = dyn.stiffness_matrix, dyn.damping_matrix
        # balanced per degree of freedom, z = [w q; q'] with w = sqrt(K_ii): a free mode propagates
        # as a rotation, so products of propagators keep norms near 1 (one scale for all made a
        # 12 Hz mode's entries 400x its 5 kHz neighbour's)
        d = np.sqrt(np.abs(np.diag(K)))
        self.scale = w = np.maximum(d, 1e-12 * d.max())
        A0 = np.zeros((2 * n, 2 * n))
        A0[:n, n:] = np.diag(w)
        A0[n:, :n] = -K / w[None, :]
        A0[n:, n:] = -C
        self.A0 = A0
        self.force_shapes = turned.force_shapes
        self.S = np.zeros((2, 2 * n))  # balanced state -> tool tip
        self.S[:, :n] = turned.shapes / w[None, :]

    def free_eig(self):
        """Eigen-decomposition of A0 (cached)."""
        if getattr(self, "_free_eig", None) is None:
            self._free_eig = np.linalg.eig(self.A0.astype(complex))
        return self._free_eig

    def residues(self):
        """(lam, S V, V^-1 [0; Phi_R^T]) of the free structure (cached): the tool-tip receptance is
        sum_k left[:, k] right[k, :] / (i w - lam_k)."""
        if getattr(self, "_frf_parts", None) is None:
            lam, V = self.free_eig()
            inp = np.zeros((2 * self.n, 2))
            inp[self.n :] = self.force_shapes.T
            self._frf_parts = (lam, self.S @ V, self.free_eig_inverse() @ inp)
        return self._frf_parts

    def frf(self, omega) -> np.ndarray:
        """Tool-tip receptance (..., 2, 2) of the (turned) structure from the eigen-decomposition
        of A0: G = S V diag(1 / (i w - lam)) V^-1 [0; Phi_R^T]."""
        lam, left, right = self.residues()
        w = np.asarray(omega, dtype=float)[..., None]
        return np.einsum("dk,...k,ke->...de", left, 1.0 / (1j * w - lam), right)

    def free_eig_inverse(self):
        if getattr(self, "_free_eig_inv", None) is None:
            self._free_eig_inv = np.linalg.inv(self.free_eig()[1])
        return self._free_eig_inv

    def unresolved(self, a: float, tau: float, look: bool = False, finer: int = 0) -> bool:
        """Whether a free mode at least 1 / SOFT_MODE as stiff at the tool tip as the cut at depth
        a (m) vibrates more than SUBSTEP_PERIODS periods in this model's longest cutting sub-step
        (tooth period tau): its answer is not yet in the asymptotic range of the resolution.
        `look`: whether a mode at most ALIAS_MODE as stiff has more than ALIAS_PERIODS periods
        in a sub-step (`look_ahead`); `finer`: at the resolution that many levels up (sub-steps
        2^-finer as long)."""
        lam, left, right = self.residues()
        with np.errstate(all="ignore"):  # static tool-tip compliance of each eigen-pair, 2 |R_k| / |lam_k|
            compliance = 2.0 * np.linalg.norm(left, axis=0) * np.linalg.norm(right, axis=1) / np.abs(lam)
            ratio = 1.0 / (compliance * a * np.hypot(self.cut.kt_pa, self.cut.kn_pa))  # k_mode / k_cut
            allowed = np.where(ratio <= SOFT_MODE, SUBSTEP_PERIODS, np.inf)
            if look:
                allowed = np.where(ratio <= ALIAS_MODE, np.minimum(allowed, ALIAS_PERIODS), allowed)
        substep = tau * (self.fraction[self.cutting].max() if self.cutting.any() else 0.0) / 2.0**finer
        return bool(np.any(np.abs(lam.imag) / (2.0 * np.pi) * substep > allowed))

    def generators(self, c: np.ndarray, dt: np.ndarray | None = None, segments=slice(None)) -> np.ndarray:
        """A_i(c) dt_i for the `segments` (all), (s, B, 2n, 2n), real for real c (balanced
        coordinates); dt (s, B) the segments' lengths (1: the generators themselves)."""
        n = self.n
        c = _complex_or_real(c)
        W = self.W[segments] / self.scale[None, None, :]
        dt = np.ones((len(W), len(c))) if dt is None else dt
        A = np.empty((len(W), len(c), 2 * n, 2 * n), dtype=c.dtype)
        np.multiply(self.A0, dt[:, :, None, None], out=A)
        A[:, :, n:, :n] -= (c[None, :] * dt)[:, :, None, None] * W[:, None]
        return A

    def monodromy(self, c: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """M(c) over one tooth period tau, (B, 2n, 2n), real for real c (flip: nu = -1); the
        batch in blocks whose exponentials stay within SEGMENT_BLOCK_BYTES."""
        c = _complex_or_real(c)
        tau = np.broadcast_to(np.asarray(tau, dtype=float).reshape(-1), c.shape)
        last = self.__dict__.get("_last_monodromy")
        if last is not None and last[0].dtype == c.dtype and np.array_equal(last[0], c) and np.array_equal(last[1], tau):
            return last[2].copy()
        blocks = _blocks(len(c), len(self.fraction) * (2 * self.n) ** 2 * c.itemsize)
        if len(blocks) > 1:
            return np.concatenate([self.monodromy(c[lo:hi], tau[lo:hi]) for lo, hi in blocks])
        E = self.exponentials(c, tau)
        M = E[0]
        for i in range(1, len(E)):
            M = E[i] @ M
        if len(c) <= REPEAT_ROWS:
            self._last_monodromy = (c.copy(), tau.copy(), M.copy())
        return M

    def exponentials(self, c: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """The segments' exp(A_i(c) dt_i), (segments, B, 2n, 2n); free-flight segments use A0 (no c)."""
        c = _complex_or_real(c)
        tau = np.broadcast_to(np.asarray(tau, dtype=float).reshape(-1), c.shape)
        n2 = 2 * self.n
        cut_idx = np.flatnonzero(self.cutting)
        A = self.generators(c, self.fraction[cut_idx, None] * tau[None, :], cut_idx)
        E = np.empty((len(self.fraction), len(c), n2, n2), dtype=c.dtype)
        if len(cut_idx) and cut_idx[-1] - cut_idx[0] == len(cut_idx) - 1:  # one run: in place (a leading-axis slice is a view)
            sdm.expm_batched(A.reshape(-1, n2, n2), out=E[cut_idx[0] : cut_idx[-1] + 1].reshape(-1, n2, n2))
        else:
            E[cut_idx] = sdm.expm_batched(A.reshape(-1, n2, n2)).reshape(len(cut_idx), len(c), n2, n2)
        free_idx = np.flatnonzero(~self.cutting)
        if len(free_idx):  # independent of c: once per distinct delay
            if np.all(tau == tau[0]):  # one delay (np.unique costs more than the rest of this)
                utau, inverse = tau[:1], np.zeros(len(tau), int)
            else:
                utau, inverse = np.unique(tau, return_inverse=True)
            E[free_idx] = self._free_flight(utau)[:, inverse.reshape(-1)]
        return E

    def _free_flight(self, utau: np.ndarray) -> np.ndarray:
        """exp(A0 dt_i) of the free-flight segments at the delays utau, (segments, len(utau), 2n,
        2n), real; cached per delay (a structure is solved at a few delays many times over)."""
        cache = self.__dict__.setdefault("_free_cache", {})
        new = [t for t in utau.tolist() if t not in cache]
        if new:
            free_idx = np.flatnonzero(~self.cutting)
            n2 = 2 * self.n
            Af = self.A0[None, None] * (self.fraction[free_idx, None] * np.array(new)[None, :])[:, :, None, None]
            Ef = sdm.expm_batched(Af.reshape(-1, n2, n2)).reshape(len(free_idx), len(new), n2, n2)
            for k, t in enumerate(new):
                cache[t] = Ef[:, k]
        return np.stack([cache[t] for t in utau.tolist()], axis=1)

    def log_char(self, a, theta, tau, h: float = 1e-6):
        """ln F and its derivatives in a and theta at nu = exp(-i theta), c = a (1 - nu).
        F = det(I - nu M(c)); d ln F / d nu = -tr((I - nu M)^-1 M), d ln F / dc by a relative
        difference of M in c."""
        a, theta, tau = (np.asarray(x, dtype=float).reshape(-1) for x in np.broadcast_arrays(a, theta, tau))
        nu = np.exp(-1j * theta)
        c = a * (1.0 - nu)
        dc = h * np.maximum(np.abs(c), 1e-30)
        M2 = self.monodromy(np.concatenate([c, c + dc]), np.concatenate([tau, tau]))
        M, Mp = M2[: len(c)], M2[len(c) :]
        eye = np.eye(M.shape[-1])
        D = eye - nu[:, None, None] * M
        sign, logdet = np.linalg.slogdet(D)
        with np.errstate(all="ignore"):
            X = _solve_each(D, np.concatenate([M, (Mp - M) / dc[:, None, None]], axis=2))
        n2 = M.shape[-1]
        L_nu = -np.trace(X[:, :, :n2], axis1=1, axis2=2)
        L_c = -nu * np.trace(X[:, :, n2:], axis1=1, axis2=2)
        L = logdet + np.log(sign)
        dL_da = L_c * (1.0 - nu)
        dL_dth = L_nu * (-1j * nu) + L_c * (1j * a * nu)
        return L, dL_da, dL_dth, np.abs(D).max(axis=(1, 2))


class ProjectedCharacteristic:
    """A FloquetCharacteristic restricted to some eigen-pairs of the free structure (a band of
    modes): z = T xi with A0 T = T diag(lam), so free flight is diagonal and a cutting segment's
    generator is diag(lam) + c Tl B_s T (Tl the matching rows of T^-1). Used for the seed search
    only (the neighbouring bands act on a seed's branch quasi-statically); every candidate is
    re-solved on the full characteristic. Coordinates: pair k at k and m + k (m pairs)."""

    def __init__(self, full: FloquetCharacteristic, pairs):
        lam, V = full.free_eig()
        Vinv = full.free_eig_inverse()
        sel = np.concatenate([[p[0] for p in pairs], [p[1] for p in pairs]]).astype(int)
        self.T, self.Tl, self.lam = V[:, sel], Vinv[sel, :], lam[sel]
        n = full.n
        self.Bs = -np.einsum("ri,sij,jq->srq", self.Tl[:, n:], full.W / full.scale[None, None, :], self.T[:n, :])
        self.fraction, self.start, self.cutting = full.fraction, full.start, full.cutting

    def monodromy(self, c: np.ndarray, tau: np.ndarray) -> np.ndarray:
        c = np.asarray(c, dtype=complex).reshape(-1)
        tau = np.broadcast_to(np.asarray(tau, dtype=float).reshape(-1), c.shape)
        r = len(self.lam)
        cut_idx = np.flatnonzero(self.cutting)
        A = c[None, :, None, None] * self.Bs[cut_idx, None]
        A[..., np.arange(r), np.arange(r)] += self.lam
        A = A * (self.fraction[cut_idx, None] * tau[None, :])[:, :, None, None]
        Ec = sdm.expm_batched(A.reshape(-1, r, r)).reshape(len(cut_idx), len(c), r, r)
        M = None
        k = 0
        for i in range(len(self.fraction)):
            if self.cutting[i]:
                E = Ec[k]
                k += 1
                M = E if M is None else E @ M
            else:  # free flight: diagonal
                d = np.exp(self.lam[None, :] * (self.fraction[i] * tau)[:, None])  # (B, r)
                M = d[:, :, None] * (np.eye(r) if M is None else M)
        return M

    def lift(self, xi: np.ndarray) -> np.ndarray:
        z = xi @ self.T.T
        return z / np.linalg.norm(z, axis=1, keepdims=True)


def mode_bands(char: FloquetCharacteristic):
    """Eigen-pairs of the free structure grouped into bands for the seed search: pairs sorted by
    frequency |Im lam| are split where consecutive frequencies differ by more than BAND_GAP;
    each band's projection holds the pairs within BAND_WIDEN of its range. Returns (pairs
    [(i, j) eigen indices], pair frequencies, band of every pair, [pair indices of every band's
    projection]) or None when the spectrum does not pair up or nothing would be left out."""
    lam, _ = char.free_eig()
    pos = np.flatnonzero(lam.imag > 0)
    real = np.flatnonzero(lam.imag == 0)
    taken = np.zeros(len(lam), bool)
    pairs = []
    for i in pos:
        d = np.abs(lam - np.conj(lam[i]))
        d[taken | (lam.imag >= 0)] = np.inf
        j = int(np.argmin(d))
        if not np.isfinite(d[j]) or d[j] > 1e-6 * abs(lam[i]):
            return None
        taken[j] = True
        pairs.append((int(i), j))
    if len(real) % 2:
        return None
    real = real[np.argsort(np.abs(lam[real]))]
    pairs += [(int(real[k]), int(real[k + 1])) for k in range(0, len(real), 2)]
    if len(pairs) * 2 != len(lam):
        return None
    freq = np.array([max(abs(lam[i].imag), 1e-9) for i, _ in pairs])
    order = np.argsort(freq)
    band = np.zeros(len(pairs), int)
    b = 0
    for k in range(1, len(order)):
        if freq[order[k]] > BAND_GAP * freq[order[k - 1]]:
            b += 1
        band[order[k]] = b
    members = []
    for bb in range(b + 1):
        f = freq[band == bb]
        members.append(np.flatnonzero((freq >= f.min() / BAND_WIDEN) & (freq <= f.max() * BAND_WIDEN)))
    if all(len(m) == len(pairs) for m in members):
        return None
    return pairs, freq, band, members


# --- seeds --------------------------------------------------------------------------------------


def _solve_each(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched solve in which a singular (or non-finite) element gives NaN instead of an
    exception for the whole batch: on failure the singular elements are found by their LU
    (slogdet's sign 0, the same zero pivot) and the others solved as one batch (a Python loop
    over the elements made this 10 % of a 300-speed lobe computation)."""
    try:
        return np.linalg.solve(A, b)
    except np.linalg.LinAlgError:
        out = np.full(np.broadcast_shapes(A.shape[:-2], b.shape[:-2]) + b.shape[-2:], np.nan, dtype=np.result_type(A, b))
        with np.errstate(all="ignore"):
            sign, logdet = np.linalg.slogdet(A)
        fine = np.flatnonzero((sign != 0) & np.isfinite(logdet))
        out[fine] = np.linalg.solve(A[fine], b[fine])
        return out


def _eig2(A: np.ndarray) -> np.ndarray:
    """Eigenvalues of 2 x 2 matrices along a grid, (k, 2), the square root's sign kept
    continuous along the grid (branches that are continuous in frequency)."""
    tr = A[:, 0, 0] + A[:, 1, 1]
    det = A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]
    s = np.sqrt(tr**2 / 4.0 - det)
    flip = np.ones(len(s))
    if len(s) > 1:
        turn = (s[1:] * np.conj(s[:-1])).real < 0
        flip[1:] = np.cumprod(np.where(turn, -1.0, 1.0))
    s = s * flip
    return np.stack([tr / 2.0 + s, tr / 2.0 - s], axis=1)


def zoa_seeds(dyn: ToolTipDynamics, cut: Cut, tau: float, char: FloquetCharacteristic | None = None):
    """(depth, theta in [0, 2 pi), mode index) of the zeroth-order boundary points at delay tau
    (`zoa_seeds_batch` at one delay)."""
    return zoa_seeds_batch(dyn, cut, np.array([tau], dtype=float), char)[0]


#: Most grid points x delays `zoa_seeds_batch` evaluates at once (memory).
ZOA_BATCH_POINTS = 1 << 20


def zoa_seeds_batch(dyn: ToolTipDynamics, cut: Cut, taus: np.ndarray, char: FloquetCharacteristic | None = None) -> list:
    """Per delay tau: (depth, theta in [0, 2 pi), mode index) of the zeroth-order boundary points:
    sign changes of Im a(w) with Re a > 0, a(w) = -1 / ((1 - exp(-i w tau)) Lambda(G(i w) H0)),
    on a grid around each mode (BAND_ZETAS zeta w each side, POINTS_PER_TOOTH_FREQUENCY points per
    w_T of the longest delay, at most zeta w / 10 apart). The receptance and its eigenvalues are
    evaluated once for all delays. With `char` (a characteristic of `dyn`) G comes from its free
    eigen-decomposition (O(n) per frequency instead of a solve for coupled structures)."""
    taus = np.asarray(taus, dtype=float).reshape(-1)
    frf = char.frf if char is not None else dyn.rotated(np.deg2rad(cut.feed_angle_deg)).frf
    H0 = mean_force_matrix(cut)
    wT = 2.0 * np.pi / taus.max()
    found = [[] for _ in taus]  # per delay: (depths, thetas, modes) arrays, mode by mode
    for r, (w, z) in enumerate(zip(dyn.wn_rad_s, dyn.zeta)):
        half = max(BAND_ZETAS * z, 0.02) * w
        spacing = min(z * w / 10.0, wT / POINTS_PER_TOOTH_FREQUENCY)
        count = int(min(20000, max(50, np.ceil(2 * half / spacing))))
        grid = np.linspace(max(w - half, 1e-3 * w), w + half, count)
        lam = _eig2(frf(grid) @ H0)  # (k, 2)
        lam[np.abs(lam) <= 1e-9 * np.abs(lam).max()] = 0.0  # round-off of a zero eigenvalue is no branch
        step = max(1, ZOA_BATCH_POINTS // count)
        for lo in range(0, len(taus), step):
            tau = taus[lo : lo + step]
            with np.errstate(all="ignore"):
                a = -1.0 / ((1.0 - np.exp(-1j * grid[None, :] * tau[:, None]))[:, :, None] * lam[None])  # (delays, k, 2)
            a = np.swapaxes(a, 1, 2)  # (delays, branch, k): crossings in the order branch, frequency
            im, re = a[..., :-1].imag, a[..., :-1].real
            im2, re2 = a[..., 1:].imag, a[..., 1:].real
            with np.errstate(all="ignore"):
                change = (np.sign(im) != np.sign(im2)) & (re > 0) & (re2 > 0) & np.isfinite(im) & np.isfinite(im2)
                # a jump of Im a through infinity (1 - exp(-i w tau) -> 0) is not a crossing
                change &= ~(np.abs(a[..., 1:] - a[..., :-1]) > 0.5 * np.maximum(np.abs(a[..., :-1]), np.abs(a[..., 1:])))
            e, b, j = np.nonzero(change)
            t = im[e, b, j] / (im[e, b, j] - im2[e, b, j])
            depth = re[e, b, j] + t * (re2[e, b, j] - re[e, b, j])
            theta = np.mod((grid[j] + t * (grid[j + 1] - grid[j])) * tau[e], 2.0 * np.pi)
            for q in np.unique(e):
                sel = e == q
                found[lo + q].append((depth[sel], theta[sel], np.full(int(sel.sum()), r, dtype=int)))
    return [tuple(np.concatenate([f[k] for f in parts]) if parts else np.zeros(0, dtype=int if k == 2 else float) for k in range(3)) for parts in found]


#: Hill's lowest boundary points (`hill`) added to the seeds of a coupled structure (an absorber):
#: the zeroth order misses branches an interrupted cut puts between the host's and the absorber's
#: modes, among them Hopf islands that no count above them sees.
HILL_SEEDS = 4


#: Period-doubling seeds: the flip condition (a real multiplier at -1, theta = pi, c = 2 a real)
#: is scanned at FLIP_POINTS depths from FLIP_RANGE[0] to FLIP_RANGE[1] x the job's lowest
#: zeroth-order seed (0: no scan; the winding count's repair then finds flip lobes, at ~10x the cost).
FLIP_POINTS = 20
FLIP_RANGE = (0.1, 4.0)


def _flip_scan(char, a: np.ndarray, tau: np.ndarray):
    """At depths a (jobs, points), delay tau per job: the number of real multipliers of M(2 a)
    below -1 and Re sigma + 1 of the multiplier nearest -1, both (jobs, points); one real batch."""
    jobs, points = a.shape
    with np.errstate(all="ignore"):
        M = char.monodromy(2.0 * a.ravel(), np.repeat(tau, points))
    finite = np.all(np.isfinite(M), axis=(1, 2))  # an overflowing M (depths far past every boundary): no multipliers
    sigma = np.full(M.shape[:2], np.nan, dtype=complex)
    sigma[finite] = np.linalg.eigvals(M[finite])
    real = np.abs(sigma.imag) <= 1e-9 * np.maximum(np.abs(sigma), 1e-300)
    below = (real & (sigma.real < -1.0)).sum(axis=1).reshape(jobs, points)
    known = finite.reshape(jobs, points)
    last = np.maximum.accumulate(np.where(known, np.arange(points)[None, :], 0), axis=1)  # where nothing is known, the last known count: no crossing
    below = np.take_along_axis(below, last, axis=1)
    nearest = np.full(len(sigma), np.nan)
    nearest[finite] = sigma[finite][np.arange(finite.sum()), np.argmin(np.abs(sigma[finite] + 1.0), axis=1)].real + 1.0
    return below, nearest.reshape(jobs, points)


def _flip_grid(a_scale, top: float) -> np.ndarray:
    """Depths FLIP_RANGE[0] to `top` x each scale, spaced as FLIP_POINTS over FLIP_RANGE."""
    lo, hi = FLIP_RANGE
    points = max(2, int(np.ceil((FLIP_POINTS - 1) * np.log(top / lo) / np.log(hi / lo) - 1e-9)) + 1)
    return np.asarray(a_scale, dtype=float)[:, None] * np.geomspace(lo, top, points)[None, :]


def flip_seeds(char, a_scale, tau, jobs):
    """[(job, depth)] where a real multiplier of M(2 a) passes below -1 between two of the scanned
    depths (the number of real multipliers below -1 grows; often just after a complex pair has
    met on the negative axis), placed by linear interpolation of Re sigma + 1 of the multiplier
    nearest -1; one batch for all the jobs of a structure (depth scale a_scale and delay tau per
    job), depths FLIP_RANGE x the scale. Also returns the scan, {job: (depths, number below -1,
    Re sigma + 1 nearest -1)}, which `_islands_from_seed_scan` reuses."""
    a = _flip_grid(a_scale, FLIP_RANGE[1])
    below, nearest = _flip_scan(char, a, np.asarray(tau, dtype=float))
    scans = {j: (a[q], below[q], nearest[q]) for q, j in enumerate(jobs)}
    out = []
    for q, j in enumerate(jobs):
        cross = np.flatnonzero(np.diff(below[q]) > 0)
        if len(cross):
            k = cross[0]
            x, y = a[q, k : k + 2], nearest[q, k : k + 2]
            inside = np.all(np.isfinite(y)) and y[0] > 0 >= y[1]
            out.append((j, float(x[0] + (x[1] - x[0]) * y[0] / (y[0] - y[1])) if inside else float(np.sqrt(x[0] * x[1]))))
    return out, scans


#: Flip islands (`flip_islands`): a coarse-model scan point whose multiplier nearest -1 is within
#: FLIP_NEAR of it (|Re sigma + 1|) sends the scan to the answer's resolution; there, at a local
#: minimum without passing, FLIP_REFINE more depths between the neighbouring scan points are
#: looked at.
FLIP_NEAR = 0.02
FLIP_REFINE = 8


def flip_islands(char, depth, tau, refine: bool = True, starts: bool = False):
    """For each (depth, tau): whether a real multiplier of M(2 a) is below -1 at some scanned a in
    FLIP_RANGE[0] .. VERIFY_FRACTION x depth, i.e. a period-doubling lobe lies below the depth.
    Such a lobe is an island (the multiplier passes -1 and comes back), which the winding count at
    one depth above it cannot see; where the multiplier nearest -1 only comes near it (FLIP_NEAR),
    the scan is refined there (FLIP_REFINE points) so an island narrower than the scan's spacing
    is not passed over. Returns (island, near): near where some scanned Re sigma + 1 is below
    FLIP_NEAR (a finer cut model may turn it into an island). `refine` False: the scan alone.
    `starts`: also a depth at the island's lower end for each (the geometric middle of the first
    scan bracket it begins in, as `dense_flip`'s; NaN where none), where a job solved again starts
    (without one it starts from the seeds, whose coarser flip scan can miss the island: seen, a
    41-48 mm island under a 57 mm answer at 30,000 rpm, 8 teeth, 2 % immersion, left unverified)."""
    depth = np.atleast_1d(np.asarray(depth, dtype=float))
    tau = np.broadcast_to(np.asarray(tau, dtype=float), depth.shape)
    a = _flip_grid(depth, VERIFY_FRACTION)
    below, nearest = _flip_scan(char, a, tau)
    hit, near = _island_verdict(below, nearest)
    inside = np.array([_first_rise(a[q], below[q], below[q, 0]) for q in range(len(depth))]) if starts else None
    near_q, near_k = [], []
    for q in np.flatnonzero(~hit) if refine else ():
        for k in _approaches(nearest[q]):
            near_q.append(q)
            near_k.append(k)
    if near_q:
        lo = a[near_q, np.array(near_k) - 1]
        hi = a[near_q, np.minimum(np.array(near_k) + 1, a.shape[1] - 1)]
        fine = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, FLIP_REFINE + 2)[None, 1:-1]
        b_fine, _ = _flip_scan(char, fine, tau[near_q])
        for i, (q, row) in enumerate(zip(near_q, b_fine)):
            if not hit[q] and np.any(row > below[q, 0]):
                hit[q] = True
                if starts:
                    inside[q] = _first_rise(np.r_[lo[i], fine[i]], np.r_[below[q, 0], row], below[q, 0])
    return (hit, near, inside) if starts else (hit, near)


def _first_rise(a: np.ndarray, below: np.ndarray, base) -> float:
    """The geometric middle of the first bracket of increasing depths a in which the number of
    real multipliers below -1 rises above `base` (below[0]); NaN where it never does."""
    k = np.flatnonzero(below > base)
    return float(np.sqrt(a[k[0] - 1] * a[k[0]])) if len(k) else np.nan


def _island_verdict(below, nearest):
    """(island, near) per row of a scan in increasing depth (`_flip_scan`): more real multipliers
    below -1 somewhere than at the first depth; some Re sigma + 1 within FLIP_NEAR of 0."""
    return np.any(below > below[:, :1], axis=1), np.any(np.abs(nearest) < FLIP_NEAR, axis=1)


def _islands_from_seed_scan(char, scans: dict, jobs, depth, tau):
    """`flip_islands(..., refine=False)` for the jobs whose flip-seed scan (`flip_seeds`, same
    cut model, same depth spacing) reaches VERIFY_FRACTION x the depth: its points below that
    depth, the points at its spacing from FLIP_RANGE[0] x the depth up to its first one (where
    the answer lies below the scan's scale) and one at VERIFY_FRACTION x the depth, in one batch.
    Returns (island, near, covered) per job; island and near are False where not covered (the
    caller scans those)."""
    depth = np.asarray(depth, dtype=float)
    island, near, covered = (np.zeros(len(depth), bool) for _ in range(3))
    for q, j in enumerate(jobs):
        covered[q] = j in scans and scans[j][0][-1] >= VERIFY_FRACTION * depth[q]
    if not covered.any():
        return island, near, covered
    idx = np.flatnonzero(covered)
    lows = []
    for q in idx:
        a = scans[jobs[q]][0]
        start = FLIP_RANGE[0] * depth[q]
        lows.append(start * (a[1] / a[0]) ** np.arange(max(0, int(np.ceil(np.log(a[0] / start) / np.log(a[1] / a[0]) - 1e-9)))))
    width = max(len(x) for x in lows) + 1  # the low points, then the top one (repeated to fill the row)
    extra = np.array([np.concatenate([x, np.full(width - len(x), VERIFY_FRACTION * depth[q])]) for x, q in zip(lows, idx)])
    extra_below, extra_nearest = _flip_scan(char, extra, np.asarray(tau, dtype=float)[idx])
    for r, (q, x) in enumerate(zip(idx, lows)):
        a, below, nearest = scans[jobs[q]]
        k = a < VERIFY_FRACTION * depth[q]
        n = len(x)
        row_below = np.concatenate([extra_below[r, :n], below[k], extra_below[r, n:]])
        row_nearest = np.concatenate([extra_nearest[r, :n], nearest[k], extra_nearest[r, n:]])
        hit, close = _island_verdict(row_below[None], row_nearest[None])
        island[q], near[q] = hit[0], close[0]
    return island, near, covered


def _coarse_islands(char_at, seed_char, seed_scans: dict, jobs, depth, tau, levels, ladders=None):
    """(island, near, inside, spans) of the island check on a coarse cut model for jobs with answers at
    `depth` (refinement `levels`): from the verification count's interpolant where the job has
    one (`ladder_islands`, on that count's cut model; `ladders`: one (level, depth, coefficients,
    bound) or None per job), else from the flip-seed scan where it covers the range
    (`_islands_from_seed_scan`; `seed_char` is the coarse model, possibly without the irrelevant
    modes), else a scan of the whole structure at level 0 (char_at(level): the whole structure's
    cut model at a level). Where the seed scan sees an island or a multiplier within FLIP_NEAR of -1 for a
    level-0 answer, a refined scan of the whole structure decides (the seed scan samples other
    depths: a narrow island can fall between its points and not between the refined scan's).
    inside: the bracket of the coarse model's island's lower end (`ladder_islands`; NaN where
    none or not known); spans: where the answer's resolution is to be looked at (`ladder_islands`;
    None: everywhere below the answer)."""
    depth, tau = np.asarray(depth, dtype=float), np.asarray(tau, dtype=float)
    ladders = [None] * len(depth) if ladders is None else ladders
    hit, near = np.zeros(len(depth), bool), np.zeros(len(depth), bool)
    inside = np.full(len(depth), np.nan)
    laddered = np.array([x is not None for x in ladders], bool)
    spans = [None] * len(depth)
    for q in np.flatnonzero(laddered):
        hit[q], spans[q], inside[q] = ladder_islands(char_at(ladders[q][0]), *ladders[q][1:], depth[q], tau[q])
        near[q] = bool(spans[q])
    rest = np.flatnonzero(~laddered)
    if not len(rest):
        return hit, near, inside, spans
    h, n, covered = _islands_from_seed_scan(seed_char, seed_scans, [jobs[q] for q in rest], depth[rest], tau[rest])
    hit[rest], near[rest] = h, n
    if not covered.all():
        hit[rest[~covered]], near[rest[~covered]] = flip_islands(char_at(0), depth[rest[~covered]], tau[rest[~covered]], refine=False)
    again = rest[covered & (hit[rest] | near[rest]) & (np.asarray(levels)[rest] == 0)]
    if len(again):
        hit[again], near[again] = flip_islands(char_at(0), depth[again], tau[again])
    hit[rest] &= np.asarray(levels)[rest] == 0  # a scan this sparse decides at level 0 only
    return hit, near, inside, spans


#: The flip-island check from the winding count's interpolant (`ladder_islands`): depths
#: FLIP_RANGE[0] to LADDER_SPLIT x the answer LADDER_RATIO[0] apart, from there to
#: VERIFY_FRACTION x it LADDER_RATIO[1] apart (a 13-point scan, 1.21 apart, passed over an island
#: 4 % wide, 0.508-0.530 mm under a 0.544 mm answer, in the blind search; 1.02 all the way costs
#: 5 % of a 300-speed lobe diagram, this 3 %). Under an answer at a finer resolution, that
#: resolution is looked at LADDER_RATIO[1] apart around every run of ladder points near -1 and
#: around the coarse island, widened by ISLAND_WIDEN either side (`dense_flip`).
LADDER_RATIO = (1.05, 1.02)
LADDER_SPLIT = 0.5
ISLAND_WIDEN = 1.1


def ladder_islands(char, a0: float, coef: np.ndarray, bound: float, depth: float, tau: float):
    """(island, spans, inside) below `depth` from the interpolant of the winding count at a0
    (`unstable_count(polynomial=...)`): M(a0 (1 - nu)) = sum coef_k nu^k is entire in nu and the
    interpolant's error bound holds on the whole disk |nu| <= 1, so nu = 1 - 2 a / a0 (real) gives
    the flip condition's M(2 a) at every a in (0, a0] without an exponential. The sign of
    det(I + M(2 a)) is (-1)^(number of real multipliers below -1); it is taken at depths
    FLIP_RANGE[0] to VERIFY_FRACTION x depth (LADDER_RATIO, LADDER_SPLIT), on the interpolant P where
    |(I + P)^-1|_F x bound < 1 (then every eigenvalue of I + (I + P)^-1 dM lies within 1 of 1:
    det(I + M) has the sign of det(I + P)), elsewhere (and above a0) on M itself. island: the
    sign changes along the ladder; spans: the depth intervals a finer cut model's island can lie
    in, each run of ladder points with |(I + M)^-1|_F >= 1 / FLIP_NEAR (wherever a multiplier
    comes within FLIP_NEAR of -1: |(I + M)^-1|_2 >= 1 / |1 + sigma| for every eigenvalue sigma)
    and the island, widened by ISLAND_WIDEN either side; inside: the geometric middle of the
    first bracket of the change, a Newton start for the island's lower flip point (NaN where
    none)."""
    n2 = coef.shape[-1]
    eye = np.eye(n2)
    (lo, ratio_lo), (mid, ratio) = (FLIP_RANGE[0], LADDER_RATIO[0]), (LADDER_SPLIT, LADDER_RATIO[1])
    a = depth * np.concatenate([np.geomspace(lo, mid, int(np.ceil(np.log(mid / lo) / np.log(ratio_lo))), endpoint=False),
                                np.geomspace(mid, VERIFY_FRACTION, int(np.ceil(np.log(VERIFY_FRACTION / mid) / np.log(ratio))) + 1)])
    M = np.zeros((len(a), n2, n2))
    inner = a <= a0
    nu = 1.0 - 2.0 * a[inner] / a0
    M[inner] = _polynomial_matrices(np.ascontiguousarray(coef.real), nu)  # real nu: real M
    size = _inverse_norms(eye + M)  # (the near test needs every inverse: no cheaper bound first)
    direct = ~(inner & (size * bound < 1.0))
    if direct.any():
        with np.errstate(all="ignore"):
            M[direct] = char.monodromy(2.0 * a[direct], np.full(int(direct.sum()), tau)).real
        size[direct] = _inverse_norms(eye + M[direct])
    island, inside = _sign_change(a, M)
    close = ~(size < 1.0 / FLIP_NEAR)
    runs = np.flatnonzero(np.diff(np.concatenate([[0], close.astype(int), [0]])))  # starts and ends of the near runs
    spans = [(a[i] / ISLAND_WIDEN, a[k - 1] * ISLAND_WIDEN) for i, k in zip(runs[::2], runs[1::2])]
    if island:
        spans.insert(0, (inside / ISLAND_WIDEN, inside * ISLAND_WIDEN))
    return island, spans, inside


#: Hopf islands (a pair of complex multipliers outside the circle between two depths below the
#: answer, inside again up to it) are looked for by the winding count at these fractions of the
#: verified depth as well (`hopf_rung`): an island that holds any of them is found. Seen in the
#: blind search: 0.50-0.80 and 0.55-0.85 of the answer (uncoupled), 0.60-0.73 and 0.67-0.75
#: (absorber poses); every one holds 0.63 or 0.71.
HOPF_RUNGS = (0.5, 0.63, 0.71, 0.8)


def hopf_rung(char, a0: float, coef: np.ndarray, bound: float, tau: float, extra=(), base: float | None = None):
    """The lowest of HOPF_RUNGS x base (a0) at which the winding count is not shown to be 0, None
    where every rung counts 0 (base <= a0). The counts read h on the interpolant of the count at
    a0 (`unstable_count(polynomial=...)`, `_interpolated_sample`: no exponential), with the same
    Rouche check per sample; where that fails or there is none (coef None: the count sampled M
    directly), on M itself (`unstable_count` at each rung)."""
    base = a0 if base is None else base
    th = _count_thetas(char, tau, VERIFY_POINTS, extra)
    try:  # every rung on one grid
        if coef is None:
            raise _Unsafe
        count, resolved, _ = _winding(functools.partial(_interpolated_sample, coef, bound, scales=np.array(HOPF_RUNGS) * (base / a0)), th, 4096)
    except _Unsafe:
        count, resolved = (np.array(x) for x in zip(*(unstable_count(char, s * base, tau, extra=extra)[:2] for s in HOPF_RUNGS)))
    shown = (count > 0) | ~resolved
    return float(HOPF_RUNGS[int(np.argmax(shown))] * base) if shown.any() else None


def _sign_change(a: np.ndarray, M: np.ndarray):
    """(changed, where) along increasing depths a: whether the sign of det(I + M(2 a)) changes
    (points with a non-finite M skipped) and the geometric middle of the first bracket (NaN)."""
    with np.errstate(all="ignore"):
        sign, _ = np.linalg.slogdet(np.eye(M.shape[-1]) + M)
    ok = np.flatnonzero(np.isfinite(sign) & (sign != 0))
    changed = ok[1:][sign[ok[1:]] != sign[ok[0]]] if len(ok) else ok
    if not len(changed):
        return False, np.nan
    k = int(np.searchsorted(ok, changed[0]))
    return True, float(np.sqrt(a[ok[k - 1]] * a[changed[0]]))


def flip_ahead(char_at, level: int, top: int, spans, depth: float, tau: float, ladder=None):
    """A period-doubling island that only a finer cut model than the answer's (`level`) has: where
    a multiplier comes near -1 (`spans`, `ladder_islands`), the levels above, one at a time, around
    each closest approach (within FLIP_NEAR; FOCUS_POINTS either side, LADDER_RATIO[1] apart, up to
    VERIFY_FRACTION x depth, and FLIP_REFINE more around a local minimum, `_scan_island`), for as
    long as at some of those depths the multiplier nearest -1 moved from the level before by more
    than it is still short of -1 (the approach is not resolved). Seen: 15 modes, 4 teeth at 9382
    rpm, a/D 0.053: -0.9979 / -0.9998 / -1.0001 / -1.0002 at 13 / 26 / 52 / 103 sub-steps a radian,
    an island at 4.55-4.70 mm under a 7.14 mm answer converged at 26. char_at(level) is the cut
    model of a level (up to `top`); `ladder`: the verification count's interpolant (level, a0,
    coefficients, bound), which gives the answer's level without an exponential where it is that
    level. Returns (a depth in the island's lower bracket, its level) or None."""
    grids = [np.geomspace(lo, hi, max(2, int(np.ceil(np.log(hi / lo) / np.log(LADDER_RATIO[1]))) + 1))
             for lo, hi in ((lo, min(hi, VERIFY_FRACTION * depth)) for lo, hi in spans) if 0.0 < lo < hi]
    if not grids:
        return None
    a = np.unique(np.concatenate(grids))
    on_ladder = ladder is not None and a[-1] <= ladder[1]
    if on_ladder:  # where the approaches are, from the count's level: M(2 a) = P(1 - 2 a / a0), real; 1 / |(I + M)^-1|_F <= |1 + sigma|
        M = _polynomial_matrices(np.ascontiguousarray(ladder[2].real), 1.0 - 2.0 * a / ladder[1])
        with np.errstate(all="ignore"):
            gap = 1.0 / _inverse_norms(np.eye(M.shape[-1]) + M)
    else:
        prev = _flip_scan(char_at(level), a[None], np.array([tau]))[1][0]
        gap = np.abs(prev)
    gap = np.where(np.isfinite(gap), gap, np.inf)
    closest = [k for k in range(len(a)) if gap[k] < FLIP_NEAR and gap[k] <= gap[max(k - 1, 0)] and gap[k] <= gap[min(k + 1, len(a) - 1)]]
    if not closest:
        return None
    keep = np.unique(np.clip(np.add.outer(closest, np.arange(-FOCUS_POINTS, FOCUS_POINTS + 1)).ravel(), 0, len(a) - 1))
    a = a[keep]
    if not on_ladder:
        prev = prev[keep]
    elif ladder[0] == level:
        with np.errstate(all="ignore"):
            sigma = np.linalg.eigvals(M[keep])
        prev = sigma[np.arange(len(a)), np.argmin(np.abs(sigma + 1.0), axis=1)].real + 1.0
    else:  # the answer's level is finer than the count's
        prev = _flip_scan(char_at(level), a[None], np.array([tau]))[1][0]
    for lv in range(level + 1, top + 1):
        inside, nearest = _scan_island(char_at(lv), a, tau)
        if inside is not None:
            return inside, lv
        with np.errstate(invalid="ignore"):
            if not np.any(np.abs(nearest) < np.abs(nearest - prev)):
                return None
        prev = nearest
    return None


#: `flip_ahead` looks at this many depths either side of each closest approach of a multiplier to -1.
FOCUS_POINTS = 3


def _scan_island(char, a: np.ndarray, tau: float):
    """(a depth in the lower bracket of the first island on depths `a`, or None; Re sigma + 1 of the
    multiplier nearest -1 at each depth): a real multiplier below -1 at a depth where the first has
    none, at the depths or at FLIP_REFINE more between the neighbours of each local minimum of
    Re sigma + 1 in (0, FLIP_NEAR)."""
    below, nearest = (x[0] for x in _flip_scan(char, a[None], np.array([tau])))
    more = np.flatnonzero(below > below[0])
    if len(more):
        return float(np.sqrt(a[more[0] - 1] * a[more[0]])), nearest
    for k in _approaches(nearest):
        fine = np.linspace(a[k - 1], a[min(k + 1, len(a) - 1)], FLIP_REFINE + 2)[1:-1]
        b_fine = _flip_scan(char, fine[None], np.array([tau]))[0][0]
        more = np.flatnonzero(b_fine > below[0])
        if len(more):
            return float(fine[more[0]]), nearest
    return None, nearest


def _approaches(y: np.ndarray) -> list:
    """Indices k >= 1 of the local minima of Re sigma + 1 along a scan that lie in (0, FLIP_NEAR):
    where a multiplier comes nearest -1 without passing it (the last point counts as a minimum)."""
    last = len(y) - 1
    return [k for k in range(1, len(y)) if 0.0 < y[k] < FLIP_NEAR and y[k] <= y[k - 1] and (k == last or y[k] <= y[k + 1])]


def dense_flip(char, lo: float, hi: float, tau: float):
    """(island, inside): `_sign_change` at depths lo .. hi, LADDER_RATIO[1] apart, on `char`
    (monodromies: one real batch)."""
    a = np.geomspace(lo, hi, max(2, int(np.ceil(np.log(hi / lo) / np.log(LADDER_RATIO[1]))) + 1))
    with np.errstate(all="ignore"):
        M = char.monodromy(2.0 * a, np.full(len(a), tau)).real
    return _sign_change(a, M)


# --- boundary-point solvers ---------------------------------------------------------------------


def _follow_eig(M, vec, sig0, iterations: int = 3):
    """Eigenpair of every M (B, N, N) continuing `vec` (unit, B x N): inverse iteration with the
    shift updated by sigma += 1 / (v^H (M - sigma)^-1 v), from sig0. Returns sigma, unit v and
    whether the pair is accepted (small residual and overlap >= 0.9 with `vec`)."""
    eye = np.eye(M.shape[-1])
    v, sig = vec, np.array(sig0, dtype=complex)
    with np.errstate(all="ignore"):
        for _ in range(iterations):
            shift = sig * (1.0 + 1e-10) + 1e-300  # never exactly an eigenvalue
            try:
                x = _solve_each(M - shift[:, None, None] * eye, v[:, :, None])[:, :, 0]
            except np.linalg.LinAlgError:
                return sig, vec, np.zeros(len(sig), bool)
            sig = shift + 1.0 / np.einsum("bi,bi->b", np.conj(v), x)
            v = x / np.linalg.norm(x, axis=1, keepdims=True)
        res = np.linalg.norm(np.einsum("bij,bj->bi", M, v) - sig[:, None] * v, axis=1)
        scale = np.abs(M).max(axis=(1, 2))
        overlap = np.abs(np.einsum("bi,bi->b", np.conj(vec), v))
    ok = np.isfinite(sig) & np.all(np.isfinite(v), axis=1) & (res <= 1e-9 * scale) & (overlap >= 0.9)
    return sig, v, ok


def _critical_log(char, a, theta, tau, target=None, idx=None, mode=None, vec=None):
    """g = ln(nu sigma) for one eigenvalue sigma of M(a (1 - nu)), nu = exp(-i theta); the
    boundary is g = 0. Batched. The branch is followed by its eigenvector: the eigenvalue whose
    eigenvector overlaps most with `vec` (previous evaluation; by inverse iteration from the
    predicted eigenvalue, full eigen-decomposition where that does not settle); at a seed, among
    the eigenvectors living on the seed's `mode` (q_r, q_r'), the one nearest to 1; otherwise
    nearest `target`. Returns g (Im wrapped to (-pi, pi]) and the unit eigenvectors picked."""
    if idx is not None and hasattr(char, "take"):
        char = char.take(idx)
    nu = np.exp(-1j * theta)
    with np.errstate(over="ignore", invalid="ignore"):  # a wild step's overflow dies below (NaN)
        M = char.monodromy(a * (1.0 - nu), tau)
    rows = np.arange(len(a))
    out_g = np.empty(len(a), dtype=complex)
    out_v = np.empty((len(a), M.shape[-1]), dtype=complex)
    todo = rows
    has_vec = np.zeros(len(a), bool)
    if vec is not None:  # rows without a vector (NaN) pick as if none were given
        with np.errstate(all="ignore"):
            vec = vec / np.linalg.norm(vec, axis=1, keepdims=True)
        has_vec = np.all(np.isfinite(vec), axis=1)
        fol = rows[has_vec]
        if target is not None:
            sig0 = np.exp(target[fol]) / nu[fol]
        else:
            sig0 = np.einsum("bi,bij,bj->b", np.conj(vec[fol]), M[fol], vec[fol])
        sig_f, v_f, ok_f = _follow_eig(M[fol], vec[fol], sig0) if len(fol) else (np.zeros(0, complex), vec[fol], np.zeros(0, bool))
        with np.errstate(all="ignore"):
            g_f = np.log(sig_f * nu[fol])
        ok_f &= np.isfinite(g_f)
        out_g[fol[ok_f]], out_v[fol[ok_f]] = g_f[ok_f], v_f[ok_f]
        left = np.ones(len(a), bool)
        left[fol[ok_f]] = False
        todo = rows[left]
        if not len(todo):
            return out_g, out_v
    finite = np.all(np.isfinite(M[todo]), axis=(1, 2))  # an overflowing element dies (NaN), not the batch
    out_g[todo[~finite]], out_v[todo[~finite]] = np.nan, np.nan
    todo = todo[finite]
    if not len(todo):
        return out_g, out_v
    Mt, nut = M[todo], nu[todo]
    sig, V = np.linalg.eig(Mt)
    V = V / np.linalg.norm(V, axis=1, keepdims=True)
    sig = sig * nut[:, None]
    with np.errstate(all="ignore"):
        lg = np.log(sig)
    r = np.arange(len(todo))
    ref = np.zeros(len(todo), dtype=complex) if target is None else target[todo]
    with np.errstate(invalid="ignore"):  # ln 0 = -inf against an infinite target: no candidate
        dist = np.abs(lg - ref[:, None])
    if mode is not None:
        md = mode[todo]
        n = M.shape[-1] // 2
        w = np.abs(V) ** 2
        share = (w[r, md] + w[r, n + md]) / w.sum(axis=1)
        share = np.where((md >= 0)[:, None], share, 1.0)
        dist = np.where(share >= 0.5 * share.max(axis=1, keepdims=True), dist, np.inf)
    pick = np.argmin(dist, axis=1)
    followed = has_vec[todo]
    if followed.any():
        overlap = np.abs(np.einsum("bi,bij->bj", np.conj(vec[todo[followed]]), V[followed]))
        with np.errstate(invalid="ignore"):
            score = overlap / (1.0 + np.abs(lg[followed] - ref[followed, None]))
        pick[followed] = np.argmax(np.where(np.isfinite(score), score, -1.0), axis=1)
    out_g[todo], out_v[todo] = lg[r, pick], V[r, :, pick]
    return out_g, out_v


def _newton(char, a, theta, tau, iterations: int = 25, tol: float = 1e-8, Gc=None, mode=None, vec=None, group=None):
    """Newton on g(a, theta) = ln(nu sigma(M(a (1 - nu)))) = 0, two real unknowns, batched.
    dg/dnu = 1 / nu exactly; G_c = d ln sigma / dc by one finite difference at the start
    (where the `Gc` given is not finite), then secant (Broyden) updates from the iterates: one monodromy per
    iteration. `group` (one id per element: the seeds of one job) enables pruning: an element
    is dropped once it heads to a point of its group already converged, once it is more than
    PRUNE_ABOVE x above the group's lowest converged point, or when it stalls (|g| > 1 after 8
    iterations, > 0.05 after 12). Returns a, theta, converged, Gc."""
    a, theta, tau = (np.array(x, dtype=float).reshape(-1) for x in np.broadcast_arrays(a, theta, tau))
    B = len(a)
    if not B:
        return a, theta, np.zeros(0, bool), np.zeros(0, complex), None
    g, vec = _critical_log(char, a, theta, tau, mode=None if mode is None else np.asarray(mode, dtype=int).reshape(-1), vec=vec)
    Gc = np.full(B, np.nan, complex) if Gc is None else np.broadcast_to(np.asarray(Gc, dtype=complex), (B,)).copy()
    need = np.flatnonzero(~np.isfinite(Gc))
    if len(need):  # by one difference where no G_c is given
        h = 1e-4
        g2, _ = _critical_log(char, a[need] * (1.0 + h), theta[need], tau[need], target=g[need], idx=need, vec=vec[need])
        with np.errstate(all="ignore"):
            Gc[need] = (g2 - g[need]) / (h * a[need] * (1.0 - np.exp(-1j * theta[need])))
    done = np.zeros(B, bool)
    dead = ~np.isfinite(g) | (a <= 0) | ~np.isfinite(Gc)
    for k in range(iterations):
        act = np.flatnonzero(~done & ~dead)
        if not len(act):
            break
        aa, th = a[act], theta[act]
        nu = np.exp(-1j * th)
        step, ga, gt, bad = _newton_step(aa, th, Gc[act], g[act])
        a_new, t_new = aa + step[:, 0], th + step[:, 1]
        g_pred = g[act] + ga * step[:, 0] + gt * step[:, 1]
        g_new, v_new = _critical_log(char, a_new, t_new, tau[act], target=g_pred, idx=act, vec=vec[act])
        vec[act] = v_new
        # secant update of G_c: g_new - g = dln(nu) + G dc
        nu_new = np.exp(-1j * t_new)
        dc = a_new * (1.0 - nu_new) - aa * (1.0 - nu)
        dlnnu = -1j * step[:, 1]
        with np.errstate(all="ignore"):
            G_upd = (g_new - g[act] - dlnnu) / dc
        ok = np.isfinite(G_upd) & (np.abs(dc) > 1e-12 * np.abs(aa))
        Gc[act[ok]] = G_upd[ok]
        a[act], theta[act], g[act] = a_new, t_new, g_new
        small = (np.abs(step[:, 0]) < tol * aa) & (np.abs(step[:, 1]) < tol) & (np.abs(g_new) < 1e-6)
        # or the next step would be that small: taken without another monodromy
        nxt, _, _, nbad = _newton_step(a_new, t_new, Gc[act], g_new)
        last = ~small & ~nbad & (np.abs(nxt[:, 0]) < tol * a_new) & (np.abs(nxt[:, 1]) < tol) & (np.abs(g_new) < LAST_G)
        a[act[last]] += nxt[last, 0]
        theta[act[last]] += nxt[last, 1]
        done[act[small | last]] = True
        dead[act[bad | (a_new <= 0) | ~np.isfinite(g_new) | ((k > 10) & (np.abs(g_new) > 0.5))]] = True
        if group is not None:
            ag = np.abs(g_new)
            dead[act[((k >= STALL[0][0]) & (ag > STALL[0][1])) | ((k >= STALL[1][0]) & (ag > STALL[1][1])) | ((k >= STALL[2][0]) & (ag > STALL[2][1]))]] = True
            _prune(a, theta, g, done, dead, np.asarray(group))
    ok = done & ~dead & (a > 0)
    theta = np.mod(theta, 2.0 * np.pi)
    return a, theta, ok, Gc, vec


def _newton_step(a, theta, Gc, g):
    """The Newton step (da, dtheta) on g(a, theta) with dg/da = G_c (1 - nu), dg/dtheta =
    -i + G_c i a nu, as a 2 x 2 real system (Cramer's rule: a singular one marks its element
    bad, not the batch), limited to 30 % in a and 0.5 rad. Returns (step, dg/da, dg/dtheta, bad)."""
    nu = np.exp(-1j * theta)
    ga = Gc * (1.0 - nu)
    gt = -1j + Gc * (1j * a * nu)
    with np.errstate(all="ignore"):
        det = ga.real * gt.imag - gt.real * ga.imag
        step = -np.stack([gt.imag * g.real - gt.real * g.imag, ga.real * g.imag - ga.imag * g.real], 1) / det[:, None]
    bad = ~np.all(np.isfinite(step), axis=1)
    step[bad] = 0.0
    step /= _step_excess(a, step[:, 0], step[:, 1])[:, None]
    return step, ga, gt, bad


def _step_excess(a, da, dtheta):
    """The divisor (>= 1) that limits a Newton step to 30 % in depth and 0.5 rad in theta."""
    return np.maximum(np.maximum(np.abs(da) / (0.3 * a), np.abs(dtheta) / 0.5), 1.0)


def _prune(a, theta, g, done, dead, group):
    """Marks dead the active elements that are heading to a converged point of their group
    (|g| < 0.1, depth within 1 %, theta within 0.01 up to conjugation) or lie PRUNE_ABOVE x above the
    group's lowest converged depth."""
    fin = np.flatnonzero(done & ~dead)
    act = np.flatnonzero(~done & ~dead)
    if not len(fin) or not len(act):
        return
    best = np.full(group.max() + 1, np.inf)
    np.minimum.at(best, group[fin], a[fin])
    dead[act[a[act] > PRUNE_ABOVE * best[group[act]]]] = True
    act = act[~dead[act]]
    if not len(act):
        return
    folded = np.mod(theta, 2.0 * np.pi)
    folded = np.where(folded > np.pi, 2.0 * np.pi - folded, folded)
    order = np.lexsort((a[fin], group[fin]))
    fg, fa, ft = group[fin][order], a[fin][order], folded[fin][order]
    key_f = fg * 4.0 + np.log(fa) / 1e3  # depths are far below exp(1e3)
    pos = np.searchsorted(key_f, group[act] * 4.0 + np.log(a[act]) / 1e3)
    for off in (-1, 0):
        p = np.clip(pos + off, 0, len(fin) - 1)
        same = (fg[p] == group[act]) & (np.abs(fa[p] - a[act]) <= 1e-2 * fa[p]) & (np.abs(ft[p] - folded[act]) <= 1e-2) & (np.abs(g[act]) < 0.1)
        dead[act[same]] = True


def segment_samples(char: FloquetCharacteristic, a: float, tau: float, m: int, previous: np.ndarray | None = None) -> np.ndarray:
    """Every segment's exponential E_s(nu) = exp(dt_s A_s(a (1 - nu))) at the m-th roots of unity
    nu = exp(-2 pi i j / m), j = 0 .. m / 2 (the others are their conjugates: the structure is
    real), (segments, m / 2 + 1, 2n, 2n); `previous`: those at m / 2 roots (reused as the even j)."""
    with np.errstate(all="ignore"):  # overflowing exponentials (far past every boundary): `segment_interpolants` refuses them
        if previous is None:
            return char.exponentials(a * (1.0 - np.exp(-2j * np.pi * np.arange(m // 2 + 1) / m)), np.full(m // 2 + 1, tau))
        odd = 2.0 * np.pi * np.arange(1, m // 2, 2) / m
        merged = np.empty(previous.shape[:1] + (m // 2 + 1,) + previous.shape[2:], dtype=complex)
        merged[:, 0::2] = previous
        merged[:, 1::2] = char.exponentials(a * (1.0 - np.exp(-1j * odd)), np.full(len(odd), tau))
    return merged


def segment_interpolants(E: np.ndarray, m: int):
    """Taylor coefficients in nu of every segment's exponential from `segment_samples`,
    (segments, m / 2, 2n, 2n), and twice each one's coefficient tail (entry bound of its error on
    the unit circle); None where a tail is not below SUBSTEP_TOL of the segment's largest
    coefficient. E_s is entire in nu, and as a segment is a fraction of the period its
    coefficients fall off much faster than the monodromy's (1e-11 after 8 terms on the issue-17
    structure, where M needs 16-32). Segment blocks of SEGMENT_BLOCK_BYTES."""
    coef = np.empty((len(E), m // 2) + E.shape[2:], dtype=complex)
    size = np.empty((len(E), m))
    for lo, hi in _blocks(len(E), m * E[0, 0].nbytes):
        with np.errstate(all="ignore"):  # real coefficients (E(conj nu) = conj E(nu)): the inverse of a real signal's spectrum
            block = np.fft.irfft(E[lo:hi], n=m, axis=1)
        size[lo:hi] = np.abs(block).max(axis=(2, 3))
        coef[lo:hi] = block[:, : m // 2]
    tail = size[:, m // 2 :].sum(axis=1)
    if not (np.all(np.isfinite(size)) and np.all(tail <= SUBSTEP_TOL * size.max(axis=1))):
        return None
    return coef, 2.0 * tail


def _blocks(count: int, bytes_each: int):
    """(lo, hi) ranges over `count` items (segments, samples) of `bytes_each`, each range at most
    SEGMENT_BLOCK_BYTES."""
    step = max(1, SEGMENT_BLOCK_BYTES // max(1, bytes_each))
    return [(lo, min(lo + step, count)) for lo in range(0, count, step)]


def circle_monodromies(coef: np.ndarray, error: np.ndarray, N: int):
    """M = E_S ... E_1 at the N-th roots of unity nu = exp(-2 pi i j / N), j = 0 .. N / 2, from the
    `segment_interpolants`, and a Frobenius bound of its error: the error of E_s reaches M through
    the products before and after it, sum over s of 2n x error_s x their Frobenius norms. The
    segments' values at the roots are made in blocks of SEGMENT_BLOCK_BYTES (again for the
    products after, where there is more than one block)."""
    nu = np.exp(-2j * np.pi * np.arange(N // 2 + 1) / N)
    powers = nu[:, None] ** np.arange(coef.shape[1])[None, :]
    blocks = _blocks(len(coef), len(nu) * coef[0, 0].nbytes)

    def values(lo, hi):  # E_s(nu) of segments lo .. hi - 1, (hi - lo, len(nu), 2n, 2n)
        return (powers @ coef[lo:hi].reshape((hi - lo,) + coef.shape[1:2] + (-1,))).reshape((hi - lo, len(nu)) + coef.shape[2:])

    before = np.ones((len(coef), len(nu)))  # |E_(s-1) ... E_1|_F (1 for none)
    after = np.ones((len(coef), len(nu)))  # |E_S ... E_(s+1)|_F
    M = None
    with np.errstate(all="ignore"):  # an overflowing product (depths far past every boundary): an infinite bound
        for lo, hi in blocks:
            En = values(lo, hi)
            for i in range(hi - lo):
                if M is None:
                    M = En[0]
                    continue
                before[lo + i] = np.sqrt(_frobenius2(M))
                M = En[i] @ M
        Q = None
        for lo, hi in blocks[::-1]:
            En = En if len(blocks) == 1 else values(lo, hi)
            for i in range(hi - lo - 1, -1, -1):
                if Q is None:
                    Q = En[i]
                    continue
                after[lo + i] = np.sqrt(_frobenius2(Q))
                Q = Q @ En[i]
        bound = float((coef.shape[-1] * error[:, None] * before * after).sum(axis=0).max())
    return M, bound


def monodromy_polynomial(half: np.ndarray, N: int):
    """nu -> M(a (1 - nu)) as a polynomial from its values at the N-th roots of unity, j = 0 .. N / 2
    (`circle_monodromies`): M is entire in c, so its Taylor coefficients in nu are the Fourier
    coefficients of its values on the unit circle (FFT), and they fall off like s^k / k! (the
    issue-17 structure, 300-12,000 rpm, a/D 0.05-1: below 1e-8 of the largest after 16 terms,
    1e-15 after 32). Returns (the lower N / 2 coefficients (K, 2n, 2n), a Frobenius bound of the
    interpolant's error: 2n x twice the upper half, which is all that aliasing and truncation
    leave out; inf where that half is not below INTERP_TOL of the largest coefficient or not
    finite)."""
    with np.errstate(all="ignore"):  # real coefficients, as in `segment_interpolants`
        coef = np.fft.irfft(half, n=N, axis=0)
    size = np.abs(coef).max(axis=(1, 2))
    tail = size[N // 2 :].sum()
    good = np.all(np.isfinite(size)) and tail <= INTERP_TOL * size.max()
    return coef[: N // 2], (2.0 * half.shape[-1] * tail if good else np.inf)


def unstable_count(char: FloquetCharacteristic, a: float, tau: float, start: int | None = None, max_points: int = 4096, extra=(),
                   polynomial: list | None = None, direct: bool = True):
    """Number of Floquet multipliers outside the unit circle at depth a (argument principle):
    zeros of h(nu) = det(I - nu M(a (1 - nu))) in |nu| < 1 (h entire, h(0) = 1, conjugate
    symmetric). The phase of h is followed over theta in [0, pi] (nu = exp(-i theta)), the grid
    refined wherever consecutive samples differ by more than pi / 4 in phase or by a factor 4
    in modulus, and count = -(phase change) / pi. Returns (count, resolved, theta of the
    smallest |h| / |h|_scale sample). `extra`: thetas sampled besides the uniform grid of
    `start` (VERIFY_POINTS) points, e.g. the known boundary points and the free multipliers'
    angles, where the phase turns fastest.

    h is evaluated on `monodromy_polynomial` (the segments' exponentials at 9-17 points of the
    circle for the whole count instead of a monodromy per sample), each sample's error checked:
    sqrt(2n) |(I - nu M)^-1|_F |dM|_F must stay below INTERP_SAFE (then the nuclear norm of
    (I - nu M)^-1 dM is below ln 2, |h_interpolated / h - 1| < 1, and both have the same zeros
    in the disk: Rouche). M's roots of unity double (INTERP_NODES, products only) until its
    polynomial converges; the segments' roots double (SUBSTEP_NODES) where a sample fails the
    check (M's then from the number its polynomial converged with); after that the count samples
    M directly. `polynomial` (a list): the interpolant the
    count used, (Taylor coefficients in nu, Frobenius bound of its error on |nu| <= 1), is
    appended to it (`ladder_islands` reuses it below a). `direct` False: no direct samples where
    the interpolants fail (then (0, False, NaN): not resolved). Where M has an entry above
    MONODROMY_LIMIT: (0, False, NaN)."""
    th = _count_thetas(char, tau, VERIFY_POINTS if start is None else start, extra)
    m, E, converged_at = SUBSTEP_NODES[0], None, INTERP_NODES[0]
    while m <= SUBSTEP_NODES[1]:
        E = segment_samples(char, a, tau, m, E)
        segments = segment_interpolants(E, m)
        m *= 2
        N = converged_at  # M is the same function: from the roots its polynomial converged with before
        while segments is not None and N <= INTERP_NODES[1]:
            half, product_bound = circle_monodromies(*segments, N)
            if not np.abs(half).max() <= MONODROMY_LIMIT:  # no count in double precision at this depth (nor directly)
                return 0, False, np.nan
            coef, bound = monodromy_polynomial(half, N)
            if not np.isfinite(bound):  # M's polynomial needs more roots (products only)
                N *= 2
                continue
            converged_at = N
            try:
                out = _winding(functools.partial(_interpolated_sample, coef, bound + product_bound), th, max_points)
            except _Unsafe:  # the segments' interpolants are not accurate enough: more roots
                break
            if polynomial is not None:
                polynomial.append((coef, bound + product_bound))
            return out
    if not direct or not _node_monodromy_size(E) <= MONODROMY_LIMIT:  # (the segments' samples give M at their nodes)
        return 0, False, np.nan

    def sample_directly(t):
        with np.errstate(all="ignore"):  # an overflowing M (depths far past every boundary): no count (`_winding`)
            M = char.monodromy(a * (1.0 - np.exp(-1j * t)), np.full(len(t), tau))
            if not np.abs(M).max() <= MONODROMY_LIMIT:
                raise _Unsafe
            sign, logdet = np.linalg.slogdet(np.eye(M.shape[-1]) - np.exp(-1j * t)[:, None, None] * M)
        return np.angle(sign), logdet

    try:
        return _winding(sample_directly, th, max_points)
    except _Unsafe:
        return 0, False, np.nan


def _node_monodromy_size(E: np.ndarray) -> float:
    """The largest |M| entry at the nodes of `segment_samples` E (segments, nodes, 2n, 2n): the
    product of the segments' exponentials at each node (exact samples, no interpolant)."""
    with np.errstate(all="ignore"):
        M = E[0]
        for i in range(1, len(E)):
            M = E[i] @ M
        return float(np.abs(M).max())


def _count_thetas(char, tau: float, points: int, extra=()) -> np.ndarray:
    """The winding count's initial thetas: `points` uniform in [0, pi], the `extra` ones and
    the free multipliers' angles, folded to [0, pi]. The free angles always: lightly damped
    robot modes put several zeros of h within 1e-3 of the circle inside one step of the uniform
    grid, and their half turns of phase add up to a whole one that the step test cannot see
    (seen: count 2, 'resolved', at a twentieth of a depth the independent simulation shows
    stable). Where a free zero's width -Re(lambda) tau is below the uniform step, also its
    angle +- that width: no zero then turns the phase by more than about pi / 4 between two
    samples, so only many zeros in one step could add up to a whole turn unseen (seen without
    them: count 2, 'resolved', at 1e-9 m, where the 16.70 / 16.71 Hz x and y modes and three
    28-30 Hz modes lie within 1.8e-3 of the circle between two samples, 5 teeth at 22,919 rpm)."""
    th = np.linspace(0.0, np.pi, points)
    lam = char.free_eig()[0]
    width = -lam.real * tau  # the zero of h near nu = exp(-lam tau) turns the phase by pi over about +- width
    narrow = width < np.pi / max(points - 1, 1)
    free = lam.imag * tau
    extra = np.concatenate([np.asarray(extra, dtype=float).reshape(-1), free, free[narrow] - width[narrow], free[narrow] + width[narrow]])
    extra = np.mod(extra, 2.0 * np.pi)
    extra = np.where(extra > np.pi, 2.0 * np.pi - extra, extra)
    return np.unique(np.concatenate([th, extra])) if len(extra) else th


def _interpolated_sample(coef: np.ndarray, bound: float, t: np.ndarray, scales=None):
    """(phase, ln |h|) of h(nu) = det(I - nu M) at nu = exp(-i t) on the polynomial
    P(x) = sum coef_k x^k of M(a (1 - x)) (the interpolant of a count at depth a); raises _Unsafe
    where sqrt(2n) |(I - nu M)^-1|_F x bound (M's Frobenius error) reaches INTERP_SAFE
    (`unstable_count`). `scales`: h at each of these fractions of a instead, one lane each
    ((lanes, len(t)) arrays): M(s a (1 - nu)) = P(1 - s (1 - nu)), and 1 - s (1 - nu) lies in the
    disk where P's bound holds for s in [0, 1]."""
    n2 = coef.shape[-1]
    nu = np.exp(-1j * t)
    x = nu if scales is None else (1.0 - np.asarray(scales, dtype=float)[:, None] * (1.0 - nu)).reshape(-1)
    D = _polynomial_matrices(coef, x)
    D *= -np.resize(nu, len(x))[:, None, None]
    D.reshape(len(x), -1)[:, :: n2 + 1] += 1.0  # I - nu P(x), in place
    with np.errstate(all="ignore"):
        sign, logdet = np.linalg.slogdet(D)
        limit = INTERP_SAFE / (np.sqrt(n2) * np.float64(bound))  # inf for an exact interpolant
    if not np.all(_inverse_norms_below(D, logdet, limit)):
        raise _Unsafe
    if scales is None:
        return np.angle(sign), logdet
    return np.angle(sign).reshape(len(scales), -1), logdet.reshape(len(scales), -1)


def _inverse_norms_below(D: np.ndarray, logdet: np.ndarray, limit: float) -> np.ndarray:
    """Whether |D^-1|_F < limit for each matrix of a batch, given ln |det D|: first by the bound
    |D^-1|_F <= sqrt(m) / sigma_min <= sqrt(m) (|D|_F^2 / (m - 1))^((m - 1) / 2) / |det D| (the
    product of the other m - 1 singular values by the AM-GM inequality), which decides almost
    every sample away from a zero of det D without an inverse; the inverse for the rest."""
    m = D.shape[-1]
    with np.errstate(all="ignore"):
        fro2 = _frobenius2(D)
        log_bound = 0.5 * np.log(m) + 0.5 * (m - 1) * np.log(fro2 / (m - 1)) - logdet
        below = log_bound < np.log(limit)
        unsure = np.flatnonzero(~below)
    if len(unsure):
        below[unsure] = _inverse_norms(D[unsure]) < limit
    return below


def _inverse_norms(D: np.ndarray) -> np.ndarray:
    """|D^-1|_F of each matrix of a batch (NaN for a singular one)."""
    with np.errstate(all="ignore"):
        return np.sqrt(_frobenius2(_solve_each(D, np.broadcast_to(np.eye(D.shape[-1]), D.shape))))


def _frobenius2(M: np.ndarray) -> np.ndarray:
    """|M_b|_F^2 of each matrix of a stack (B, m, m): one real dot product per matrix (complex
    entries as (re, im) pairs), without the temporaries of np.linalg.norm."""
    flat = np.ascontiguousarray(M).reshape(len(M), -1)
    flat = flat.view(np.float64) if flat.dtype.kind == "c" else flat
    return np.einsum("bi,bi->b", flat, flat)


def _polynomial_matrices(coef: np.ndarray, x: np.ndarray) -> np.ndarray:
    """sum_k coef_k x^k at every x: (len(x), m, m) from coefficients (K, m, m)."""
    return (x[:, None] ** np.arange(len(coef))[None, :] @ coef.reshape(len(coef), -1)).reshape((len(x),) + coef.shape[1:])


class _Unsafe(Exception):
    """The interpolated characteristic is not accurate enough for a winding count."""


def _winding(sample, th, max_points):
    """The argument-principle count of `unstable_count` from sample(theta) -> (phase, ln |h|).
    A sampler that returns (lanes, thetas) arrays counts several characteristics on one grid,
    refined wherever any lane is rough: then (counts, resolved, theta) are arrays per lane."""
    ph, lm = sample(th) if len(th) else (np.zeros(0), np.zeros(0))
    lanes = np.ndim(ph) == 2
    ph, lm = np.atleast_2d(ph), np.atleast_2d(lm)
    while True:
        d = np.angle(np.exp(1j * np.diff(ph, axis=1)))
        rough_lane = (np.abs(d) > np.pi / 4) | (np.abs(np.diff(lm, axis=1)) > np.log(4.0)) | ~np.isfinite(d)
        # a lane with a non-finite sample (an overflowing M) has no count whatever is added: not refined
        rough = (rough_lane & np.all(np.isfinite(d), axis=1)[:, None]).any(axis=0)
        if not rough.any() or len(th) + rough.sum() > max_points:
            break
        mid = 0.5 * (th[:-1] + th[1:])[rough]
        pm, lmm = (np.atleast_2d(x) for x in sample(mid))
        th = np.concatenate([th, mid])
        order = np.argsort(th)
        th, ph, lm = th[order], np.concatenate([ph, pm], axis=1)[:, order], np.concatenate([lm, lmm], axis=1)[:, order]
    resolved = ~rough_lane.any(axis=1)
    finite = np.all(np.isfinite(d), axis=1)  # an overflowing characteristic: no count
    count = np.where(finite, np.rint(-np.where(np.isfinite(d), d, 0.0).sum(axis=1) / np.pi), 0).astype(int)
    theta = np.where(finite, th[np.argmin(lm, axis=1)], np.nan)
    resolved &= finite
    if lanes:
        return count, resolved, theta
    return int(count[0]), bool(resolved[0]), float(theta[0])


# --- chatter frequency --------------------------------------------------------------------------

#: A boundary point's Floquet vector is the null vector of D = I - nu M(a (1 - nu))
#: (`sdm.null_vectors`: where D's smallest singular value is below sdm.NULL_GAP x the next, a
#: simple zero of det D). Where it is not (`_genuine`): thetas scanned for Newton on det D
#: (`_newton_on_determinant`), and how close (relative) the count's bracket of a crossing below
#: is taken before Newton starts from its top.
RELOCATE_POINTS = 128
RELOCATE_BRACKET = 1e-3
#: A null vector whose singular-value gap (smallest / next) is below NULL_SURE is taken as a
#: zero of det D as it stands; one between NULL_SURE and sdm.NULL_GAP must also be a loss of
#: stability: the count at (1 + CROSSING_STEP) x its depth not 0 (`_crossings_confirmed`). Seen
#: (g025 with its y rows in 2 of 24 orders, modes dying out over 150 e-folds between cuts):
#: gaps of 3e-4 and 1.2e-4 at 1.549 and 1.606 mm, reported converged, where the count is 0 up to
#: 1.65 mm and the boundary is 1.67 mm; the genuine zeros there 1.2e-6. On the issue-17 pose's
#: 300-speed lobes and a 100-pose chunk of the bench sweep (503 answers) the largest gap was
#: 7.7e-6 and one was above 1e-6.
NULL_SURE = 1e-6
CROSSING_STEP = 1e-3
#: Where no zero is confirmed and the count at the point's depth is 0, the boundary lies above:
#: the count is read at UPWARD_RATIO times the depth, up to UPWARD_STEPS times, and the
#: crossing bracketed from the last depth it was 0 (g025 in one of 24 row orders: a point at
#: 1.107 mm where det D is regular, no zero Newton reaches from it; the boundary 1.670 mm).
UPWARD_RATIO = 1.25
UPWARD_STEPS = 12


def floquet_vectors(char: FloquetCharacteristic, a, theta, tau, gap: float = sdm.NULL_GAP):
    """(z, ok) at boundary points (`sdm.null_vectors` of D = I - nu M(a (1 - nu)), nu =
    exp(-i theta)): z (B, 2n) the Floquet solution's state at the period start (M z = z / nu),
    ok where D has a simple null vector (`gap`: `sdm.null_vectors`). Not LAPACK's eigenvectors of M: a blind check's chatter
    frequencies came out at 9085 Hz, beside a mode of k = 6.5e9 N/m, where the independent
    simulation chatters at 7089 Hz (geev's vector had a residual |M z - z / nu| of |z|)."""
    nu = np.exp(-1j * np.asarray(theta, dtype=float))
    with np.errstate(all="ignore"):
        M = char.monodromy(np.asarray(a, dtype=float) * (1.0 - nu), tau)
        return sdm.null_vectors(np.eye(M.shape[-1]) - nu[:, None, None] * M, gap)


def _genuine(char_at, p: CriticalPoint | None, tau: float, base: float, rel_tol: float, verify: bool, frequencies: bool) -> CriticalPoint | None:
    """The point itself where det(I - nu M) has a simple zero there (`floquet_vectors`), the count
    did not show a branch below it and it has an error estimate. Else the lowest of the point
    (where it is such a zero) and the simple zeros Newton on det D reaches from it
    (`_newton_on_determinant`) that, where the job is verified, the count at VERIFY_FRACTION of
    its depth shows to be the lowest; where none is, the zero Newton on det D reaches from the
    top of the count's crossing below (`_count_bracket`, to RELOCATE_BRACKET), or above where the
    count at the point is 0 (UPWARD_RATIO). A zero is a simple one where its null vector's gap
    is decisive, else where the count just above it is not 0 (`_crossings_confirmed`). Its error is the
    move of that zero one level down (not converged where there is none, or where the level
    leaves a soft mode unresolved: `unresolved`), its chatter frequency taken there. Where no
    zero is found: the point as it was where it is a simple zero, else flagged not converged
    and not verified, without a chatter frequency.
    Seen where the modes die out between cuts (110-160 e-folds): Newton on the eigenvalues of
    M, known there to about 1e-3 only, settled at 10.67 mm where det D is regular, and the same
    table with its modes in other orders gave 11.37 mm (an independent simulation grows from
    11.36 mm), or, on another table, 1.57, 3.73 and 4.26 mm (the simulation: 1.671 mm)."""
    if p is None or not (np.isfinite(p.depth_m) and 0.0 < p.depth_m < np.inf):
        return p
    level = _level(p.substeps_per_rad, base)
    ch = char_at(level)
    simple = bool(_crossings_confirmed(ch, np.array([p.depth_m]), np.array([p.theta_rad]), tau)[0])
    if simple and p.verified is not False and np.isfinite(p.rel_error_estimate):
        return p

    def zeros(depth):  # simple zeros of det D Newton reaches from this depth, by depth
        a_r, t_r = _newton_on_determinant(ch, tau, depth, RELOCATE_POINTS, DESCENT_STARTS)
        ok = _crossings_confirmed(ch, a_r, t_r, tau) if len(a_r) else np.zeros(0, bool)
        return list(zip(a_r[ok].tolist(), t_r[ok].tolist()))

    def lowest(a, theta, model=None):  # the count at VERIFY_FRACTION x a shows no branch below (on `ch` or `model`)
        count, resolved, rung, _, _ = _verify_count(ch if model is None else model, VERIFY_FRACTION * a, tau, [theta])
        return bool(count == 0 and resolved and rung is None)

    found = sorted(([(p.depth_m, p.theta_rad)] if simple else []) + zeros(p.depth_m))
    if not verify:
        pick = found[0] if found else None
    else:
        pick = next(((a, t) for a, t in found if lowest(a, t)), None)
    if pick is None and verify:
        def unstable(a):
            count, resolved, _ = unstable_count(ch, a, tau)
            return count > 0 or not resolved
        top = max([p.depth_m] + [a for a, _ in found]) / VERIFY_FRACTION
        lo = 0.0
        for _ in range(UPWARD_STEPS):  # stable there: the boundary is above (the point was no zero)
            if unstable(VERIFY_FRACTION * top):
                break
            lo, top = VERIFY_FRACTION * top, UPWARD_RATIO * top
        if unstable(VERIFY_FRACTION * top):
            _, hi = _count_bracket(unstable, lo, top, RELOCATE_BRACKET)
            pick = next(((a, t) for a, t in zeros(hi) if abs(a - hi) <= 2.0 * RELOCATE_BRACKET * hi and lowest(a, t)), None)
    if pick is None:
        return p if simple else dataclasses.replace(p, chatter_hz=np.nan, family=(), rel_error_estimate=np.inf, converged=False, verified=False if verify else p.verified)
    a, theta = pick
    err = _zero_moved(char_at(level - 1), tau, a, theta) if level > 0 else np.inf
    if not err <= rel_tol and level < _top_level(base):
        # the coarser model is no estimate where it aliases a stiff mode (seen: 0.993 mm at 43-86
        # sub-steps a radian, 1.070 mm at 171-685, 9.4-9.7 kHz modes at 212 rpm): the zero one
        # level up, reported where it is a crossing there (and the lowest, where verified)
        finer = char_at(level + 1)
        a_u, t_u = _newton_on_determinant(finer, tau, a, RELOCATE_POINTS, DESCENT_STARTS)
        near = np.flatnonzero((np.abs(t_u - _fold(theta)) <= 0.1) & (np.abs(a_u - a) <= rel_tol * a))
        near = near[_crossings_confirmed(finer, a_u[near], t_u[near], tau)] if len(near) else near
        if len(near):
            k = near[np.argmin(np.abs(a_u[near] - a))]
            if not verify or lowest(a_u[k], t_u[k], finer):
                err, a, theta, ch, level = abs(a_u[k] - a) / a_u[k], float(a_u[k]), float(t_u[k]), finer, level + 1
    hz, family = floquet_families(ch, [a], [theta], [tau])[0] if frequencies else (np.nan, ())
    return dataclasses.replace(p, depth_m=a, theta_rad=_fold(theta), chatter_hz=hz, family=family, rel_error_estimate=err, substeps_per_rad=base * 2.0**level,
                               converged=bool(err <= rel_tol and not ch.unresolved(a, tau)), verified=True if verify else p.verified)


def _zero_moved(char, tau: float, a: float, theta: float) -> float:
    """Relative move of the zero of det D at (a, theta) in another cut model `char`: to the
    nearest zero Newton on det D reaches from a there with theta within 0.1 (inf: none)."""
    a_d, t_d = _newton_on_determinant(char, tau, a, RELOCATE_POINTS, DESCENT_STARTS)
    moved = [abs(a - x) / a for x, t in zip(a_d, t_d) if abs(t - _fold(theta)) <= 0.1]
    return min(moved) if moved else np.inf


def _crossings_confirmed(char: FloquetCharacteristic, a: np.ndarray, theta: np.ndarray, tau: float) -> np.ndarray:
    """Whether each (a, theta) is a simple zero of det(I - nu M(a (1 - nu))): a null vector with
    a singular-value gap below NULL_SURE, or below sdm.NULL_GAP and the winding count at
    (1 + CROSSING_STEP) a not shown to be 0 (a boundary point brings multipliers out of the
    circle just above it; where that count is 0 and resolved, the point is no crossing: an
    eigenvalue of a graded M known to 1e-3 settled where D is merely near-singular)."""
    a, theta = np.asarray(a, dtype=float), np.asarray(theta, dtype=float)
    taus = np.full(len(a), tau)
    _, loose = floquet_vectors(char, a, theta, taus)
    _, sure = floquet_vectors(char, a, theta, taus, gap=NULL_SURE)
    out = loose & sure
    for k in np.flatnonzero(loose & ~sure):
        count, resolved, _ = unstable_count(char, (1.0 + CROSSING_STEP) * a[k], tau, extra=[theta[k]])
        out[k] = count > 0 or not resolved
    return out


def floquet_families(char: FloquetCharacteristic, a, theta, tau, keep: float = 0.05) -> list:
    """[(dominant Hz, ((Hz, relative amplitude), ...)), ...] of the Floquet solutions with
    multipliers exp(i theta_b) at depths a_b and delays tau_b (batched): Fourier coefficients of
    p(t) = u(t) exp(-i theta t / tau), integrated exactly over every segment (eigenbasis of its
    constant A), harmonics up to twice the highest mode frequency; the solution's start
    `floquet_vectors` (the engine's points are zeros of det(I - nu M): `_genuine`)."""
    a, theta, tau = (np.asarray(x, dtype=float).reshape(-1) for x in np.broadcast_arrays(a, theta, tau))
    if not len(a):
        return []
    out = []
    # harmonics j = -K..K of each element's tooth frequency, K reaching twice the highest mode
    harmonics = (np.ceil(2.0 * char.dyn.wn_rad_s.max() * tau / (2.0 * np.pi)) + 4).astype(int)
    # bounded memory: (segments x batch x harmonics x 2n) complex per chunk (segments in blocks inside)
    per = len(char.fraction) * (2 * harmonics.max() + 1) * 2 * char.n
    chunk = int(max(1, 1_000_000 // per))
    for lo in range(0, len(a), chunk):
        part = slice(lo, lo + chunk)
        out += _families(char, a[part], theta[part], tau[part], int(harmonics[part].max()), keep)
    return out


def _families(char, a, theta, tau, K, keep):
    B = len(a)
    nu = np.exp(-1j * theta)
    c = a * (1.0 - nu)
    z, _ = floquet_vectors(char, a, theta, tau)  # (B, 2n)
    wT = 2.0 * np.pi / tau
    j = np.arange(-K, K + 1)
    omega = theta[:, None] / tau[:, None] + j[None, :] * wT[:, None]  # (B, J)
    s_count, n2 = len(char.fraction), z.shape[1]
    cut_idx = np.flatnonzero(char.cutting)
    lam = np.empty((s_count, B, n2), dtype=complex)
    V = np.empty((s_count, B, n2, n2), dtype=complex)
    if len(cut_idx):
        lam[cut_idx], V[cut_idx] = np.linalg.eig(char.generators(c, segments=cut_idx))
    if len(cut_idx) < s_count:  # free flight: one eigen-decomposition of A0
        lam0, V0 = char.free_eig()
        lam[~char.cutting], V[~char.cutting] = lam0, V0
    dt = char.fraction[:, None] * tau[None, :]  # (s, B)
    t0 = char.start[:, None] * tau[None, :]
    Y = np.empty_like(lam)
    for i in range(s_count):
        Y[i] = y = np.linalg.solve(V[i], z[:, :, None])[:, :, 0]
        z = np.einsum("bij,bj->bi", V[i], np.exp(lam[i] * dt[i][:, None]) * y)
    P = np.einsum("dk,sbkm->sbdm", char.S, V)  # (s, B, 2, 2n)
    # coeff_bjd = sum_s w_sbj sum_m g_sbjm Y_sbm P_sbdm with g = (E_sbm F_sbj - 1) / x_sbjm,
    # E = exp(lam dt), F = exp(-i omega dt), x = lam - i omega: the sum over m is
    # F (C @ (E Y P)) - C @ (Y P) with C = 1 / x, one small product per segment and element
    # instead of g, GY and their temporaries over (s, B, J, 2n) (the same coefficients to
    # rounding; where some |x| dt < 1e-6, g = dt there, the sum as before). In blocks of
    # segments: at 512 sub-steps a radian the (s, B, J, 2n) arrays reach GBs.
    coeff = np.zeros((B, len(j), P.shape[2]), dtype=complex)
    YP = Y[:, :, :, None] * P.transpose(0, 1, 3, 2)  # (s, B, 2n, 2)
    for lo, hi in _blocks(s_count, 2 * B * len(j) * n2 * lam.itemsize):  # x, and g where some x is tiny
        x = lam[lo:hi, :, None, :] - 1j * omega[None, :, :, None]  # (s, B, J, 2n)
        F = np.exp(-1j * omega[None] * dt[lo:hi, :, None])  # (s, B, J)
        weights = np.exp(-1j * omega[None] * t0[lo:hi, :, None])  # (s, B, J)
        tiny = np.abs(x) * dt[lo:hi, :, None, None] < 1e-6
        if tiny.any():
            with np.errstate(all="ignore"):
                g = (np.exp(lam[lo:hi] * dt[lo:hi, :, None])[:, :, None, :] * F[..., None] - 1.0) / x
            g[tiny] = np.broadcast_to(dt[lo:hi, :, None, None], g.shape)[tiny]
            part = np.einsum("sbjm,sbmd->sbjd", g, YP[lo:hi])
        else:
            E = np.exp(lam[lo:hi] * dt[lo:hi, :, None])  # (s, B, 2n)
            np.reciprocal(x, out=x)
            R = x @ np.concatenate([E[..., None] * YP[lo:hi], YP[lo:hi]], axis=3)  # (s, B, J, 4)
            d = P.shape[2]
            part = F[..., None] * R[..., :d] - R[..., d:]
        coeff += np.einsum("sbj,sbjd->bjd", weights, part)
    amplitude = np.sqrt(np.sum(np.abs(coeff) ** 2, axis=2))  # (B, J)
    freq = np.abs(omega) / (2.0 * np.pi)
    out = []
    for b in range(B):
        # members +-w are one frequency of the real motion (every member has its mirror at
        # theta = 0 or pi: period doubling listed '10 (100%), 10 (100%) Hz'): their powers added
        _, inverse, count = np.unique(np.round(freq[b] * tau[b] * 1e6), return_inverse=True, return_counts=True)  # within 1e-6 tooth frequencies
        inverse = inverse.ravel()
        f_b = np.bincount(inverse, weights=freq[b]) / count
        a_b = np.sqrt(np.bincount(inverse, weights=amplitude[b] ** 2))
        order = np.argsort(-a_b)
        top_amp = a_b[order[0]]
        family = tuple((float(f_b[k]), float(a_b[k] / top_amp)) for k in order if a_b[k] >= keep * top_amp)
        out.append((float(f_b[order[0]]), family))
    return out


# --- public API ---------------------------------------------------------------------------------


def critical_depth(dyn: ToolTipDynamics, cut: Cut, rpm: float, rel_tol: float = 0.02, substeps_per_rad: float | None = None, verify: bool = True) -> CriticalPoint:
    """Critical axial depth (m) and dominant chatter frequency at one spindle speed, resolution
    chosen automatically (`substeps_per_rad` overrides the coarsest level); `verify` runs the
    winding count at VERIFY_FRACTION x the depth (and repairs a missed lower branch)."""
    return _solve([dyn], cut, np.array([float(rpm)]), rel_tol, substeps_per_rad, verify)[0][0]


#: Continuation (`critical_depths(..., continuation=True)`): along a path through the
#: structures of a group (`modal_path`), every CONTINUATION_STRIDE-th (an anchor) starts from
#: the anchor before it (the first from its seeds); then, halving the stride, the midpoints of
#: what is solved, each batch from the nearest solved either side (same speed), so half the
#: structures still start from their immediate neighbours; every one verified by the winding
#: count. Measured (250 sweep poses, 7500-7749, bare and with the absorber, two runs side by
#: side): 8 against 2 (every other one an anchor, the rest in one batch) 2.6-3.7 % less CPU,
#: the same answers to 2.2e-6 (the anchors' single-structure solves cost a third more each than
#: batched ones). Before the halving, strides 16 / 8 / 3 / 2 from anchors only cost 2639 / 2220 /
#: 2046 / 1809 exponential units (fewer jobs solved again from the seeds at 2).
CONTINUATION_STRIDE = 8
#: A neighbour's boundary points up to this many times its lowest are continued (Newton on the
#: whole structure, from the neighbour's G_c); a branch further up that came down past the
#: lowest would be caught by the count (and the job solved from the seeds).
START_SPAN = 1.5
#: ... and of those the lowest MAX_STARTS (four chunks of 250 sweep poses, bare and with the
#: absorber: the same answers to 1e-8 as all of them, 3-8 % less time; 2 moved one answer by
#: 0.36 %, 1 another by 1.2 %, both passing the count at VERIFY_FRACTION).
MAX_STARTS = 3


def critical_depths(structures, cut: Cut, rpm, rel_tol: float = 0.02, substeps_per_rad: float | None = None, verify: bool = False,
                    frequencies: bool = True, continuation: bool = False) -> list:
    """`critical_depth` for many structures (e.g. one per pose), each at its own speed (`rpm`
    scalar or one per structure). Structures with the same number of modes share the batched
    Newton iterations. `frequencies` False skips the chatter frequencies (NaN).

    `continuation`: structures with similar modes (the poses of a sweep, samples of one pose's
    uncertainty) start from each other's boundary points instead of the seeds: the same
    answers (each verified by the winding count; a count that is not 0 sends it back to the
    seeds) at about half the cost."""
    structures = list(structures)
    rpm = np.broadcast_to(np.asarray(rpm, dtype=float), (len(structures),))
    out = [None] * len(structures)
    groups: dict = {}
    for i, s in enumerate(structures):
        groups.setdefault(s.n_modes, []).append(i)
    for idx in groups.values():
        idx = np.array(idx)
        if continuation:
            idx = idx[modal_path([structures[i] for i in idx])]
        if not continuation:
            for k, r in enumerate(_solve([structures[i] for i in idx], cut, rpm[idx], rel_tol, substeps_per_rad, verify, pairs=True, frequencies=frequencies)):
                out[idx[k]] = r[0]
            continue
        anchors = np.unique(np.concatenate([np.arange(0, len(idx), CONTINUATION_STRIDE), [len(idx) - 1]]))
        for q, k in enumerate(anchors):  # each anchor from the one before (the first from its seeds)
            prev = out[idx[anchors[q - 1]]] if q else None
            hint = [list(prev.starts)] if prev is not None and rpm[idx[anchors[q - 1]]] == rpm[idx[k]] else None
            out[idx[k]] = _solve([structures[idx[k]]], cut, rpm[idx[[k]]], rel_tol, substeps_per_rad, verify, pairs=True, frequencies=frequencies, hints=hint)[0][0]
        solved = np.zeros(len(idx), bool)
        solved[anchors] = True
        step = CONTINUATION_STRIDE // 2
        while step >= 1:  # the midpoints of what is solved, batched, each from the nearest solved either side (a branch may take over between them)
            rest = np.flatnonzero(~solved & (np.arange(len(idx)) % step == 0))
            if len(rest):
                done = np.flatnonzero(solved)
                after = np.searchsorted(done, rest)
                hints = [_union_starts([out[idx[k]].starts for k in done[[q - 1, q]] if rpm[idx[k]] == rpm[idx[i]]]) for q, i in zip(after, rest)]
                for k, r in zip(rest, _solve([structures[i] for i in idx[rest]], cut, rpm[idx[rest]], rel_tol, substeps_per_rad, verify, pairs=True,
                                             hints=hints, frequencies=frequencies)):
                    out[idx[k]] = r[0]
                solved[rest] = True
            step //= 2
    return out


def _union_starts(lists) -> list | None:
    """The starts of several neighbours, one of each boundary point (depth within 2 %, theta
    within 0.02 rad), or None where there are none."""
    out = []
    for starts in lists:
        for a, th, g, v in starts:
            if not any(abs(a - b) <= 0.02 * b and abs(th - u) <= 0.02 for b, u, _, _ in out):
                out.append((a, th, g, v))
    return out or None


def modal_path(structures) -> np.ndarray:
    """An order of structures with equal mode counts in which neighbours have similar modes:
    greedy nearest neighbour from the first, distance between (ln fn, ln zeta, tool-tip shapes
    relative to the largest) vectors."""
    if len(structures) < 3:
        return np.arange(len(structures))
    shapes = np.array([d.shapes.ravel() for d in structures])
    features = np.hstack([np.log([d.fn_hz for d in structures]), np.log([d.zeta for d in structures]), shapes / max(np.abs(shapes).max(), 1e-300)])
    left = np.ones(len(structures), bool)
    order = [0]
    left[0] = False
    for _ in range(len(structures) - 1):
        d = np.abs(features - features[order[-1]]).sum(axis=1)
        d[~left] = np.inf
        order.append(int(np.argmin(d)))
        left[order[-1]] = False
    return np.array(order)


def lobes(dyn: ToolTipDynamics, cut: Cut, rpm, rel_tol: float = 0.02, substeps_per_rad: float | None = None, verify: bool = False) -> Lobes:
    """`critical_depth` at many speeds, Newton iterations batched over speeds. (Continuation from
    neighbouring speeds does not pay: with kHz spindle modes at low speed consecutive speeds of a
    lobe diagram lie on different lobes, lobe numbers of 80 and more.)"""
    rpm = np.atleast_1d(np.asarray(rpm, dtype=float))
    points = _solve([dyn], cut, rpm, rel_tol, substeps_per_rad, verify, branch_families=False)[0]
    return Lobes(
        rpm=rpm,
        depth_m=np.array([p.depth_m for p in points]),
        chatter_hz=np.array([p.chatter_hz for p in points]),
        theta_rad=np.array([p.theta_rad for p in points]),
        rel_error_estimate=np.array([p.rel_error_estimate for p in points]),
        converged=np.array([p.converged for p in points]),
        verified=np.array([p.verified is not False for p in points]),
    )


class _Batch:
    """Several FloquetCharacteristics (same mode count) evaluated as one: element e of a batch
    belongs to structure owner[e]."""

    def __init__(self, chars, owner):
        self.chars, self.owner = chars, np.asarray(owner)

    def monodromy(self, c, tau):
        c = np.asarray(c, dtype=complex).reshape(-1)
        tau = np.broadcast_to(np.asarray(tau, dtype=float).reshape(-1), c.shape)
        if len(self.chars) == 1:
            return self.chars[0].monodromy(c, tau)
        out = None
        for s in np.unique(self.owner):
            m = self.owner == s
            Ms = self.chars[s].monodromy(c[m], tau[m])
            if out is None:
                out = np.empty((len(c),) + Ms.shape[1:], dtype=complex)
            out[m] = Ms
        return out

    def take(self, idx):
        return _Batch(self.chars, self.owner[idx])


def _solve(dyns, cut, rpm, rel_tol, substeps_per_rad, verify, pairs=False, branch_families=True, hints=None, frequencies=True, lost_before: float | None = None):
    """pairs=False: every structure at every speed; pairs=True: structure i at rpm[i] only.
    Returns, per structure, the list of CriticalPoints.

    `hints` (continuation; None or one entry per job, None or [(depth m, theta, mode), ...]): the
    boundary points of a neighbouring structure (a nearby pose) at the same speed. A hinted job
    starts Newton from them (on the band of the mode, as a zeroth-order seed of that mode would)
    instead of the zeroth-order, flip and band seeds; it is always
    verified by the winding count, and a job whose count is not 0 is solved again from the seeds.
    `frequencies` False: no chatter frequencies (NaN; the families are a tenth of a solve).
    `lost_before`: the depth of the point a job solved again here had at the level below, which
    Newton could not follow to this resolution (`_finish_all`); where its point here is lost again
    within rel_tol / 2 of that depth (a branch that stays put but that Newton cannot take from one
    level to the next), the job goes on at the first level that resolves its stiff modes
    (`_unaliased_level`) instead of the next."""
    rpm = np.asarray(rpm, dtype=float).reshape(-1)
    if np.any(~np.isfinite(rpm) | (rpm <= 0)):
        raise InputError("spindle speeds > 0 rpm", got=rpm[~np.isfinite(rpm) | (rpm <= 0)][0], column="rpm")
    base = coarsest_substeps(cut) if substeps_per_rad is None else float(substeps_per_rad)
    keeps = [relevant_modes(d) for d in dyns]
    smalls = [_subset(d, k) for d, k in zip(dyns, keeps)]
    cache: dict = {}
    seed_level = -SEED_LEVELS_BELOW

    def char(s, level, full=False):
        key = (s, level, full or len(keeps[s]) == dyns[s].n_modes)
        if key not in cache:
            cache[key] = FloquetCharacteristic(dyns[s] if key[2] else smalls[s], cut, base * 2.0**level)
        return cache[key]

    # (structure, speed) jobs
    if pairs:
        jobs = [(s, s) for s in range(len(dyns))]
    else:
        jobs = [(s, e) for s in range(len(dyns)) for e in range(len(rpm))]
    tau_all = np.asarray(cut.tooth_period_s(rpm), dtype=float).reshape(-1)
    # 1. zeroth-order seeds: per mode band the lowest few, overall the lowest MAX_SEEDS
    seed_job, seed_a, seed_t, seed_m, seed_g, seed_v = [], [], [], [], [], []
    hill_idx: list = []  # the seeds from Hill's boundary points
    hinted = np.zeros(len(jobs), bool)
    zoa = {}  # job -> its zeroth-order seeds, batched over each structure's delays
    for s in range(len(dyns)):
        mine = [j for j in range(len(jobs)) if jobs[j][0] == s and not (hints is not None and hints[j])]
        if mine:
            zoa.update(zip(mine, zoa_seeds_batch(smalls[s], cut, tau_all[[jobs[j][1] for j in mine]], char(s, 0))))
    for j, (s, e) in enumerate(jobs):
        if hints is not None and hints[j]:
            hinted[j] = True
            lowest = min(h[0] for h in hints[j])
            for a_, th, g_, v_ in sorted(hints[j], key=lambda h: h[0])[:MAX_STARTS]:  # on the whole structure, from the neighbour's G_c and eigenvector
                if a_ <= START_SPAN * lowest:
                    seed_job.append(j)
                    seed_a.append(float(a_))
                    seed_t.append(float(th))
                    seed_m.append(-1)
                    seed_g.append(complex(g_))
                    seed_v.append(v_ if v_ is not None and len(v_) == 2 * smalls[s].n_modes else None)
            continue
        d, t, mode = zoa[j]
        pick = set(np.argsort(d)[:MAX_SEEDS].tolist())
        for m in np.unique(mode):
            idx = np.flatnonzero(mode == m)
            pick |= set(idx[np.argsort(d[idx])[:SEEDS_PER_MODE]].tolist())
        pick = sorted(pick)
        seed_job += [j] * len(pick)
        seed_a += list(d[pick])
        seed_t += list(t[pick])
        seed_m += list(mode[pick])
        seed_g += [np.nan] * len(pick)
        seed_v += [None] * len(pick)
        if HILL_SEEDS and dyns[s].coupling is not None:  # Hill's boundary points (whole structure)
            a_h, t_h = hill.hill_seeds(char(s, 0).frf, char(s, 0).free_eig()[0], cut, tau_all[e])
            a_h, t_h = a_h[:HILL_SEEDS], t_h[:HILL_SEEDS]
            hill_idx += range(len(seed_job), len(seed_job) + len(a_h))
            seed_job += [j] * len(a_h)
            seed_a += list(a_h)
            seed_t += list(t_h)
            seed_m += [-1] * len(a_h)
            seed_g += [np.nan] * len(a_h)
            seed_v += [None] * len(a_h)
    seed_scans: dict = {}  # job -> its flip-seed scan (on char(s, seed_level)), reused by the island check
    if FLIP_POINTS:  # period-doubling seeds, which the zeroth order never gives (mode -1: the whole structure)
        lowest = {}
        for j, a_ in zip(seed_job, seed_a):
            if not hinted[j]:
                lowest[j] = min(lowest.get(j, np.inf), a_)
        for s in range(len(dyns)):
            mine = [j for j in range(len(jobs)) if jobs[j][0] == s and np.isfinite(lowest.get(j, np.inf))]
            if mine:
                found, scans = flip_seeds(char(s, seed_level), np.array([lowest[j] for j in mine]), tau_all[[jobs[j][1] for j in mine]], mine)
                seed_scans.update(scans)
                for j, a_ in found:
                    seed_job.append(j)
                    seed_a.append(a_)
                    seed_t.append(np.pi)
                    seed_m.append(-1)
                    seed_g.append(np.nan)
                    seed_v.append(None)
    seed_job, seed_a, seed_t, seed_m, seed_g = np.array(seed_job, int), np.array(seed_a), np.array(seed_t), np.array(seed_m, int), np.array(seed_g, complex)
    owners = np.array([jobs[j][0] for j in seed_job], int)
    seed_tau = tau_all[[jobs[j][1] for j in seed_job]] if len(seed_job) else np.zeros(0)
    # the characteristic each seed is refined on: its band's projection, or the whole structure
    search, key_of = [], {}
    seed_key = np.zeros(len(seed_a), int)
    seed_mode = seed_m.copy()
    bands = {}
    for i in range(len(seed_a)):
        s_ = owners[i]
        if PROJECT_SEEDS and seed_m[i] >= 0:
            if s_ not in bands:
                bands[s_] = mode_bands(char(s_, seed_level))
                if bands[s_] is not None:  # the pair whose eigenvector lives most on each mode
                    c_ = char(s_, seed_level)
                    V = c_.free_eig()[1]
                    w2 = np.abs(V) ** 2
                    w2 = w2 / w2.sum(axis=0, keepdims=True)
                    on_mode = w2[: c_.n] + w2[c_.n :]  # (mode, eigenvector)
                    first = np.array([p[0] for p in bands[s_][0]])
                    bands[s_] = bands[s_] + (np.argmax(on_mode[:, first], axis=1),)
            info = bands[s_]
        else:
            info = None
        if info is None:
            key = (s_, -1)
        else:
            pairs_, freq, band, members = info[:4]
            k = int(info[4][seed_m[i]])
            key = (s_, int(band[k]))
            seed_mode[i] = int(np.flatnonzero(members[band[k]] == k)[0]) if k in members[band[k]] else -1
        if key not in key_of:
            key_of[key] = len(search)
            if key[1] < 0:
                search.append(char(s_, seed_level))
            else:
                pairs_, freq, band, members = info[:4]
                search.append(ProjectedCharacteristic(char(s_, seed_level), [pairs_[q] for q in members[key[1]]]))
        seed_key[i] = key_of[key]
    size = np.array([len(search[k].lam) if isinstance(search[k], ProjectedCharacteristic) else 2 * search[k].n for k in seed_key], int)
    a0 = np.full(len(seed_a), np.nan)
    t0 = np.full(len(seed_a), np.nan)
    ok0 = np.zeros(len(seed_a), bool)
    v0 = [None] * len(seed_a)
    g0 = np.full(len(seed_a), np.nan, complex)
    for sz in np.unique(size):
        sel = np.flatnonzero(size == sz)
        batch = _Batch(search, seed_key[sel])
        v_in = None if all(seed_v[i] is None for i in sel) else np.array([np.full(sz, np.nan, complex) if seed_v[i] is None else seed_v[i] for i in sel])
        a_, t_, ok_, gc_, vec_ = _newton(batch, seed_a[sel], seed_t[sel], seed_tau[sel], tol=REFINE_TOL, Gc=seed_g[sel], mode=seed_mode[sel], vec=v_in, group=seed_job[sel])
        a0[sel], t0[sel], ok0[sel], g0[sel] = a_, t_, ok_, gc_
        for q, i in enumerate(sel):
            if ok_[q]:
                ch = search[seed_key[i]]
                v0[i] = ch.lift(vec_[q : q + 1])[0] if isinstance(ch, ProjectedCharacteristic) else vec_[q]
                if t_[q] > np.pi:
                    v0[i] = np.conj(v0[i])
    # a band seed that did not converge, below its job's lowest point: once more on the whole
    # structure (the band's projection can lose a branch that couples bands; seen: a Hopf island
    # of an absorber pose, 4.0 mm under a 6.0 mm answer, lost at 32 sub-steps a radian)
    lowest_ok = {}
    for i in np.flatnonzero(ok0):
        lowest_ok[seed_job[i]] = min(lowest_ok.get(seed_job[i], np.inf), a0[i])
    lost = np.array([i for i in range(len(seed_a)) if not ok0[i] and isinstance(search[seed_key[i]], ProjectedCharacteristic)
                     and seed_a[i] < lowest_ok.get(seed_job[i], np.inf)], int)
    size = np.array([char(owners[i], seed_level).n for i in lost], int)
    for sz in np.unique(size):
        sel = lost[size == sz]
        batch = _Batch([char(s_, seed_level) if s_ in set(owners[sel].tolist()) else None for s_ in range(int(owners.max()) + 1)], owners[sel])
        a_, t_, ok_, gc_, vec_ = _newton(batch, seed_a[sel], seed_t[sel], seed_tau[sel], tol=REFINE_TOL, mode=seed_m[sel], group=seed_job[sel])
        for q, i in enumerate(sel):
            if ok_[q]:
                a0[i], t0[i], ok0[i], g0[i] = a_[q], t_[q], True, gc_[q]
                v0[i] = np.conj(vec_[q]) if t_[q] > np.pi else vec_[q]
                seed_key[i] = key_of.setdefault((owners[i], -1), len(search))
                if seed_key[i] == len(search):
                    search.append(char(owners[i], seed_level))

    cands, start_of = [], []
    for j in range(len(jobs)):
        m = np.flatnonzero((seed_job == j) & ok0)
        keep = _dedupe(a0[m], t0[m], index=True)
        m = m[keep]
        cands.append((a0[m], np.where(t0[m] > np.pi, 2 * np.pi - t0[m], t0[m]), [v0[i] for i in m], np.where(t0[m] > np.pi, np.conj(g0[m]), g0[m]),
                      np.array([isinstance(search[seed_key[i]], ProjectedCharacteristic) for i in m], bool)))
        start_of.append(tuple(zip(cands[-1][0].tolist(), cands[-1][1].tolist(), cands[-1][3].tolist(), cands[-1][2])))
    points, missed, ladders, lost = _finish_all(char, dyns, keeps, jobs, cut, rpm, tau_all, cands, base, rel_tol, verify, seed_level, branch_families, hinted, frequencies)
    # a neighbour starts from every point the search converged on and from the reported branches
    # (a repaired one included: the seeds of a neighbour would miss it too)
    points = [p if p is None else dataclasses.replace(p, starts=st + tuple((a, th, np.nan, None) for a, _, th in p.branches if not any(abs(a - b) <= 1e-3 * a for b, *_ in st)))
              for p, st in zip(points, start_of)]

    def solve_again(j, substeps, hints=None, check=True, lost=None):  # job j from the seeds (and `hints`) at `substeps`
        return _solve([dyns[jobs[j][0]]], cut, rpm[[jobs[j][1]]], rel_tol, substeps, check, True, branch_families, hints=hints, frequencies=frequencies,
                      lost_before=lost)[0][0]

    def solve_lower(j, substeps, start=None):
        """Job j solved again at `substeps` (from the seeds; from `start` = (depth, theta) and
        its point where given): a converged boundary point bounds the critical depth from above,
        so the redo replaces the point only where lower, else the point is not verified."""
        p = points[j]
        hints = None if start is None else [[(float(start[0]), _fold(start[1]), np.nan, None), (p.depth_m, p.theta_rad, np.nan, None)]]
        redo = solve_again(j, substeps, hints=hints)
        points[j] = redo if redo.depth_m < p.depth_m else dataclasses.replace(p, verified=False)

    for j in np.flatnonzero(lost):  # no point followed to the finer cut model: from the seeds there
        if points[j] is not None:
            lv = _level(points[j].substeps_per_rad, base)
            if lost_before is not None and abs(points[j].depth_m - lost_before) <= 0.5 * rel_tol * points[j].depth_m:
                # lost again, in place: the cut models in between alias a stiff mode. A blind check's
                # c097 (2 teeth at 239 rpm, an 8.15 kHz mode 9 times as stiff as the cut, 1000 of its
                # periods a tooth period) lost its point, at 0.4421, 0.4399, 0.4396 ... mm, one level
                # up from each of 19, 38, ... 305 sub-steps a radian and was solved from the seeds at
                # each next one (70 s); no level up to the finest, 610, resolves that mode, and the
                # answer comes from there (0.4394 mm, the same in 39 s). Where the lost points move
                # (1.94 / 2.17 mm at 32 / 64 on another) the levels go on one by one.
                lv = _unaliased_level(char(jobs[j][0], lv, True), points[j].depth_m, tau_all[jobs[j][1]], lv, lv, _top_level(base))
            redo = solve_again(j, base * 2.0**lv, check=bool(verify or hinted[j]), lost=points[j].depth_m)
            if np.isfinite(redo.depth_m) and redo.depth_m > 0:  # the lost point bounds nothing at that resolution
                points[j] = redo
                missed[j] = False
                ladders.pop(j, None)
    for j in np.flatnonzero(missed):  # a lower branch at the answer's resolution: from the seeds there
        solve_lower(j, points[j].substeps_per_rad)
        ladders.pop(j, None)
    # period-doubling islands below the answer, at the answer's own resolution (scanned there
    # where the coarse cut model shows one or comes near): where one is, the job is solved
    # again at that resolution, from the seeds and from the island's lowest scanned point
    scan: dict = {}
    for j, (s, e) in enumerate(jobs):
        p = points[j]
        if p is not None and (verify or hinted[j]) and np.isfinite(p.depth_m) and p.depth_m > 0:
            scan.setdefault(s, []).append(j)
    for s, group in scan.items():
        group = np.array(group)
        levels = np.array([_level(points[j].substeps_per_rad, base) for j in group])
        depths, taus = np.array([points[j].depth_m for j in group]), tau_all[[jobs[j][1] for j in group]]
        hit, near, inside, spans = _coarse_islands(functools.partial(char, s, full=True), char(s, seed_level), seed_scans if seed_level == 0 else {}, group, depths, taus,
                                                   levels, [ladders.get(j) for j in group])
        seen = np.array([ladders[j][0] if j in ladders else 0 for j in group])  # the level the check looked at
        for level in np.unique(levels[(hit | near) & (levels > seen)]):
            sub = np.flatnonzero((hit | near) & (levels == level) & (levels > seen))
            fine = char(s, int(level), True)
            whole = np.array([q for q in sub if spans[q] is None], int)
            if len(whole):
                hit[whole], _, inside[whole] = flip_islands(fine, depths[whole], taus[whole], starts=True)
            for q in (q for q in sub if spans[q] is not None):  # densely where the coarse ladder came near -1
                hit[q], inside[q] = False, np.nan
                for lo, hi in spans[q]:
                    hi = min(hi, VERIFY_FRACTION * depths[q])
                    if lo < hi:
                        hit[q], inside[q] = dense_flip(fine, lo, hi, taus[q])
                        if hit[q]:
                            break
        at = levels.copy()  # the level the island was found at
        for q in np.flatnonzero(near & ~hit):  # a multiplier near -1 that a finer cut model can take past it
            found = flip_ahead(functools.partial(char, s, full=True), int(levels[q]), _top_level(base),
                               spans[q] if spans[q] is not None else [(FLIP_RANGE[0] * depths[q], depths[q])], depths[q], taus[q], ladders.get(group[q]))
            if found is not None:
                hit[q], inside[q], at[q] = True, found[0], found[1]
        for q, j in zip(np.flatnonzero(hit), group[hit]):
            # at the finest level too where the island's lower end is known (the redo estimates its
            # error one level down), unless this is such a redo meeting the island again (hinted)
            if at[q] < _top_level(base) or (np.isfinite(inside[q]) and hints is None):
                solve_lower(j, base * 2.0 ** at[q], (inside[q], np.pi) if np.isfinite(inside[q]) else None)
            else:  # an island no finer model can be asked about: the answer is known to be too high
                points[j] = dataclasses.replace(points[j], verified=False)
    # Hill's boundary points that reached none on the coarse cut model, below an answer at a finer
    # resolution: once more there (an island of complex multipliers can exist only with the finer
    # model, seen: from 5.96 mm under a 9.88 mm answer at 16 sub-steps a radian, none at 4); a
    # boundary point reached below the answer sends the job back to that resolution from it
    late: dict = {}
    for i in hill_idx:
        p = points[seed_job[i]]
        if not ok0[i] and p is not None and (verify or hinted[seed_job[i]]) and p.substeps_per_rad > base and seed_a[i] < p.depth_m:
            late.setdefault((jobs[seed_job[i]][0], _level(p.substeps_per_rad, base)), []).append(i)
    for (s, level), idx in late.items():
        idx = np.array(idx, int)
        a_, t_, ok_, _, _ = _newton(char(s, level, True), seed_a[idx], seed_t[idx], seed_tau[idx], tol=REFINE_TOL)
        for j in np.unique(seed_job[idx]):
            p = points[j]
            below = (seed_job[idx] == j) & ok_ & (a_ < VERIFY_FRACTION * p.depth_m)
            if below.any():
                k = np.flatnonzero(below)[np.argmin(a_[below])]
                solve_lower(j, p.substeps_per_rad, (a_[k], t_[k]))
    again = [j for j in range(len(jobs)) if points[j] is None]
    if again:  # hinted jobs the count did not verify: from the seeds
        redo = _solve([dyns[jobs[j][0]] for j in again], cut, rpm[[jobs[j][1] for j in again]], rel_tol, substeps_per_rad, verify, True, branch_families, frequencies=frequencies)
        for j, r in zip(again, redo):
            points[j] = r[0]
    for j, (s, e) in enumerate(jobs):
        if j not in again:
            points[j] = _genuine(functools.partial(char, s, full=True), points[j], tau_all[e], base, rel_tol, bool(verify or hinted[j]), frequencies)
    results = [[None] * (len(rpm) if not pairs else 1) for _ in dyns]
    for j, (s, e) in enumerate(jobs):
        results[s][0 if pairs else e] = points[j]
    return results


def _unaliased_level(char, a: float, tau: float, level: int, start: int, top: int) -> int:
    """The first level from `start` below `top` at which no mode at most ALIAS_MODE times as stiff
    as the cut at depth a has more than ALIAS_PERIODS of its periods in a sub-step (`char`, the
    cut model at `level`: `unresolved(look=True)`), else `top`: where the look-ahead estimates a
    converged job's error, and where a job lost twice in place is solved again (`_solve`)."""
    return next((lv for lv in range(start, top) if not char.unresolved(a, tau, look=True, finer=lv - level)), top)


def _verify_count(char, a: float, tau: float, thetas, above: float | None = None):
    """(count, resolved, rung, ladder, count_above) of the verification at depth a on `char`'s cut
    model: the winding count (`unstable_count`, the boundary points' thetas sampled), the Hopf
    rung below where it is 0 (`hopf_rung`; None: none counts), its interpolant for the flip
    ladder ((depth, coefficients, bound) for `ladder_islands`; None where the count sampled M
    directly) and the count at the depth `above` (> a; None where not asked or not resolved).
    With `above` the interpolant is made there and the count at a read on it (every depth below
    is on it: no more exponentials); where the interpolants fail there, no count above and the
    count at a as without it."""
    poly: list = []
    count_above = None
    if above is not None:
        n_above, resolved_above, _ = unstable_count(char, above, tau, extra=thetas, polynomial=poly, direct=False)
        if poly:
            count_above = n_above if resolved_above else None
            try:
                th = _count_thetas(char, tau, VERIFY_POINTS, thetas)
                counts, resolved_at, _ = _winding(functools.partial(_interpolated_sample, *poly[0], scales=(a / above,)), th, 4096)
                count, resolved, a0 = int(counts[0]), bool(resolved_at[0]), above
            except _Unsafe:  # not accurate enough down there: the count at a itself
                poly = []
    if not poly:
        count, resolved, _ = unstable_count(char, a, tau, extra=thetas, polynomial=poly)
        a0 = a
    # where the count sampled M directly (no interpolant), the rungs do too
    rung = hopf_rung(char, a0, *(poly[0] if poly else (None, np.inf)), tau, thetas, base=a) if count == 0 and resolved else None
    return count, resolved, rung, ((a0,) + poly[0] if poly else None), count_above


def _crossings(theta) -> int:
    """Zeros of h that boundary points at these thetas (folded to [0, pi]) bring into the unit
    disk just above their depths: 1 at theta = pi (a real multiplier through -1), else 2 (a
    conjugate pair)."""
    theta = np.asarray(theta, dtype=float).reshape(-1)
    return int(np.sum(np.where(np.abs(theta - np.pi) < 1e-6, 1, 2)))


def _fold(theta: float) -> float:
    """theta folded to [0, pi] (a boundary point and its conjugate are one)."""
    theta = float(np.mod(theta, 2.0 * np.pi))
    return min(theta, 2.0 * np.pi - theta)


def _level(substeps_per_rad: float, base: float) -> int:
    """The refinement level of a resolution: substeps_per_rad = base x 2^level."""
    return int(round(np.log2(substeps_per_rad / base)))


def _top_level(base: float) -> int:
    """The finest refinement level: the first at or above MAX_SUBSTEPS_PER_RAD."""
    return int(np.ceil(np.log2(MAX_SUBSTEPS_PER_RAD / base) - 1e-9))


def _batched_step(char, keeps, level, a, t, tau, owner, Gc, vec, full=False, step=None):
    """`_step_level` (or `step`, the same signature) for boundary points of several structures
    (owner[i]), one batch per matrix size."""
    step = _step_level if step is None else step
    a_new, t_new = a.copy(), t.copy()
    ok = np.zeros(len(a), bool)
    Gc_new = np.zeros(len(a), complex)
    vec_new = [None] * len(a)
    sizes = np.array([len(keeps[o]) if not full else -1 for o in owner])
    for size in np.unique(sizes):
        sel = np.flatnonzero(sizes == size)
        n_struct = int(owner.max()) + 1

        def ch(lv, sel=sel):
            return _Batch([char(s, lv, full) if s in set(owner[sel].tolist()) else None for s in range(n_struct)], owner[sel])

        v_in, g_in = None, None
        if vec is not None and any(vec[i] is not None for i in sel):  # a point without one (a repair, a branch found above) picks its own (NaN)
            width = next(len(vec[i]) for i in sel if vec[i] is not None)
            v_in = np.array([np.full(width, np.nan, complex) if vec[i] is None else vec[i] for i in sel])
            g_in = np.where([vec[i] is None for i in sel], np.nan, Gc[sel])
        an, tn, okn, gn, vn = step(ch, level, a[sel], t[sel], tau[sel], g_in, v_in)
        a_new[sel], t_new[sel], ok[sel], Gc_new[sel] = an, tn, okn, gn
        for k, i in enumerate(sel):
            vec_new[i] = vn[k]
    return a_new, t_new, ok, Gc_new, vec_new


def _finish_all(char, dyns, keeps, jobs, cut, rpm, tau_all, cands, base, rel_tol, verify, seed_level, branch_families=True, hinted=None, frequencies=True):
    """From the converged seed-search points of every job: band candidates re-solved on the whole
    structure, near ties (NEAR_TIE) brought to level 0 and one level up, verified there (winding
    count and Hopf rungs, job by job; `_verify_count`, `_repair`), refined in resolution until
    the error estimate is below rel_tol / 2, put back on the full structure (irrelevant modes),
    chatter frequency. Newton steps batched over jobs. A `hinted` job is always verified; where
    its count is not 0 its point is None (the caller solves it again from the seeds). Also
    returns the jobs whose count at the answer's own (finer) resolution is not 0 and each
    verified job's count interpolant ({job: (level, depth, coefficients, bound)}) and the jobs
    no point of which Newton could follow to a finer level (the caller solves them again from the
    seeds at that level)."""
    hinted = np.zeros(len(jobs), bool) if hinted is None else hinted
    retry = np.zeros(len(jobs), bool)
    J = len(jobs)
    repaired = np.zeros(J, bool)
    verified = [None] * J
    ladders: dict = {}  # job -> (level, depth, its verification count's interpolant): `ladder_islands`
    # near ties at the seed level (band searches: twice as wide), flattened
    ej, ea, et, ev, eg, ep = [], [], [], [], [], []
    for j, (ca, ct, cv, cg, cp) in enumerate(cands):
        if len(ca):
            near = np.flatnonzero(ca <= ca[0] * (1.0 + (2.0 if cp.any() else 1.0) * NEAR_TIE))
            ej += [j] * len(near)
            ea += list(ca[near])
            et += list(ct[near])
            ev += [cv[i] for i in near]
            eg += list(cg[near])
            ep += list(cp[near])
    ej, ea, et = np.array(ej, int), np.array(ea, float), np.array(et, float)
    owner = np.array([jobs[j][0] for j in ej], int)
    etau = np.array([tau_all[jobs[j][1]] for j in ej], float)
    Gc, vec = np.array(eg, complex).reshape(-1), None  # searched on the whole structure: as they are
    # candidates of band searches: re-solved on the whole structure, same level
    lifted = np.flatnonzero(ep)
    if len(ej):
        for o in np.unique(owner[lifted]):
            ii = lifted[owner[lifted] == o]
            g_in = np.array([eg[i] for i in ii])
            a_f, t_f, ok, g_f, v_f = _newton(char(int(o), seed_level), ea[ii], et[ii], etau[ii], tol=REFINE_TOL, vec=np.array([ev[i] for i in ii]),
                                             Gc=g_in if np.all(np.isfinite(g_in)) else None)
            ea[ii] = np.where(ok, a_f, np.inf)
            et[ii] = np.where(t_f > np.pi, 2 * np.pi - t_f, t_f)
            Gc[ii] = g_f
            for q, i in enumerate(ii):
                ev[i] = np.conj(v_f[q]) if t_f[q] > np.pi else v_f[q]
        fine = np.isfinite(ea)
        # near ties again, on the whole structure
        for j in np.unique(ej):
            mine = np.flatnonzero(ej == j)
            if fine[mine].any():
                fine[mine] &= ea[mine] <= ea[mine][fine[mine]].min() * (1.0 + NEAR_TIE)
        sel = np.flatnonzero(fine)
        order = sel[np.lexsort((ea[sel], ej[sel]))]
        ej, ea, et, owner, etau, Gc = ej[order], ea[order], et[order], owner[order], etau[order], Gc[order]
        ev = [ev[i] for i in order]
        # duplicates (two bands converging on one point)
        dup = np.zeros(len(ej), bool)
        for k in range(1, len(ej)):
            if ej[k] == ej[k - 1] and abs(ea[k] - ea[k - 1]) <= 1e-5 * ea[k] and abs(et[k] - et[k - 1]) <= 1e-4:
                dup[k] = True
        keep_ = np.flatnonzero(~dup)
        ej, ea, et, owner, etau, Gc = ej[keep_], ea[keep_], et[keep_], owner[keep_], etau[keep_], Gc[keep_]
        ev = [ev[i] for i in keep_]
        if all(v is not None for v in ev):
            vec = list(ev)
    level = seed_level
    while level < 0 and len(ej):
        ea, et, _, Gc, vec = _batched_step(char, keeps, level, ea, et, etau, owner, Gc, vec)
        level += 1
    err = np.full(len(ej), np.inf)
    conv_job = np.zeros(J, bool)
    tied = np.zeros(J, bool)  # settled but for which of near points is the lowest (`settle`)
    level_job = np.zeros(J, int)
    lost = np.zeros(J, bool)  # no point of the job followed to level_job + 1
    active = np.ones(len(ej), bool)

    def keep_only(sel):
        nonlocal ej, ea, et, owner, etau, Gc, vec, err, active
        ej, ea, et, owner, etau, Gc, err, active = (x[sel] for x in (ej, ea, et, owner, etau, Gc, err, active))
        vec = None if vec is None else [vec[i] for i in sel]

    def near_ties():  # every job's points within NEAR_TIE of its lowest, none of a job to retry
        keep_el = np.ones(len(ej), bool)
        for j in range(J):
            mine = np.flatnonzero(ej == j)
            if len(mine):
                keep_el[mine] = (ea[mine] <= ea[mine].min() * (1.0 + NEAR_TIE)) & ~retry[j]
        keep_only(np.flatnonzero(keep_el))

    def refine():  # the active points one level up; a job converges where its lowest (and near) points moved by less than rel_tol / 2
        nonlocal level, vec
        idx = np.flatnonzero(active)
        v_in = None if vec is None else [vec[i] for i in idx]
        an, tn, ok, gn, vn = _batched_step(char, keeps, level, ea[idx], et[idx], etau[idx], owner[idx], Gc[idx], v_in)
        err[idx] = np.where(ok, np.abs(an - ea[idx]) / an, np.inf)
        ea[idx], et[idx], Gc[idx] = an, tn, gn
        if vec is None:
            vec = [None] * len(ej)
        for k, i in enumerate(idx):
            vec[i] = vn[k]
        level += 1
        # a point Newton cannot follow to the finer cut model is no boundary point of it (seen: a
        # 7.06 mm branch of 4 sub-steps a radian, 5 % immersion, 4.6 kHz modes, that no finer
        # model has; the answer there is 27.5 mm): dropped where the job has another point at
        # this level (a real lower branch is then caught by the count at the answer's resolution),
        # else the job is lost here and solved again from the seeds at this resolution
        failed = np.zeros(len(ej), bool)
        failed[idx[~ok]] = True
        drop = np.zeros(len(ej), bool)
        refined = np.unique(ej[idx])
        level_job[refined] = level
        for j in refined:
            mine = np.flatnonzero(ej == j)
            lost[j] = failed[mine].all()  # (a repair that adds a point later takes the job up again)
            if lost[j]:
                active[mine] = False
            elif verify or hinted[j]:  # unverified jobs keep them (not converged: flagged)
                drop[mine[failed[mine]]] = True
        keep_only(np.flatnonzero(~drop))
        for j in refined[~lost[refined]]:
            settle(j, level)
        look_ahead([j for j in refined[~lost[refined]] if conv_job[j]])

    def look_ahead(done):  # the lowest point of each job that has just converged, one step one level up (or up to where its stiff modes are not aliased): its error estimate the larger step, the job settled again with it
        top = _top_level(base)
        if not done or level + 1 > top:
            return
        low = np.array([mine[np.argmin(ea[mine])] for mine in (np.flatnonzero(ej == j) for j in done)])
        ahead = np.array([_unaliased_level(char(jobs[ej[i]][0], level, True), ea[i], etau[i], level, level + 1, top) for i in low])
        for lv in np.unique(ahead):
            sel = low[ahead == lv]
            v_in = None if vec is None else [vec[i] for i in sel]
            an, _, ok, _, _ = _batched_step(char, keeps, lv - 1, ea[sel], et[sel], etau[sel], owner[sel], Gc[sel], v_in, step=_step_estimate)
            moved = np.where(ok, np.abs(an - ea[sel]) / an, np.inf)
            far = np.arange(len(sel)) if lv > level + 1 else []
            if len(far):  # a step over several levels that can raise the estimate: one Newton step is no bound there (0.42 % where the root is 0.83 % away), Newton to the root
                v_far = None if v_in is None else [v_in[k] for k in far]
                af, _, okf, _, _ = _batched_step(char, keeps, lv - 1, ea[sel[far]], et[sel[far]], etau[sel[far]], owner[sel[far]], Gc[sel[far]], v_far)
                moved[far] = np.where(okf, np.maximum(moved[far], np.abs(af - ea[sel[far]]) / af), np.inf)
            err[sel] = np.maximum(err[sel], moved)
        for j in done:
            conv_job[j] = tied[j] = False
            active[ej == j] = True
            settle(j, level)

    def settle(j, lv):  # converged where the lowest (and near) points moved by less than rel_tol / 2, the lowest is known to be the lowest (TIE_TOL) and the cut model at lv resolves the soft modes
        mine = np.flatnonzero(ej == j)
        b = mine[np.argmin(ea[mine])]
        close = mine[ea[mine] <= ea[b] * (1 + rel_tol)]
        other = mine[(np.abs(et[mine] - et[b]) > 1e-3) | (np.abs(ea[mine] - ea[b]) > 1e-5 * ea[b])]  # other boundary points (not b again)
        with np.errstate(invalid="ignore"):
            ranked = (ea[other] * (1.0 - err[other]) > ea[b] * (1.0 + err[b])) | (np.maximum(err[other], err[b]) <= TIE_TOL)
        settled = (err[b] <= 0.5 * rel_tol and np.all(err[close] <= 0.5 * rel_tol)
                   and (np.all(ranked) or lv == _top_level(base)) and not char(jobs[j][0], lv, True).unresolved(ea[b], tau_all[jobs[j][1]]))
        tied[j] = settled and not np.all(ranked)  # only at the finest level (`_tie_immaterial`)
        if settled and not tied[j]:
            conv_job[j] = True
            active[mine] = False

    near_ties()
    if level + 2 <= _top_level(base) and len(ej):
        refine()
    # verified at the first refined level (where 9 in 10 sweep answers end; a lower branch at
    # the answer's own cut model that the coarse one puts above it is missed by a count there:
    # seen 3-8 % too deep in the blind search), lower branches repaired there (at the coarse
    # level where no level above the first is left to estimate a repaired point's error); a
    # hinted job not settled there is counted at its own resolution only (below: 4-12 % of a
    # sweep chunk's exponentials and samples, the same rows)
    vlevel = level
    deferred = np.zeros(J, bool)
    if verify or hinted.any():
        add_j, add_a, add_t = [], [], []
        for j, (s, e) in enumerate(jobs):
            if not (verify or hinted[j]):
                continue
            if hinted[j] and not (conv_job[j] or tied[j] or lost[j]) and np.any(ej == j):  # still refining: counted at its own resolution
                deferred[j] = True
                continue
            tau = tau_all[e]
            cv = char(s, vlevel, True)
            mine = np.flatnonzero(ej == j)
            top = ea[mine].min() if len(mine) else np.inf
            above = (1.0 + rel_tol) * top
            if len(mine):
                count, resolved, rung, ladder, count_above = _verify_count(cv, VERIFY_FRACTION * top, tau, et[mine], above)
            else:
                count, resolved, rung, ladder, count_above = 1, True, None, None, None
            if (count > 0 or not resolved or rung is not None) and hinted[j]:
                retry[j] = True
                continue
            found, lower = [], None  # boundary points to add to the job; the one below the count's depth

            def unknown(x, t):  # not a point the job has
                return not np.any((np.abs(ea[mine] - x) <= 1e-4 * x) & (np.abs(et[mine] - t) <= 1e-3))

            if count > 0 or not resolved or rung is not None:  # a lower branch (below a Hopf rung's depth where one counts)
                extra = _repair(cv, tau, top if rung is None else rung / VERIFY_FRACTION)
                if extra:  # the others the repair reached are ranked with it (near ties: refined too)
                    lower = extra[0]
                    found = [lower] + [p for p in extra[1:] if unknown(*p)]
            elif count_above is not None and count_above > _crossings(et[mine][ea[mine] <= above]):
                # more crossings up to rel_tol above the answer than its known points bring: a
                # branch the search missed there (continuation follows the neighbours' branches
                # only), which a finer cut model can put below the answer (`TIE_TOL`): Newton
                # from the multipliers nearest the circle at that depth, the new points refined
                # with the others (one below the count's depth, an island the count could not
                # see, is verified there, as a repair)
                a_r, t_r = _newton_from_nearest(cv, tau, above, DESCENT_POINTS, DESCENT_STARTS)
                found = [(float(x), float(t)) for x, t in zip(a_r, t_r) if x <= above * (1.0 + REPAIR_SLACK) and unknown(x, t)]
                lower = found[0] if found and found[0][0] < VERIFY_FRACTION * top else None
            if found:
                add_j += [j] * len(found)
                add_a += [x for x, _ in found]
                add_t += [t for _, t in found]
                conv_job[j] = tied[j] = False
                active[mine] = True
            if lower is not None:
                repaired[j] = True
                count, resolved, rung, ladder, _ = _verify_count(cv, VERIFY_FRACTION * lower[0], tau, [lower[1]])
            if ladder is not None:
                ladders[j] = (vlevel,) + ladder
            verified[j] = bool(count == 0 and resolved and rung is None)
        if add_j:
            n_add = len(add_j)
            ej = np.concatenate([ej, add_j])
            ea = np.concatenate([ea, add_a])
            et = np.concatenate([et, add_t])
            owner = np.array([jobs[j][0] for j in ej], int)
            etau = np.array([tau_all[jobs[j][1]] for j in ej], float)
            Gc = np.concatenate([Gc, np.zeros(n_add, complex)])
            err = np.concatenate([err, np.full(n_add, np.inf)])
            active = np.concatenate([active, np.ones(n_add, bool)])
            vec = None if vec is None else list(vec) + [None] * n_add
        near_ties()
    while level + 1 <= _top_level(base) and active.any():
        refine()
    # points at the finest level with no estimate (a repair there, a job solved again there): no
    # level above is left, so one level down (Newton from the point; the difference bounds the
    # finer value's error as it does upward)
    top = _top_level(base)
    at_top = np.array([level_job[j] == top and not lost[j] for j in ej], bool)
    down = np.flatnonzero(at_top & ~np.isfinite(err)) if len(ej) else np.zeros(0, int)
    if len(down):
        v_in = None if vec is None or any(vec[i] is None for i in down) else [vec[i] for i in down]
        a_d, _, ok, _, _ = _batched_step(char, keeps, top - 2, ea[down], et[down], etau[down], owner[down], Gc[down], v_in)  # Newton at top - 1
        err[down] = np.where(ok, np.abs(a_d - ea[down]) / ea[down], np.inf)
        for j in np.unique(ej[down]):
            settle(j, top)
    # the irrelevant modes back in, same resolution
    back = np.flatnonzero([len(keeps[o]) < dyns[o].n_modes for o in owner])
    if len(back):
        full_vec = []
        for i in back:
            o = owner[i]
            N, kp = dyns[o].n_modes, keeps[o]
            ns = len(kp)
            v = np.zeros(2 * N, dtype=complex)
            if vec is None or vec[i] is None:  # a point never refined (a repair at the finest level): Newton picks its own
                v[:] = np.nan
            else:
                v[kp], v[N + kp] = vec[i][:ns], vec[i][ns:]
            full_vec.append(v)
        ob, lb = owner[back], level_job[ej[back]]
        for lv in np.unique(lb):
            sb = np.flatnonzero(lb == lv)
            ii = back[sb]
            n_struct = int(owner.max()) + 1
            batch = _Batch([char(s, int(lv), True) if s in set(ob[sb].tolist()) else None for s in range(n_struct)], ob[sb])
            a_f, t_f, ok, _, _ = _newton(batch, ea[ii], et[ii], etau[ii], tol=REFINE_TOL, Gc=Gc[ii], vec=np.array([full_vec[k] for k in sb]))
            ea[ii] = np.where(ok, a_f, ea[ii])
            et[ii] = np.where(ok, np.where(t_f > np.pi, 2 * np.pi - t_f, t_f), et[ii])
    # the count again at the answer's own resolution where that is finer than the verification's:
    # not 0 means a lower branch there that the search missed (the caller solves the job again at
    # that resolution)
    missed = np.zeros(J, bool)
    for j, (s, e) in enumerate(jobs):
        mine = np.flatnonzero(ej == j)
        lv = int(level_job[j])
        if len(mine) and (verify or hinted[j]) and not retry[j] and (lv > vlevel or deferred[j]):
            top = ea[mine].min()
            above = (1.0 + rel_tol) * top if deferred[j] else None
            count, resolved, rung, ladder, count_above = _verify_count(char(s, lv, True), VERIFY_FRACTION * top, tau_all[e], et[mine], above)
            # (a job counted here only: more crossings up to rel_tol above than its points bring is
            # a branch the search missed, as at the first refined level)
            missed[j] = not (count == 0 and resolved and rung is None) or (count_above is not None and count_above > _crossings(et[mine][ea[mine] <= above]))
            if deferred[j]:  # (hinted: where the count is not 0, solved again from the seeds)
                retry[j], missed[j] = missed[j], False
                verified[j] = not retry[j]
                if ladder is not None and not retry[j]:
                    ladders[j] = (lv,) + ladder
    # chatter frequencies, batched per (structure, resolution)
    wanted: dict = {}
    for j, (s, e) in enumerate(jobs):
        mine = np.flatnonzero(ej == j)
        for rank, i in enumerate(mine[np.argsort(ea[mine])]):
            if frequencies and (rank == 0 or branch_families):  # or the lowest branch's frequency only
                wanted.setdefault((s, int(level_job[j])), []).append(i)
    family_of = {}
    for (s, lv), members in wanted.items():
        members = np.array(members, int)
        for i, fam in zip(members, floquet_families(char(s, lv, True), ea[members], et[members], etau[members])):
            family_of[int(i)] = fam
    points = []
    for j, (s, e) in enumerate(jobs):
        if retry[j]:
            points.append(None)
            continue
        mine = np.flatnonzero(ej == j)
        r = float(rpm[e])
        if not len(mine):  # no boundary point found: proven absent only where no cutting force reaches the structure
            inert = not np.any(char(s, 0, True).W)
            points.append(CriticalPoint(r, np.inf if inert else np.nan, np.nan, np.nan, (), base, 0.0 if inert else np.inf, inert, True if inert else verified[j], ()))
            continue
        lv = level_job[j]
        branches = []
        for i in mine[np.argsort(ea[mine])]:
            hz, family = family_of.get(int(i), (np.nan, ()))
            branches.append((float(ea[i]), hz, float(et[i]), family, float(err[i])))
        a, hz, th, family, er = branches[0]
        settled = conv_job[j] or (tied[j] and _tie_immaterial(branches, frequencies))
        points.append(CriticalPoint(r, a, hz, th, family, base * 2.0**lv, er, bool(settled and er <= rel_tol), verified[j],
                                    tuple((b[0], b[1], b[2]) for b in branches), bool(repaired[j])))
    return points, missed, ladders, lost


#: Two boundary points too near to rank at the finest level (`TIE_TOL`) whose chatter frequencies
#: agree within this fraction leave nothing open: either is the answer, depth and frequency.
#: Seen in a blind check: 6.0279 / 6.0287 mm at 9339.8 / 9394.6 Hz (4 teeth, 277 rpm; their
#: estimates 0.16 %) and 3.0668 / 3.0721 mm at 9839.5 / 9839.1 Hz (248 rpm, 0.30 %) were flagged
#: not converged at 628 and 815 sub-steps a radian, where no finer level is left.
TIE_FREQUENCY = 1e-2


def _tie_immaterial(branches, frequencies: bool) -> bool:
    """Whether the points of a job that cannot be ranked against its lowest (intervals depth x
    (1 +- estimate) overlapping) leave its answer open: not where no frequency is asked (the depth
    is the lowest either way, each within its estimate) or where all their frequencies agree
    within TIE_FREQUENCY. `branches`: (depth, hz, theta, family, estimate), lowest first."""
    a, hz, _, _, er = branches[0]
    if not frequencies:
        return True
    tied_hz = [b[1] for b in branches[1:] if b[0] * (1.0 - b[4]) <= a * (1.0 + er)]
    return bool(np.isfinite(hz)) and all(np.isfinite(f) and abs(f - hz) <= TIE_FREQUENCY * hz for f in tied_hz)


def _dedupe(a, t, rel: float = 1e-5, index: bool = False):
    """Distinct boundary points (theta folded to [0, pi]), sorted by depth (or their indices)."""
    t = np.where(t > np.pi, 2.0 * np.pi - t, t)
    order = np.argsort(a)
    out_a, out_t, out_i = [], [], []
    for i in order:
        if any(abs(a[i] - x) <= rel * x and abs(t[i] - y) <= 1e-4 for x, y in zip(out_a, out_t)):
            continue
        out_a.append(a[i])
        out_t.append(t[i])
        out_i.append(i)
    if index:
        return np.array(out_i, int)
    return np.array(out_a), np.array(out_t)


def _step_level(char, level, a_prev, t_prev, tau, Gc, vec):
    """Newton at level + 1 from the boundary points of `level`: (a, theta folded to [0, pi],
    converged, Gc, vec). Rows of `vec` that are NaN (and None for all) take the eigenvector of
    the eigenvalue nearest 1 / nu at `level`; rows of Gc that are NaN a difference."""
    taus = np.full(len(a_prev), tau)
    if vec is None:
        _, vec = _critical_log(char(level), a_prev, t_prev, taus)
    elif not np.all(np.isfinite(vec)):  # the points without one: picked at this level, as above
        missing = np.flatnonzero(~np.all(np.isfinite(vec), axis=1))
        vec = vec.copy()
        vec[missing] = _critical_log(char(level), a_prev[missing], t_prev[missing], taus[missing], idx=missing)[1]
    a_new, t_new, ok, Gc, vec = _newton(char(level + 1), a_prev, t_prev, taus, tol=REFINE_TOL, Gc=Gc, vec=vec)
    a_new = np.where(ok, a_new, a_prev)
    vec = np.where((t_new > np.pi)[:, None], np.conj(vec), vec)
    t_new = np.where(ok, np.where(t_new > np.pi, 2 * np.pi - t_new, t_new), t_prev)
    return a_new, t_new, ok, Gc, vec


def _step_estimate(char, level, a_prev, t_prev, tau, Gc, vec):
    """`_step_level` by one Newton step (one monodromy at level + 1, G_c of `level`): the depth
    and theta to first order in the step, for an error estimate."""
    taus = np.full(len(a_prev), tau)
    if vec is None or not np.all(np.isfinite(vec)) or Gc is None or not np.all(np.isfinite(Gc)):
        return _step_level(char, level, a_prev, t_prev, tau, Gc, vec)
    g, vec = _critical_log(char(level + 1), a_prev, t_prev, taus, vec=vec)
    step, _, _, bad = _newton_step(a_prev, t_prev, Gc, g)
    ok = ~bad & np.isfinite(g) & np.all(np.isfinite(step), axis=1)
    return np.where(ok, a_prev + step[:, 0], a_prev), np.where(ok, t_prev + step[:, 1], t_prev), ok, Gc, vec


def _repair(char, tau, a_top) -> list:
    """Boundary points below a_top missed by the seeds: first Newton from the boundary points of
    Hill's method (`_from_hill`), then `_descend` (Newton from the multipliers nearest the
    boundary condition at VERIFY_FRACTION x a_top), else bisection in depth on the winding
    count, then Newton from the multipliers nearest it there. Returns [(depth, theta), ...]: the
    accepted point first, then the other boundary points the same Newton reached, by depth (a
    finer cut model can put one of them below the first: they are ranked with the job's points;
    seen: two branches 0.6 % apart at the coarse level, the one kept 1.9 % too deep at the
    converged one, 22 modes at 443 rpm); [] where none is accepted."""
    found = _from_hill(char, tau, a_top)
    if not found and np.isfinite(a_top):
        found = _descend(char, tau, a_top)
    return found if found else _bisect_repair(char, tau, a_top)


def _accepted_first(a, theta, k: int) -> list:
    """[(a[k], theta[k]), then the other points by depth], thetas folded to [0, pi]."""
    order = [k] + [i for i in np.argsort(a) if i != k]
    return [(float(a[i]), _fold(theta[i])) for i in order]


#: Repair from Hill's method: Newton from this many of its lowest boundary points below the
#: depth the count rejected (and up to HILL_ABOVE x it: Newton moves a seed by a few per cent).
HILL_STARTS = 4
HILL_ABOVE = 1.1


def _from_hill(char, tau, a_top):
    """The zeroth-order seeds miss boundary points that the interrupted cut makes between modes
    at or below a few tooth-passing frequencies (`hill`); Hill's method with HARMONICS harmonics
    places them within a few per cent. Newton (whole structure) from its lowest HILL_STARTS
    points; the lowest one reached below VERIFY_FRACTION x a_top is accepted when the winding
    count at VERIFY_FRACTION x its depth is 0 (`_repair`'s list). [] otherwise (or where the
    structure has no mode within reach of the harmonics)."""
    a_s, th_s = hill.hill_seeds(char.frf, char.free_eig()[0], char.cut, tau)
    take = np.flatnonzero(a_s <= HILL_ABOVE * a_top)[:HILL_STARTS]
    if not len(take):
        return []
    a_r, t_r, ok, _, _ = _newton(char, a_s[take], th_s[take], np.full(len(take), tau))
    ok &= a_r > 0
    a_r, t_r = a_r[ok], t_r[ok]
    below = np.flatnonzero(a_r < VERIFY_FRACTION * a_top)
    if not len(below):
        return []
    found = _accepted_first(a_r, t_r, int(below[np.argmin(a_r[below])]))
    count, resolved, _ = unstable_count(char, VERIFY_FRACTION * found[0][0], tau, extra=[found[0][1]])
    return found if count == 0 and resolved else []


#: Repair by descent: theta samples of the multipliers, Newton starts, rounds.
DESCENT_POINTS = 64
DESCENT_STARTS = 4
DESCENT_ROUNDS = 4
#: Depths (fractions of the rejected one) counted before the bisection proper, in this order.
BISECT_PROBES = (0.95, 0.8, 0.5)
#: Thetas sampled for the Newton starts after the bisection.
BISECT_POINTS = 181
#: How far above the bisection's bracket a Newton root may lie and still be taken (half the
#: engine's default tolerance).
REPAIR_SLACK = 0.01


def _newton_from_nearest(char, tau, a, points: int, starts: int):
    """Boundary points (depth, theta folded to [0, pi]) reached by Newton on g = ln(nu sigma) = 0
    from depth a and the `starts` thetas, among `points` in [0, pi], where an eigenvalue sigma of
    M(a (1 - nu)) comes nearest to 1 / nu (local minima of min_k |ln(nu sigma_k)|), each on that
    eigenvalue's eigenvector; sorted by depth."""
    th = np.linspace(0.0, np.pi, points)
    with np.errstate(all="ignore"):  # an overflowing monodromy (depths far past any boundary) gives no start
        M = char.monodromy(a * (1.0 - np.exp(-1j * th)), np.full(len(th), tau))
    finite = np.all(np.isfinite(M), axis=(1, 2))
    th, M = th[finite], M[finite]
    if not len(th):
        return np.zeros(0), np.zeros(0)
    nu = np.exp(-1j * th)
    values, vectors = np.linalg.eig(M)
    with np.errstate(all="ignore"):
        dist = np.abs(np.log(values * nu[:, None]))
    dist = np.where(np.isfinite(dist), dist, np.inf)
    k = np.argmin(dist, axis=1)
    near = dist[np.arange(len(th)), k]
    local = np.flatnonzero((near <= np.roll(near, 1)) & (near <= np.roll(near, -1)) & np.isfinite(near))
    if not len(local):
        return np.zeros(0), np.zeros(0)
    first = local[np.argsort(near[local])[:starts]]
    a_r, t_r, ok, _, _ = _newton(char, np.full(len(first), a), th[first], np.full(len(first), tau), vec=vectors[first, :, k[first]])
    ok &= a_r > 0
    t_r = np.mod(t_r[ok], 2.0 * np.pi)
    order = np.argsort(a_r[ok])
    return a_r[ok][order], np.minimum(t_r, 2.0 * np.pi - t_r)[order]


def _descend(char, tau, a_top):
    """Where the winding count says multipliers are outside the unit circle at a = 0.995 a_top,
    the branch they belong to crossed the circle below: `_newton_from_nearest` at that depth
    (DESCENT_STARTS starts among DESCENT_POINTS thetas) reaches such crossings directly. The lowest
    crossing below a is accepted when the count at 0.995 x its depth is 0 (otherwise the next round
    starts from it). About 3 winding counts of work where the bisection takes 10. `_repair`'s
    list; [] when no round ends with a zero count."""
    a = VERIFY_FRACTION * a_top
    for _ in range(DESCENT_ROUNDS):
        a_r, t_r = _newton_from_nearest(char, tau, a, DESCENT_POINTS, DESCENT_STARTS)
        if not len(a_r) or a_r[0] >= a:  # sorted by depth
            return []
        count, resolved, _ = unstable_count(char, VERIFY_FRACTION * a_r[0], tau, extra=[t_r[0]])
        if count == 0 and resolved:
            return _accepted_first(a_r, t_r, 0)
        a = VERIFY_FRACTION * a_r[0]
    return []


def _count_bracket(unstable, lo: float, hi: float, rel: float):
    """(lo, hi), rel apart, with the count's crossing between them, below VERIFY_FRACTION x hi
    (`unstable(a)`: the count at a is not 0): probes at BISECT_PROBES of it first (a missed
    branch is often just below), then bisection (geometric above a floor of hi / 1000, or the
    `lo` given where higher)."""
    floor = max(lo, hi * 1e-3)
    hi *= VERIFY_FRACTION
    lo = None
    for fraction in BISECT_PROBES:
        if unstable(fraction * hi):
            hi = fraction * hi
        else:
            lo = fraction * hi
            break
    if lo is None:  # every probe unstable: down to the floor (the doubling's last stable depth only where still below)
        floor = floor if floor < hi else 1e-3 * hi
        lo = 0.0 if unstable(floor) else floor
    while hi - lo > rel * hi:
        mid = 0.5 * (lo + hi) if lo == 0.0 else np.sqrt(lo * hi)
        if unstable(mid):
            hi = mid
        else:
            lo = mid
    return lo, hi


def _bisect_repair(char, tau, a_top):
    trusted = True  # every count of the bisection resolved: its bracket can be trusted

    def unstable(a):  # a count that is not resolved has not shown stability (its number can be anything)
        nonlocal trusted
        count, resolved, _ = unstable_count(char, a, tau)
        trusted &= resolved
        return count > 0 or not resolved

    lo, hi = 0.0, a_top if np.isfinite(a_top) else None
    if hi is None:
        a = 1e-4
        for _ in range(30):
            if unstable(a):
                hi = a
                break
            lo, a = a, a * 2.0
        if hi is None:
            return []
    lo, hi = _count_bracket(unstable, lo, hi, 0.01)
    # the crossing lies between lo and hi (1 % apart): Newton from hi, the lowest point reached
    # not above hi by more than REPAIR_SLACK (a start that runs to a higher branch is no answer;
    # on a flip lobe, theta = pi, Newton's root at this level can sit just above the bracket the
    # count gives: seen 0.8 % above on seed 002's TMD host at 1900 rpm; the caller's winding
    # count at 0.995 x the point verifies it)
    a_r, t_r = _newton_from_nearest(char, tau, hi, BISECT_POINTS, DESCENT_STARTS)
    fit = a_r <= hi * (1.0 + REPAIR_SLACK)
    if not fit.any():  # the crossing's multiplier is not among the nearest few (seen: the 5th, absorber pose): from every local minimum
        a_r, t_r = _newton_from_nearest(char, tau, hi, BISECT_POINTS, BISECT_POINTS)
        fit = a_r <= hi * (1.0 + REPAIR_SLACK)
    if not fit.any():  # e.g. two multipliers nearly equal (x and y spindle modes 0.3 % apart), or M's eigenvalues known to 1e-3 only (modes dying out between cuts): on the determinant (an untrusted bracket too: the caller's count verifies the point)
        a_r, t_r = _newton_on_determinant(char, tau, hi, BISECT_POINTS, DESCENT_STARTS)
        fit = (a_r <= hi * (1.0 + REPAIR_SLACK)) & (a_r >= lo * (1.0 - REPAIR_SLACK))
    if not fit.any() and trusted:  # a flip point: a real multiplier passes -1 in the bracket
        flip = _flip_root(char, tau, lo, hi)
        if flip is not None:
            return [(flip, np.pi)]
    if not fit.any():
        return []
    return _accepted_first(a_r, t_r, int(np.flatnonzero(fit)[0]))


def _flip_root(char, tau: float, lo: float, hi: float, rel_tol: float = 1e-10):
    """The depth in [lo, hi] where det(I + M(2 a)) changes sign (a real multiplier passes -1:
    a boundary point at theta = pi), by Brent's method on det^(1/2n) (one real monodromy a
    step); None where the sign is the same at both ends. The 2-D Newton on one eigenvalue fails
    where the multiplier has just split from a complex pair that met on the negative axis (seen:
    -0.994 double at 0.995 x the root, absorber pose, 64 sub-steps a radian)."""
    eye = np.eye(2 * char.n)

    def scaled(a):
        with np.errstate(all="ignore"):
            sign, logdet = np.linalg.slogdet(eye + char.monodromy(np.array([2.0 * a]), np.array([tau]))[0].real)
        return float(sign * np.exp(logdet / len(eye)))

    f_lo, f_hi = scaled(lo), scaled(hi)
    if not (np.isfinite(f_lo) and np.isfinite(f_hi)) or f_lo * f_hi >= 0.0:
        return None
    return float(scipy.optimize.brentq(scaled, lo, hi, xtol=rel_tol * hi, rtol=1e-14))


def _newton_on_determinant(char, tau, a, points: int, starts: int, iterations: int = 30, tol: float = 1e-8):
    """Boundary points (depth, theta in [0, pi]) by Newton on h(a, theta) = det(I - nu M(a (1 - nu)))
    = 0 itself, from depth a and the `starts` thetas among `points` in [0, pi] where |h| has its
    lowest local minima. h is entire in c and smooth in (a, theta) where two multipliers nearly
    coincide, which is where following one eigenvalue (`_newton`) jumps between them. The step
    solves L_a da + L_theta dtheta = -1 (L = ln h, `log_char`), limited like `_newton`'s."""
    th = np.linspace(0.0, np.pi, points)
    nu = np.exp(-1j * th)
    M = char.monodromy(a * (1.0 - nu), np.full(len(th), tau))
    with np.errstate(all="ignore"):
        _, size = np.linalg.slogdet(np.eye(M.shape[-1]) - nu[:, None, None] * M)
    size = np.where(np.isfinite(size), size, np.inf)
    local = np.flatnonzero((size <= np.roll(size, 1)) & (size <= np.roll(size, -1)) & np.isfinite(size))
    first = local[np.argsort(size[local])[:starts]]
    a_r, t_r = np.full(len(first), float(a)), th[first].copy()
    done = np.zeros(len(first), bool)
    for _ in range(iterations):
        act = np.flatnonzero(~done & (a_r > 0) & np.isfinite(a_r) & np.isfinite(t_r))
        if not len(act):
            break
        with np.errstate(all="ignore"):
            _, La, Lt, _ = char.log_char(a_r[act], t_r[act], np.full(len(act), tau))
            det = La.real * Lt.imag - Lt.real * La.imag
            da, dt = -Lt.imag / det, La.imag / det
            excess = _step_excess(a_r[act], da, dt)
            a_r[act] += np.where(np.isfinite(da / excess), da / excess, np.nan)  # a singular step ends that start
            t_r[act] += dt / excess
        done[act] = (np.abs(da) < tol * a_r[act]) & (np.abs(dt) < tol)
    ok = done & (a_r > 0)
    t = np.mod(t_r[ok], 2.0 * np.pi)
    order = np.argsort(a_r[ok])
    return a_r[ok][order], np.minimum(t, 2.0 * np.pi - t)[order]
