"""Stability and chatter frequency of a cut, from the semi-discretization (`sdm`).

- `spectral_radius`: |dominant Floquet multiplier| on any grid of speeds and depths (stable < 1).
- `critical_depths`: the smallest depth with spectral radius 1 at each speed, found by bracketing
  on a geometric depth ladder and Illinois regula falsi on ln(rho) against ln(depth).
- chatter frequencies (Dombovari, Iglesias, Zatarain, Insperger 2011): the critical multiplier mu
  gives lambda = ln(mu) / tau; the Floquet solution is exp(lambda t) p(t) with p tau-periodic, so
  it vibrates at the family |Im(lambda) + j w_T|, w_T = 2 pi / tau. The weight of each member is the
  j-th Fourier coefficient of p, sampled from the eigenvector over one delay with the growth
  exp(lambda t) divided out; the dominant chatter frequency is the member with the largest
  tool-tip amplitude. A real negative multiplier (flip) puts the family at w_T / 2 + j w_T.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError
from posedyn.stability import sdm, zoa
from posedyn.stability.cutting import Cut

#: Batch elements per worker task; big batches run on a thread pool (numpy releases the GIL).
CHUNK = 2500


@dataclass(frozen=True)
class Discretization:
    """Steps per delay and the order of the delayed-term approximation (0: seed 004's weights 1/2)."""

    steps: int = 40
    order: int = 0

    def __post_init__(self):
        if not isinstance(self.steps, (int, np.integer)) or self.steps < 2:
            raise InputError("an integer number of steps per delay >= 2", got=self.steps, column="steps")
        if self.order not in sdm.ORDERS:
            raise InputError("order 0 or 1", got=self.order, column="order")


class StabilityModel:
    """A tool-tip modal model and a cut, ready for repeated stability evaluations.

    Holds the per-step modal force matrices (which depend on the cut and the step count only),
    like Pinocchio's Model: immutable, shared by every call; each call builds its own step
    matrices.
    """

    def __init__(self, dyn: ToolTipDynamics, cut: Cut, disc: Discretization = Discretization(), workers: int | None = None):
        self.dyn = dyn
        self.cut = cut
        self.disc = disc
        self.workers = workers or os.cpu_count() or 1
        self.w_modal = sdm.modal_force_matrices(dyn, cut, disc.steps)
        self._absolute_zoa = None

    def step_matrices(self, rpm, depth_m) -> sdm.StepMatrices:
        rpm, depth = np.broadcast_arrays(np.asarray(rpm, dtype=float).reshape(-1), np.asarray(depth_m, dtype=float).reshape(-1))
        if np.any(~np.isfinite(rpm) | (rpm <= 0)):
            raise InputError("spindle speeds > 0 rpm", got=rpm[~np.isfinite(rpm) | (rpm <= 0)][0], column="rpm")
        if np.any(~np.isfinite(depth) | (depth < 0)):
            raise InputError("depths >= 0", got=depth[~np.isfinite(depth) | (depth < 0)][0], column="depth")
        dt = self.cut.tooth_period_s(rpm) / self.disc.steps
        return sdm.step_matrices(self.dyn, self.w_modal, depth, dt, self.disc.order)

    def multipliers(self, rpm, depth_m) -> np.ndarray:
        """Dominant multiplier (Im >= 0) for each (rpm, depth) pair of the broadcast inputs."""
        rpm, depth = np.broadcast_arrays(np.asarray(rpm, dtype=float), np.asarray(depth_m, dtype=float))
        flat_rpm, flat_depth = rpm.reshape(-1), depth.reshape(-1)

        def run(index):
            return sdm.dominant_multipliers(self.step_matrices(flat_rpm[index], flat_depth[index]))

        n = len(flat_rpm)
        if n <= CHUNK or self.workers == 1:
            out = run(np.arange(n))
        else:
            parts = np.array_split(np.arange(n), -(-n // CHUNK))
            with ThreadPoolExecutor(self.workers) as pool:
                out = np.concatenate(list(pool.map(run, parts)))
        return out.reshape(rpm.shape)

    def spectral_radius(self, rpm, depth_m) -> np.ndarray:
        return np.abs(self.multipliers(rpm, depth_m))

    @property
    def absolute_limit_zoa_m(self) -> float:
        if self._absolute_zoa is None:
            self._absolute_zoa = zoa.absolute_limit_m(self.dyn, self.cut)
        return self._absolute_zoa

    def critical_depths(self, rpm, rel_tol: float = 1e-6, frequencies: bool = True, guess_m=None, guess_span: float = 2.0) -> "CriticalDepths":
        """Critical depth at each speed. `guess_m` (per speed) starts the bracketing ladder at
        five depths from guess / guess_span to guess * guess_span instead of around the ZOA
        absolute limit (the ladder still widens when the crossing is outside)."""
        rpm = np.atleast_1d(np.asarray(rpm, dtype=float))
        scale = np.full(len(rpm), self.absolute_limit_zoa_m)
        depth, depth_unstable, mu = critical_crossing(lambda j, d: self.multipliers(rpm[j], d), scale, rel_tol, guess_m, guess_span)
        family = [()] * len(rpm)
        dominant = np.full(len(rpm), np.nan)
        if frequencies:
            finite = np.flatnonzero(np.isfinite(depth))
            if len(finite):
                steps = self.step_matrices(rpm[finite], depth_unstable[finite])
                for j, (dom, fam) in zip(finite, chatter_frequencies(self.shapes, steps, mu[finite])):
                    dominant[j], family[j] = dom, fam
        return CriticalDepths(rpm=rpm, depth_m=depth, multiplier=mu, dominant_chatter_hz=dominant, family=tuple(family))

    @property
    def shapes(self) -> np.ndarray:
        """Tool-tip mode shapes in the feed-aligned axes of the cut (2, n)."""
        return self.dyn.rotated(np.deg2rad(self.cut.feed_angle_deg)).shapes

    def chatter_at(self, rpm, depth_m) -> "CriticalDepths":
        """Dominant multiplier and chatter frequencies at given (rpm, depth) pairs (the depth
        field holds the given depths)."""
        rpm, depth = np.broadcast_arrays(np.atleast_1d(np.asarray(rpm, dtype=float)), np.atleast_1d(np.asarray(depth_m, dtype=float)))
        mu = self.multipliers(rpm, depth)
        pairs = chatter_frequencies(self.shapes, self.step_matrices(rpm, depth), mu)
        return CriticalDepths(
            rpm=rpm,
            depth_m=depth,
            multiplier=mu,
            dominant_chatter_hz=np.array([d for d, _ in pairs]),
            family=tuple(f for _, f in pairs),
        )

    def absolute_limit_m(self, lobes: int = 4) -> tuple[float, float]:
        """Speed-independent limit: the lowest bottom of the first `lobes` stability lobes and
        its speed. Each bottom is searched (golden section on the speed) within 10 % of the
        speed where the zeroth-order approximation puts it: lobe k has
        rpm_k = 60 w* / (N (psi* + 2 pi k)), w* the ZOA's most critical chatter frequency."""
        b = zoa.branches(self.dyn, self.cut)
        if not np.isfinite(b.depth_m).any():
            return float("inf"), float("nan")
        branch, index = np.unravel_index(np.nanargmin(b.depth_m), b.depth_m.shape)
        w, psi = b.omega_rad_s[index], b.phase_rad[branch, index]
        centre = 60.0 * w / (self.cut.teeth * (psi + 2.0 * np.pi * np.arange(lobes)))
        guess = np.full(lobes, b.depth_m[branch, index])
        lo, hi = 0.9 * centre, 1.1 * centre
        ratio = (np.sqrt(5.0) - 1.0) / 2.0
        evaluate = lambda r, g: self.critical_depths(r, rel_tol=1e-7, frequencies=False, guess_m=g, guess_span=1.1).depth_m  # noqa: E731
        c, d = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
        fc, fd = np.split(evaluate(np.concatenate([c, d]), np.concatenate([guess, guess])), 2)
        for _ in range(25):
            left = fc < fd  # minimum in [lo, d]
            hi, lo = np.where(left, d, hi), np.where(left, lo, c)
            new = np.where(left, hi - ratio * (hi - lo), lo + ratio * (hi - lo))
            fnew = evaluate(new, np.minimum(fc, fd))
            c, d, fc, fd = (
                np.where(left, new, d), np.where(left, c, new),
                np.where(left, fnew, fd), np.where(left, fc, fnew),
            )
            if np.all(hi - lo < 1e-4 * centre):  # depth is flat at the bottom: error ~ (d rpm)^2
                break
        best = np.where(fc < fd, fc, fd)
        best_rpm = np.where(fc < fd, c, d)
        k = int(np.argmin(best))
        return float(best[k]), float(best_rpm[k])


@dataclass(frozen=True, eq=False)
class CriticalDepths:
    """Per speed: critical depth (m, inf when no depth up to 10^4 times the ZOA limit chatters),
    the critical multiplier, the dominant chatter frequency and the chatter frequency family
    ((hz, relative amplitude) pairs, largest first)."""

    rpm: np.ndarray
    depth_m: np.ndarray
    multiplier: np.ndarray
    dominant_chatter_hz: np.ndarray
    family: tuple


def critical_crossing(multipliers, scale: np.ndarray, rel_tol: float, guess_m=None, guess_span: float = 2.0, rungs: int | None = None):
    """Bracket and refine rho(a) = 1 for every element (a speed, or a structure at one speed);
    `multipliers(elements, depths)` gives the dominant multiplier of broadcast (element index,
    depth) pairs and `scale` (per element) is where the ladder starts, the ZOA absolute limit or
    an estimate of it. Returns the critical depths, the depths just on the unstable side, and
    the multipliers there.

    Bracketing walks geometric ladders of depths: the first unstable rung and the rung below it
    bound the lowest crossing on the ladder; a ladder that starts unstable is followed by one
    below it, one that stays stable by one above it (up to 10^4 times the ZOA limit: beyond
    that the cut is taken as stable at every depth). With `rungs`, every ladder has that many
    rungs a factor sqrt(2) apart, the first one ending at the guess (short ladders walked in
    more rounds: fewer evaluations when the guess is good, as in a pose sweep)."""
    n = len(scale)
    scale = np.where(np.isfinite(scale) & (scale > 0), scale, 1e-3)
    below, above = np.arange(-8, 0) / 2.0, np.arange(1, 9) / 2.0
    if rungs is not None:
        start = np.asarray(scale if guess_m is None else guess_m, dtype=float).reshape(-1, 1)
        ladders = list(start * 2.0 ** (np.arange(1 - rungs, 1) / 2.0)[None])
        below, above = np.arange(-rungs, 0) / 2.0, np.arange(1, rungs + 1) / 2.0
    elif guess_m is None:
        ladders = list(scale[:, None] * 2.0 ** (np.arange(-8, 9) / 2.0)[None])
    else:
        ladders = list(np.asarray(guess_m, dtype=float).reshape(-1, 1) * guess_span ** (np.arange(-2, 3) / 2.0)[None])
    lo = np.zeros(n)
    lo_rho = np.full(n, np.nan)
    hi = np.full(n, np.inf)
    hi_mu = np.full(n, np.nan + 0j)
    todo = list(range(n))
    for _ in range(12 if rungs is None else max(12, 96 // rungs)):
        if not todo:
            break
        width = max(len(ladders[j]) for j in todo)
        rows = np.array([np.pad(ladders[j], (0, width - len(ladders[j])), mode="edge") for j in todo])
        mu = multipliers(np.array(todo)[:, None], rows)
        rho = np.abs(mu)
        still = []
        for row, j in enumerate(todo):
            unstable = np.flatnonzero(rho[row] >= 1.0)
            rung = rows[row]
            if len(unstable) and unstable[0] > 0:
                k = unstable[0]
                lo[j], lo_rho[j], hi[j], hi_mu[j] = rung[k - 1], rho[row, k - 1], rung[k], mu[row, k]
            elif len(unstable):  # unstable from the first rung: look below it
                hi[j], hi_mu[j] = rung[0], mu[row, 0]
                if lo[j] > 0:  # a stable rung is already known below (from an earlier ladder)
                    continue
                if rung[0] < 1e-9 * scale[j]:
                    lo[j] = 0.0
                    continue
                ladders[j] = rung[0] * 2.0**below
                still.append(j)
            else:  # stable on every rung: look above
                lo[j], lo_rho[j] = rung[-1], rho[row, -1]
                if np.isfinite(hi[j]):
                    continue
                if rung[-1] > 1e4 * scale[j]:
                    continue
                ladders[j] = rung[-1] * 2.0**above
                still.append(j)
        todo = still
    bracketed = np.flatnonzero((lo > 0) & np.isfinite(hi))
    x_lo, x_hi = np.log(lo[bracketed]), np.log(hi[bracketed])
    g_lo, g_hi = np.log(lo_rho[bracketed]), np.log(np.abs(hi_mu[bracketed]))
    mu_hi = hi_mu[bracketed]
    side = np.zeros(len(bracketed), dtype=int)
    active = np.arange(len(bracketed))
    for _ in range(100):
        active = active[(x_hi[active] - x_lo[active]) > rel_tol]
        if not len(active):
            break
        xl, xh, gl, gh = x_lo[active], x_hi[active], g_lo[active], g_hi[active]
        x = xh - gh * (xh - xl) / (gh - gl)
        width = xh - xl
        bad = ~np.isfinite(x) | (x <= xl + 1e-3 * width) | (x >= xh - 1e-3 * width)
        x = np.where(bad, 0.5 * (xl + xh), x)
        mu = multipliers(bracketed[active], np.exp(x))
        g = np.log(np.abs(mu))
        up = g >= 0.0
        # Illinois: when the same end moves twice, halve the other end's value
        a_up, a_dn = active[up], active[~up]
        g_lo[a_up] = np.where(side[a_up] == 1, 0.5 * g_lo[a_up], g_lo[a_up])
        g_hi[a_dn] = np.where(side[a_dn] == -1, 0.5 * g_hi[a_dn], g_hi[a_dn])
        x_hi[a_up], g_hi[a_up], mu_hi[a_up] = x[up], g[up], mu[up]
        x_lo[a_dn], g_lo[a_dn] = x[~up], g[~up]
        side[a_up], side[a_dn] = 1, -1
        # |ln rho| this small against the bracket's slope pins the root inside rel_tol / 4
        slope = np.abs((gh - gl) / width)
        exact = np.abs(g) < 0.25 * rel_tol * slope
        x_lo[active[exact]] = x_hi[active[exact]] = x[exact]
        mu_hi[active[exact]] = mu[exact]
    depth = np.full(n, np.inf)
    mu_out = np.full(n, np.nan + 0j)
    depth[bracketed] = np.exp(0.5 * (x_lo + x_hi))
    unstable_depth = depth.copy()
    unstable_depth[bracketed] = np.exp(x_hi)
    mu_out[bracketed] = mu_hi
    at_zero = np.flatnonzero((lo == 0) & np.isfinite(hi))
    depth[at_zero] = 0.0  # unstable at any depth we could test: the structure itself is unstable
    unstable_depth[at_zero] = hi[at_zero]
    mu_out[at_zero] = hi_mu[at_zero]
    return depth, unstable_depth, mu_out


def chatter_frequencies(shapes: np.ndarray, steps: sdm.StepMatrices, mu: np.ndarray, keep: float = 0.05):
    """(dominant_hz, ((hz, relative amplitude), ...)) per batch element of `steps` at multiplier mu;
    `shapes` are the tool-tip mode shapes in the cut's axes, (2, n) or per element (B, 2, n).

    The Floquet eigenvector's tool-tip positions over one delay are divided by mu^(i/m) (the
    growth exp(lambda t_i)) and Fourier-analysed; members with amplitude >= `keep` times the
    largest are listed, largest first."""
    mu = np.asarray(mu, dtype=complex).reshape(-1)
    q = sdm.floquet_positions(steps, mu)  # (m, n, B)
    m = q.shape[0]
    shapes = np.broadcast_to(shapes, (len(mu),) + np.shape(shapes)[-2:])
    u = np.einsum("bdr,irb->idb", shapes, q)  # tool tip (m, 2, B)
    growth = mu[None, :] ** (-np.arange(m)[:, None] / m)  # exp(-lambda t_i), principal branch
    p = u * growth[:, None, :]
    c = np.fft.fft(p, axis=0) / m
    amplitude = np.sqrt(np.sum(np.abs(c) ** 2, axis=1))  # (m, B)
    harmonic = np.fft.fftfreq(m, d=1.0 / m)  # j
    tau = steps.dt_s * m
    omega_b = np.angle(mu) / tau
    out = []
    for b in range(len(mu)):
        freq = np.abs(omega_b[b] + harmonic * 2.0 * np.pi / tau[b]) / (2.0 * np.pi)
        order = np.argsort(-amplitude[:, b])
        top = amplitude[order[0], b]
        family = tuple((float(freq[j]), float(amplitude[j, b] / top)) for j in order if amplitude[j, b] >= keep * top)
        out.append((float(freq[order[0]]), family))
    return out
