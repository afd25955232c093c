"""Zeroth-order approximation (Altintas and Budak; seed 002 eqs. 9-13, seed 001 eqs. 1-4).

Keeping only the mean H0 of the cutting-force matrix, the characteristic equation at a chatter
frequency w is det(I + a (1 - exp(-i w tau)) G(i w) H0) = 0. With nu an eigenvalue of G H0 and
w = -1 / nu = w_R + i w_I:

    a = w_R (1 + kappa^2) / 2,   kappa = w_I / w_R = sin(w tau) / (1 - cos(w tau)),
    w tau = pi - 2 arctan(kappa) + 2 pi k   (k = 0, 1, 2, ... lobe number),
    rpm = 60 / (N tau),

valid where w_R > 0. For one mode in one direction this is seed 002 eq. 12,
a_lim = 1 / (2 h (-Re G)), and its minimum over w, the absolute (speed-independent) limit, is
2 k zeta (1 + zeta) / h. (Signs: H here is -(Kt / 2) times the directional matrix of seed 002.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from posedyn.dynamics import ToolTipDynamics
from posedyn.stability.cutting import Cut, mean_force_matrix


@dataclass(frozen=True, eq=False)
class ZoaBranches:
    """Critical depth a(w) (m) of each eigenvalue branch on a chatter-frequency grid w (rad/s);
    NaN where no positive depth exists."""

    omega_rad_s: np.ndarray
    depth_m: np.ndarray  # (branches, len(omega))
    phase_rad: np.ndarray  # w tau of lobe k = 0, in (0, 2 pi)


def frequency_grid(dyn: ToolTipDynamics, points_per_mode: int = 4000) -> np.ndarray:
    """Chatter frequencies to scan (rad/s): a log grid from 0.2 to 3 times the mode band,
    dense (about 10 half-power bandwidths each side) around every mode."""
    wn, zeta = dyn.wn_rad_s, dyn.zeta
    parts = [np.geomspace(0.2 * wn.min(), 3.0 * wn.max(), points_per_mode)]
    for w, z in zip(wn, zeta):
        half = max(10.0 * z, 0.02) * w
        parts.append(np.linspace(max(w - half, 1e-3 * w), w + half, points_per_mode))
    return np.unique(np.concatenate(parts))


def branches(dyn: ToolTipDynamics, cut: Cut, omega_rad_s: np.ndarray | None = None) -> ZoaBranches:
    w = frequency_grid(dyn) if omega_rad_s is None else np.asarray(omega_rad_s, dtype=float)
    rotated = dyn.rotated(np.deg2rad(cut.feed_angle_deg))
    nu = _track(np.linalg.eigvals(rotated.frf(w) @ mean_force_matrix(cut)))  # (len, 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        ww = -1.0 / nu
    ok = np.isfinite(ww) & (ww.real > 0)
    kappa = np.where(ok, ww.imag / np.where(ok, ww.real, 1.0), 0.0)
    depth = np.where(ok, ww.real * (1.0 + kappa**2) / 2.0, np.nan)
    phase = np.pi - 2.0 * np.arctan(kappa)
    return ZoaBranches(w, depth.T, phase.T)


def _track(nu: np.ndarray) -> np.ndarray:
    """Order the two eigenvalues at each frequency so that each column is a continuous branch
    (LAPACK returns them in no particular order)."""
    nu = nu.copy()
    for i in range(1, len(nu)):
        keep = abs(nu[i, 0] - nu[i - 1, 0]) + abs(nu[i, 1] - nu[i - 1, 1])
        swap = abs(nu[i, 1] - nu[i - 1, 0]) + abs(nu[i, 0] - nu[i - 1, 1])
        if swap < keep:
            nu[i] = nu[i, ::-1]
    return nu


def absolute_limit_m(dyn: ToolTipDynamics, cut: Cut) -> float:
    """Speed-independent limit: min over chatter frequencies of the ZOA depth (grid, then a
    bounded scalar minimisation around the grid minimum)."""
    b = branches(dyn, cut)
    if not np.isfinite(b.depth_m).any():
        return float("inf")
    branch, index = np.unravel_index(np.nanargmin(b.depth_m), b.depth_m.shape)
    w = b.omega_rad_s
    lo, hi = w[max(index - 1, 0)], w[min(index + 1, len(w) - 1)]

    def depth(x):
        d = branches(dyn, cut, np.array([x])).depth_m[:, 0]
        return np.nanmin(d) if np.isfinite(d).any() else np.inf

    if hi > lo:
        result = minimize_scalar(depth, bounds=(lo, hi), method="bounded", options={"xatol": 1e-10 * hi})
        return float(min(result.fun, b.depth_m[branch, index]))
    return float(b.depth_m[branch, index])


def lobes(dyn: ToolTipDynamics, cut: Cut, rpm: np.ndarray, max_lobes: int = 200) -> np.ndarray:
    """Critical depth (m) at each spindle speed: the lower envelope of all lobes and branches."""
    rpm = np.asarray(rpm, dtype=float)
    b = branches(dyn, cut)
    out = np.full(rpm.shape, np.inf)
    for depth, phase in zip(b.depth_m, b.phase_rad):
        for k in range(max_lobes):
            tau = (phase + 2.0 * np.pi * k) / b.omega_rad_s
            lobe_rpm = 60.0 / (cut.teeth * tau)
            reach = np.where(np.isfinite(depth), lobe_rpm, np.nan)
            if not np.isfinite(reach).any() or np.nanmax(reach) < rpm.min():
                break
            if np.nanmin(reach) > rpm.max():
                continue
            for segment in _monotonic_segments(lobe_rpm, depth):
                x, y = lobe_rpm[segment], depth[segment]
                order = np.argsort(x)
                x, y = x[order], y[order]
                inside = (rpm >= x[0]) & (rpm <= x[-1])
                if inside.any():
                    out[inside] = np.minimum(out[inside], np.interp(rpm[inside], x, y))
    return out


def _monotonic_segments(x: np.ndarray, y: np.ndarray):
    """Slices over which x is strictly monotonic and x, y are finite (lobe pieces to interpolate)."""
    finite = np.isfinite(x) & np.isfinite(y)
    d = np.diff(x)
    good = finite[:-1] & finite[1:] & (d != 0)
    direction = np.sign(d)
    starts = good.copy()
    starts[1:] &= ~good[:-1] | (direction[1:] != direction[:-1])
    ends = good.copy()
    ends[:-1] &= ~good[1:] | (direction[1:] != direction[:-1])
    for first, last in zip(np.flatnonzero(starts), np.flatnonzero(ends)):
        yield slice(first, last + 2)
