"""Modal identification from measured FRFs (seed 003 sections 4.1-4.2, seed 000 eq. 1).

Poles: least-squares complex frequency-domain estimation (LSCF, Guillaume et al. 2003), a
common-denominator rational model H_o = N_o(z) / D(z) in z = exp(i w dt) over one frequency
band, solved through its reduced normal equations for the denominator; the poles of D for model
orders 2..2N give a stabilization diagram. A pole is stable when the next lower order has one
within 1 % in frequency and 10 % in damping; clusters of stable poles found at a third or more of
the orders are the physical modes (median frequency and damping, their spread over the orders
as the uncertainty). Wide bands (robot modes at 5-40 Hz and spindle modes at kHz in one FRF)
are identified decade by decade.

Residues: least-squares frequency domain (LSFD) over the whole band with all the poles fixed,
plus lower (1 / (i w)^2) and upper (constant) residual terms per FRF. For a direct receptance a
mode with pole lambda = -zeta w_n + i w_d and residue R has modal mass 1 / (2 w_d |R|) and
modal stiffness k = w_n^2 / (2 w_d |R|); its uncertainty follows from the LSFD covariance.

FRF matrices: the same poles for all FRFs; each mode's residue matrix (times 2 i w_d) is fitted by
its best rank-one factor sigma u v^T (SVD): right and left mode shapes at the tool tip
sqrt(sigma) v and sqrt(sigma) u, normalised so that their product reproduces the residues (seed
003 eqs. 15-17); for a symmetric structure they coincide, and the x-y coupling is their product.
Written here rather than through sdypy-EMA because that package selects poles interactively or
by given frequencies, and the pipeline needs an automatic stabilization criterion and a
multi-FRF common-pole fit with residue matrices.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.optimize

from posedyn.errors import InputError, check_choice


@dataclass(frozen=True)
class IdentifiedMode:
    fn_hz: float
    zeta: float
    std_fn_hz: float
    std_zeta: float


def lscf_poles(frequency_hz: np.ndarray, H: np.ndarray, order: int) -> np.ndarray:
    """Continuous-time poles (rad/s) of a common-denominator LSCF model of `order` for the FRFs
    H (n_freq, n_out) on one band; none where the band's lines cannot determine that order (no
    more lines than the order's coefficients, or singular normal equations: a 1-10 Hz decade
    measured at 0.5 Hz has 18 lines, and orders up to 40 were a LinAlgError traceback)."""
    f = np.asarray(frequency_hz, dtype=float)
    H = np.asarray(H).reshape(len(f), -1)
    if order + 1 >= len(f):
        return np.zeros(0, dtype=complex)
    try:
        return _lscf_poles(f, H, order)
    except np.linalg.LinAlgError:
        return np.zeros(0, dtype=complex)


def _lscf_poles(f: np.ndarray, H: np.ndarray, order: int) -> np.ndarray:
    dt = 1.0 / (2.0 * f[-1])
    z = np.exp(1j * 2 * np.pi * f * dt)
    X = z[:, None] ** np.arange(order + 1)[None, :]  # (n, order + 1)
    R = np.real(X.conj().T @ X)
    Rinv = np.linalg.inv(R)
    M = np.zeros((order + 1, order + 1))
    for o in range(H.shape[1]):
        Y = -H[:, o : o + 1] * X
        S = np.real(X.conj().T @ Y)
        T = np.real(Y.conj().T @ Y)
        M += T - S.T @ Rinv @ S
    alpha = np.append(-np.linalg.solve(M[:order, :order], M[:order, order]), 1.0)
    roots = np.roots(alpha[::-1])
    lam = np.log(roots.astype(complex)) / dt
    return lam[(lam.imag > 0) & (lam.real < 0)]


def stable_modes(frequency_hz, H, max_order: int = 40, min_fraction: float = 0.33) -> list[IdentifiedMode]:
    """Stabilization diagram on one band and the modes it shows (see the module docstring)."""
    f = np.asarray(frequency_hz, dtype=float)
    orders = list(range(2, max_order + 1, 2))
    poles = [lscf_poles(f, H, n) for n in orders]
    stable = []
    for i in range(1, len(orders)):
        for lam in poles[i]:
            fn, z = abs(lam) / (2 * np.pi), -lam.real / abs(lam)
            prev = poles[i - 1]
            if len(prev) == 0:
                continue
            fp, zp = np.abs(prev) / (2 * np.pi), -prev.real / np.abs(prev)
            ok = (np.abs(fp - fn) < 0.01 * fn) & (np.abs(zp - z) < 0.10 * max(z, 1e-6))
            if ok.any() and f[0] <= fn <= f[-1] and 0 < z < 0.5:
                stable.append((fn, z))
    if not stable:
        return []
    stable.sort()
    clusters, current = [], [stable[0]]
    for fn, z in stable[1:]:
        if fn - current[-1][0] < 0.005 * fn:
            current.append((fn, z))
        else:
            clusters.append(current)
            current = [(fn, z)]
    clusters.append(current)
    modes = []
    for c in clusters:
        if len(c) >= min_fraction * (len(orders) - 1):
            fns, zs = np.array([p[0] for p in c]), np.array([p[1] for p in c])
            modes.append(IdentifiedMode(float(np.median(fns)), float(np.median(zs)), float(fns.std(ddof=1)) if len(c) > 1 else 0.0, float(zs.std(ddof=1)) if len(c) > 1 else 0.0))
    return modes


#: Modes within this factor of an inner decade edge are looked for again in a decade centred on
#: it: LSCF's poles near a band's edge do not stabilize, and a 10.0 Hz robot mode measured from
#: 1 Hz (a 100 Hz mode alike) sat on the edge of both its decades and was lost, its neighbour's k
#: fitted 3x too stiff in its place (9.6e6 N/m for 3e6).
EDGE_ZONE = 1.25


def identify_poles(frequency_hz, H, fmin_hz=None, fmax_hz=None, max_order: int = 40, points_per_band: int = 1500) -> list[IdentifiedMode]:
    """Modes over [fmin, fmax], decade by decade (each band decimated to about
    `points_per_band` frequencies)."""
    f = np.asarray(frequency_hz, dtype=float)
    H = np.asarray(H).reshape(len(f), -1)
    lo = max(fmin_hz or f[f > 0][0], f[f > 0][0])
    hi = min(fmax_hz or f[-1], f[-1])
    if not hi > lo:
        raise InputError("fmin < fmax within the measured band", got=(lo, hi), column="--fmin-hz")
    edges = [lo]
    while edges[-1] * 10 < hi:
        edges.append(edges[-1] * 10)
    edges.append(hi)
    modes: list[IdentifiedMode] = []

    def band(a, b, keep_lo, keep_hi):  # the stable modes of [0.9 a, 1.1 b] within [keep_lo, keep_hi] not found yet
        inside = np.flatnonzero((f >= a * 0.9) & (f <= b * 1.1))
        if len(inside) < 20:
            return
        idx = inside[:: max(1, len(inside) // points_per_band)]
        for m in stable_modes(f[idx], H[idx], max_order):
            if keep_lo <= m.fn_hz <= keep_hi and all(abs(m.fn_hz - o.fn_hz) > 0.01 * m.fn_hz for o in modes):
                modes.append(m)

    for a, b in zip(edges[:-1], edges[1:]):
        band(a, b, a, b)
    for e in edges[1:-1]:  # a decade centred on each inner edge, for the modes near it
        band(max(lo, e / math.sqrt(10.0)), min(hi, e * math.sqrt(10.0)), e / EDGE_ZONE, e * EDGE_ZONE)
    return sorted(modes, key=lambda m: m.fn_hz)


#: LSFD's weights: "relative" (1 / |H|, floored at 1e-3 of the peak: measurement noise grows
#: with |H|) for measured FRFs; "absolute" for noise-free computed ones (a tool change's coupled
#: FRFs), where weighting the antiresonances 1000x let the model's misfit there (59 % at 9.8 kHz
#: beside a new tool's modes) move a robot mode's residue: k 3.10e6 for 3.00e6 N/m, which a fit
#: around the mode alone and the absolute weights give exactly.
WEIGHTINGS = ("relative", "absolute")
#: The upper residual's pseudo-mode, 1 / (1 - (f / f_u)^2) beside the constant, f_u / (the band's
#: top) the best of these multiples (per FRF), refined between its neighbours. A mode just above
#: the band (a tool or spindle mode at 1.1-1.7 x its top) is not constant over it and shifts the
#: antiresonances, which the relative weights count up to 1000x: with the constant alone, a
#: receptance with 9 and 21 Hz robot and 1.5 and 2.2 kHz spindle modes fitted over 1-3000 Hz (2 %
#: noise) came out with k 16 % low for both robot modes and 31 % high at 2.2 kHz (a mode at
#: 3.6 kHz; 10 % and 11 % at 5 kHz, 12 % and 18 % with modes at 3.6 and 7 kHz); with the
#: pseudo-mode, within 0.5 % (on the grid alone 1.3 %; a mode at 2.2 kHz above a band to 2 kHz:
#: 1 %, 3.4 % on the grid). A w^2 term instead left 7 %.
UPPER_RATIOS = np.geomspace(1.05, 10.0, 24)


def lsfd(frequency_hz, H, modes: list[IdentifiedMode], weighting: str = "relative"):
    """Residues R (n_modes, n_out) with fixed poles and their standard errors, plus the residual
    terms of the modes outside the band (lower 1 / s^2; upper a constant and a pseudo-mode,
    UPPER_RATIOS); returns (R, std_R, reconstructed H). `weighting`: WEIGHTINGS."""
    check_choice("weighting", weighting, WEIGHTINGS)
    f = np.asarray(frequency_hz, dtype=float)
    H = np.asarray(H).reshape(len(f), -1)
    s = 1j * 2 * np.pi * f
    lam = np.array([-m.zeta * 2 * np.pi * m.fn_hz + 1j * 2 * np.pi * m.fn_hz * math.sqrt(1 - m.zeta**2) for m in modes])
    # unknowns per FRF: Re R_r, Im R_r for every mode, lower residual, upper constant and pseudo-mode (real)
    cols = []
    for l in lam:
        cols.append(1 / (s - l) + 1 / (s - l.conj()))  # multiplies Re R
        cols.append(1j / (s - l) - 1j / (s - l.conj()))  # multiplies Im R
    with np.errstate(divide="ignore", invalid="ignore"):
        lower = np.where(f > 0, 1 / s**2, 0.0)
    cols += [lower, np.ones_like(s)]
    A = np.column_stack(cols + [np.zeros(len(f))])  # the last column: the upper pseudo-mode
    Ar = np.vstack([A.real, A.imag])
    R = np.empty((len(modes), H.shape[1]), dtype=complex)
    std = np.empty((len(modes), H.shape[1]))
    fit = np.empty_like(H)
    scale = np.abs(H).max(axis=0)
    for o in range(H.shape[1]):
        w = 1.0 / np.maximum(np.abs(H[:, o]), 1e-3 * scale[o]) if weighting == "relative" else np.ones(len(f))  # relative: noise ~ |H|
        Aw = Ar * np.concatenate([w, w])[:, None]
        b = np.concatenate([H[:, o].real * w, H[:, o].imag * w])
        Q, _ = np.linalg.qr(Aw[:, :-1])  # the other terms' span: each f_u costs a projection, not a solve
        r0 = b - Q @ (Q.T @ b)

        def misfit(ln_ratio):  # |residual|^2 with the pseudo-mode added: r0's part along its direction off Q removed
            p = np.zeros(len(b))
            p[: len(f)] = w * _pseudo_mode(f, math.exp(ln_ratio))  # real: its imaginary rows stay 0
            p -= Q @ (Q.T @ p)
            return float(r0 @ r0 - (p @ r0) ** 2 / max(p @ p, 1e-300))

        grid = np.log(UPPER_RATIOS)
        j = int(np.argmin([misfit(g) for g in grid]))
        ln_ratio = scipy.optimize.minimize_scalar(misfit, bounds=(grid[max(j - 1, 0)], grid[min(j + 1, len(grid) - 1)]), method="bounded",
                                                  options={"xatol": 1e-4}).x
        A[:, -1] = _pseudo_mode(f, math.exp(ln_ratio))
        Aw[: len(f), -1] = w * A[:, -1].real
        x, *_ = np.linalg.lstsq(Aw, b, rcond=None)
        residual = b - Aw @ x
        dof = max(len(b) - len(x), 1)
        cov = np.linalg.pinv(Aw.T @ Aw) * (residual @ residual / dof)
        R[:, o] = x[0 : 2 * len(modes) : 2] + 1j * x[1 : 2 * len(modes) : 2]
        var = np.diag(cov)
        std[:, o] = np.sqrt(var[0 : 2 * len(modes) : 2] + var[1 : 2 * len(modes) : 2])
        fit[:, o] = A @ x
    return R, std, fit


def _pseudo_mode(f: np.ndarray, ratio: float) -> np.ndarray:
    """1 / (1 - (f / f_u)^2), f_u = ratio x the band's top (`UPPER_RATIOS`)."""
    return 1.0 / (1.0 - (f / (ratio * f.max())) ** 2)


