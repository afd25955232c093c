"""How deep a cut can go before a surface perturbation grows from one pass to the next, where
only the surface remembers the last pass (`critical.free_flight_decay`).

Where every mode's vibration dies out between cuts, each pass starts from rest and the chip
depends only on the surface the previous pass left. Over the cut window phi_st < phi < phi_ex
of a tooth (one tooth in the cut: there is free flight), with the modal equations of `floquet`,

    q'' + C q' + K q + a W(t) q = a Phi_R^T f(phi) h_j(phi),   q = q' = 0 at phi_st,
    h_(j+1)(phi) = n(phi) . Phi_L q(t),

n = (sin phi, cos phi) the chip direction and f = (Kt cos phi + Kn sin phi, -Kt sin phi +
Kn cos phi) the force per unit chip (H = f n^T, `cutting`; seed 004 eq. 6), so h_(j+1) =
L(a) h_j. L is a Volterra operator (causal, no direct term: a mass does not move at once): its
spectrum is {0}, the asymptotic (Floquet) boundary is set by the e^-efolds of vibration left at
the next entry and lies far above the depths where perturbations grow, and ||L^k|| can grow by
orders of magnitude over tens of passes before it decays. No perturbation of the surface grows
from one pass to the next (in the L2 norm over the cut window) while ||L(a)||_2 <= 1, and the
worst one (L's top right singular vector) grows above: `no_growth_depth` is that depth.

Discretization: N equal sub-steps of the window; on each, W by its exact average (`cutting`),
the input f by its average and h_j constant, the surface sampled at the sub-step's middle
(half-step exponentials of the state augmented with the input): second order in the sub-step
(one 3 kHz mode, 300 rpm: 4.6 / 1.1 / 0.3 % at 10 / 21 / 42 samples per vibration period).
The surface carries the vibration's marks, so N follows the fastest relevant mode
(SAMPLES_PER_PERIOD), and the depth is computed at N and 2 N: their difference is the estimate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg

from posedyn.dynamics import ToolTipDynamics
from posedyn.stability import sdm
from posedyn.stability.cutting import Cut, engaged_integral
from posedyn.stability.floquet import FloquetCharacteristic, relevant_modes

#: Surface samples per period of the fastest relevant mode at the coarser of the two resolutions.
SAMPLES_PER_PERIOD = 16
#: Fewest surface samples over the cut window.
MIN_SAMPLES = 64
#: Most surface samples at the finer resolution (L is N x N: 3072 is 75 MB); above it the
#: depth is not computed.
MAX_SAMPLES = 3072
#: |ln ||L||| at which the depth counts as found.
GAIN_TOL = 1e-5


@dataclass(frozen=True)
class NoGrowthDepth:
    """The deepest cut at which no surface perturbation grows from one pass to the next (m; NaN
    where not computed), the relative difference between the two resolutions, and the finer
    resolution's surface samples over the cut window."""

    depth_m: float
    rel_error_estimate: float
    samples: int


def surface_map(dyn: ToolTipDynamics, cut: Cut, rpm: float, depth_m: float, samples: int) -> np.ndarray:
    """L(a), (samples, samples): the surface h_(j+1) at the middles of `samples` equal sub-steps of
    the cut window from h_j at the same points (lower triangular: causal)."""
    return _pass_map(_pass_parts(dyn, cut, rpm, samples), depth_m)


@dataclass(frozen=True)
class _PassParts:
    """What L(a) needs at one resolution that does not depend on the depth a (balanced state of
    `floquet`): A0, the sub-steps' W / a and input f / a, state -> surface rows, half sub-step (s)."""

    A0: np.ndarray
    W: np.ndarray  # (samples, n, n)
    drive: np.ndarray  # (samples, n)
    out: np.ndarray  # (samples, 2n)
    half_step_s: float


def _pass_parts(dyn: ToolTipDynamics, cut: Cut, rpm: float, samples: int) -> _PassParts:
    start, exit_ = cut.engagement_rad
    edges = np.linspace(start, exit_, samples + 1)
    lo, hi = edges[:-1], edges[1:]
    middle = 0.5 * (lo + hi)
    char = FloquetCharacteristic(dyn, cut, 1.0)  # (its balanced state and W; its segments unused)
    H = engaged_integral(cut, lo, hi) / (hi - lo)[:, None, None]
    mean_cos = (np.sin(hi) - np.sin(lo)) / (hi - lo)
    mean_sin = (np.cos(lo) - np.cos(hi)) / (hi - lo)
    f = np.stack([cut.kt_pa * mean_cos + cut.kn_pa * mean_sin, -cut.kt_pa * mean_sin + cut.kn_pa * mean_cos], -1)
    return _PassParts(
        A0=char.A0,
        W=np.einsum("ir,sij,jq->srq", char.force_shapes, H, char.shapes) / char.scale[None, None, :],
        drive=f @ char.force_shapes,
        out=np.stack([np.sin(middle), np.cos(middle)], -1) @ char.S,
        half_step_s=(exit_ - start) / samples / (2.0 * math.pi * rpm / 60.0) / 2.0,
    )


