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
    return branches_from_eigenvalues(w, nu.T)


def branches_from_eigenvalues(omega_rad_s: np.ndarray, nu: np.ndarray) -> ZoaBranches:
    """The branches of eigenvalues nu(w) of G(i w) H0, shape (..., len(omega)): any leading
    dimensions (branches, samples) are kept. For a structure flexible in one direction y only,
    nu = G_yy(i w) H0_yy (seed 002 eq. 12)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ww = -1.0 / nu
    ok = np.isfinite(ww) & (ww.real > 0)
    kappa = np.where(ok, ww.imag / np.where(ok, ww.real, 1.0), 0.0)
    depth = np.where(ok, ww.real * (1.0 + kappa**2) / 2.0, np.nan)
    phase = np.pi - 2.0 * np.arctan(kappa)
    return ZoaBranches(np.asarray(omega_rad_s, dtype=float), depth, phase)


def depth_at_speed(b: ZoaBranches, teeth: int, rpm: float) -> np.ndarray:
    """Critical depth (m) at one spindle speed of every branch set in `b` (leading dimensions
    of b.depth_m but the last two, e.g. Monte Carlo samples): where a lobe k passes the speed,
    w tau = phase(w) + 2 pi k with tau = 60 / (N rpm), the depth interpolated there, the least
    over lobes and branches; inf where no lobe passes."""
    tau = 60.0 / (teeth * rpm)
    h = (b.omega_rad_s * tau - b.phase_rad) / (2.0 * np.pi)  # an integer k >= 0 where lobe k passes
    d0, d1 = b.depth_m[..., :-1], b.depth_m[..., 1:]
    h0, h1 = h[..., :-1], h[..., 1:]
    k = np.ceil(np.minimum(h0, h1))
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (k - h0) / (h1 - h0)
        cross = np.isfinite(d0) & np.isfinite(d1) & (k >= 0) & (k <= np.maximum(h0, h1)) & (h1 != h0)
        depth = np.where(cross, d0 + t * (d1 - d0), np.inf)
    return depth.min(axis=(-2, -1))


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


def lobes(dyn: ToolTipDynamics, cut: Cut, rpm: np.ndarray) -> np.ndarray:
    """Critical depth (m) at each spindle speed: the lower envelope of all lobes and branches."""
    b = branches(dyn, cut)
    return np.array([depth_at_speed(b, cut.teeth, r) for r in np.ravel(rpm)]).reshape(np.shape(rpm))