def stiffness_rel_std(modes: list[IdentifiedMode], R: np.ndarray, std_R: np.ndarray) -> np.ndarray:
    """Relative std (n_modes, n_out) of the modal stiffnesses k = w_n^2 / (2 w_d |R|) of an LSFD
    fit (`lsfd`: residues R with standard errors std_R at fixed poles): the residue's error and
    twice fn's relative std. Measured on 12 seeds of 2 % noise (coupled 9 and 21 Hz robot modes,
    1.5 and 2.2 kHz spindle modes; direct and matrix fits alike): the robot modes' true stiffness
    1.2-3.7 stds off (rms; the residue's error at fixed poles leaves part out: moving the pole by
    its std and fitting again adds little), the spindle modes' 0.2-0.3 (the relative weighting
    overstates their residues' error)."""
    fn = np.array([m.fn_hz for m in modes])[:, None]
    std_fn = np.array([m.std_fn_hz for m in modes])[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.abs(R) > 0, np.hypot(std_R / np.abs(R), 2 * std_fn / fn), np.inf)


def direct_modal_parameters(frequency_hz, h, fmin_hz=None, fmax_hz=None, max_order: int = 40, weighting: str = "relative"):
    """fn, zeta, k (with stds) of every mode of one direct receptance; returns a list of dicts."""
    modes = identify_poles(frequency_hz, h, fmin_hz, fmax_hz, max_order)
    if not modes:
        raise InputError("an FRF with at least one identifiable mode in the band", got="none found", column="frf")
    R, std_R, _ = lsfd(frequency_hz, h, modes, weighting)
    rel = stiffness_rel_std(modes, R, std_R)[:, 0]
    out = []
    for m, r, rel_k in zip(modes, R[:, 0], rel):
        wn = 2 * np.pi * m.fn_hz
        wd = wn * math.sqrt(1 - m.zeta**2)
        k = wn**2 / (2 * wd * abs(r))
        out.append({"fn_hz": m.fn_hz, "zeta": m.zeta, "k_n_per_m": k, "std_fn_hz": m.std_fn_hz, "std_zeta": m.std_zeta, "std_k_n_per_m": k * rel_k})
    return out