def _pass_map(parts: _PassParts, depth_m: float) -> np.ndarray:
    samples, n = parts.drive.shape
    n2 = 2 * n
    generator = np.zeros((samples, n2 + 1, n2 + 1))
    generator[:, :n2, :n2] = parts.A0
    generator[:, n:n2, :n] -= depth_m * parts.W
    generator[:, n:n2, n2] = depth_m * parts.drive
    augmented = sdm.expm_batched(generator * parts.half_step_s)
    E, g = augmented[:, :n2, :n2], augmented[:, :n2, n2]
    Z = np.zeros((n2, samples))  # state response to each surface sample so far
    L = np.zeros((samples, samples))
    for i in range(samples):
        Zi = Z[:, : i + 1]
        Zi[:] = E[i] @ Zi
        Zi[:, i] += g[i]
        L[i, : i + 1] = parts.out[i] @ Zi
        Zi[:] = E[i] @ Zi
        Zi[:, i] += g[i]
    return L


def pass_gain(L: np.ndarray, vector: bool = False):
    """||L||_2, the largest growth of the surface's L2 norm in one pass (and, with `vector`, the
    surface that grows most, unit norm)."""
    start = np.ones(L.shape[0])  # (ARPACK's random start otherwise)
    if not vector:
        return float(scipy.sparse.linalg.svds(L, k=1, tol=1e-10, v0=start, return_singular_vectors=False)[0])
    _, s, vt = scipy.sparse.linalg.svds(L, k=1, tol=1e-10, v0=start, return_singular_vectors="vh")
    return float(s[0]), vt[0] * np.sign(vt[0][np.argmax(np.abs(vt[0]))])


def surface_samples(dyn: ToolTipDynamics, cut: Cut, rpm: float) -> int:
    """The coarser resolution: SAMPLES_PER_PERIOD per period of the fastest relevant mode
    (`floquet.relevant_modes`: a stiff 10 kHz mode that barely moves the tool leaves no marks to
    resolve) over the window's duration, at least MIN_SAMPLES."""
    start, exit_ = cut.engagement_rad
    window_s = (exit_ - start) / (2.0 * math.pi * rpm / 60.0)
    return max(MIN_SAMPLES, int(math.ceil(SAMPLES_PER_PERIOD * float(np.max(dyn.fn_hz[relevant_modes(dyn)])) * window_s)))


def no_growth_depth(dyn: ToolTipDynamics, cut: Cut, rpm: float, upper_m: float) -> NoGrowthDepth:
    """The depth a with ||L(a)||_2 = 1 (`surface_map`), at most `upper_m` (the critical depth: the
    asymptotic boundary; where ||L|| <= 1 there, it is the answer), at `surface_samples` and
    twice as many. Not computed (NaN) where the finer one exceeds MAX_SAMPLES or a tooth never
    leaves the cut."""
    start, exit_ = cut.engagement_rad
    samples = surface_samples(dyn, cut, rpm)
    if 2 * samples > MAX_SAMPLES or exit_ - start >= 2.0 * math.pi / cut.teeth or not upper_m > 0:
        return NoGrowthDepth(math.nan, math.inf, 2 * samples)
    depths = []
    guess = 0.1 * upper_m if math.isfinite(upper_m) else 1e-3  # (L is about proportional to the depth: any start will do)
    for count in (samples, 2 * samples):
        depth = _unit_gain(_pass_parts(dyn, cut, rpm, count), guess, upper_m)
        depths.append(depth)
        guess = depth
    return NoGrowthDepth(depths[1], abs(depths[1] - depths[0]) / depths[1], 2 * samples)


def _unit_gain(parts: _PassParts, guess, upper):
    """Secant on ln ||L(a)|| against ln a (nearly linear: L is about proportional to a below the
    boundary) from `guess`, capped at `upper`."""
    def log_gain(a):
        return math.log(pass_gain(_pass_map(parts, a)))

    x0, y0 = math.log(guess), log_gain(guess)
    x1 = x0 - y0  # slope 1
    for _ in range(20):
        x1 = min(x1, math.log(upper))
        y1 = log_gain(math.exp(x1))
        if abs(y1) < GAIN_TOL or (x1 >= math.log(upper) and y1 < 0):
            return math.exp(x1)
        slope = (y1 - y0) / (x1 - x0) if x1 != x0 else 1.0
        x0, y0, x1 = x1, y1, x1 - y1 / (slope if slope > 0.1 else 1.0)
    return math.exp(x1)