def matrix_modal_fit(frequency_hz, H: dict, fmin_hz=None, fmax_hz=None, max_order: int = 40, weighting: str = "relative"):
    """Common-pole fit of an FRF matrix {'h_xx', 'h_xy', 'h_yx', 'h_yy'} (receptances):
    modes with right/left tool-tip shapes (x, y) in 1/sqrt(kg), the stds of fn and zeta (scatter
    over the stable model orders) and the relative stds of the direct stiffnesses k_xx, k_yy
    (`rel_std_k`, `stiffness_rel_std` of the direct residues), and the reconstructed matrix."""
    names = ["h_xx", "h_xy", "h_yx", "h_yy"]
    missing = [n for n in names if n not in H]
    if missing:
        raise InputError("the four FRFs h_xx, h_xy, h_yx, h_yy", got=f"missing {missing}", column=missing[0])
    stack = np.column_stack([H[n] for n in names])
    modes = identify_poles(frequency_hz, stack, fmin_hz, fmax_hz, max_order)
    R, std_R, fit = lsfd(frequency_hz, stack, modes, weighting)
    rel = stiffness_rel_std(modes, R, std_R)
    out = []
    for m, r, std_r, rel_k in zip(modes, R, std_R, rel):
        wd = 2 * np.pi * m.fn_hz * math.sqrt(1 - m.zeta**2)
        C = (r * 2j * wd).reshape(2, 2)  # the pole's residue matrix; of a real mode phi_out phi_in^T
        u, sigma, vt = np.linalg.svd(C.real)
        # one rank-one mode, or two where x and y share the pole (an x and a y spindle mode at one
        # frequency: the first factor alone dropped one of them, h_yy's largest peak, silently)
        pairs = [0, 1] if _second_factor_needed(C, (std_r * 2 * wd).reshape(2, 2)) else [0]
        for k in pairs:
            right, left = math.sqrt(sigma[k]) * vt[k], math.sqrt(sigma[k]) * u[:, k]
            if right @ left < 0:  # a direct term is positive: make both factors point the same way
                left = -left
            if right[np.argmax(np.abs(right))] < 0:
                right, left = -right, -left
            out.append({"fn_hz": m.fn_hz, "zeta": m.zeta, "shape_right": right.tolist(), "shape_left": left.tolist(),
                        "std_fn_hz": m.std_fn_hz, "std_zeta": m.std_zeta, "rel_std_k": [float(rel_k[0]), float(rel_k[3])]})
    return out, {n: fit[:, i] for i, n in enumerate(names)}


#: A pole's residue matrix holds two modes where its best complex rank-one factor leaves more
#: than SECOND_FACTOR of a direct term (x x or y y) out, and more than SECOND_SIGMAS of that
#: term's standard error (`matrix_modal_fit`). One mode, real or complex (non-proportional
#: damping, whose real part alone can be rank two), has a rank-one residue up to noise; a mode
#: seen in one direction only has a direct term of noise in the other.
SECOND_FACTOR = 0.1
SECOND_SIGMAS = 5.0


def _second_factor_needed(C: np.ndarray, std_C: np.ndarray) -> bool:
    """Whether the 2 x 2 complex residue matrix C (standard errors std_C) is more than one mode."""
    u, sigma, vh = np.linalg.svd(C)
    missed = np.abs(np.diag(C - sigma[0] * np.outer(u[:, 0], vh[0])))
    return bool(np.any((missed > SECOND_FACTOR * np.abs(np.diag(C))) & (missed > SECOND_SIGMAS * np.diag(std_C))))


def complex_modes_frf(fn_hz, zeta, left, right, omega_rad_s) -> np.ndarray:
    """FRF matrix (f, p, q) of complex modes (seed 003's MDOF model, its Table B1 form):
    H = sum_r L_r R_r^T / (i w - lambda_r) + conj(L_r R_r^T) / (i w - conj(lambda_r)),
    lambda_r = -zeta_r w_r + i w_r sqrt(1 - zeta_r^2); `left` (modes, p), `right` (modes, q)."""
    w = np.asarray(omega_rad_s, dtype=float)[:, None, None]
    out = 0.0
    for fn, z, l, r in zip(fn_hz, zeta, np.asarray(left, complex), np.asarray(right, complex)):
        wn = 2 * math.pi * fn
        lam = -z * wn + 1j * wn * math.sqrt(1 - z * z)
        residue = np.outer(l, r)
        out = out + residue / (1j * w - lam) + np.conj(residue) / (1j * w - np.conj(lam))
    return out
