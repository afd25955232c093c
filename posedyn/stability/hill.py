"""Seeds for the Floquet search from Hill's method, the multi-frequency solution of Budak and
Altintas (1998; seed 002 section 2 cites it as [52], of which the zeroth order keeps the mean
term only).

Why: the zeroth-order crossings (`floquet.zoa_seeds`, the mean force H0) lie near the modes.
Where the structure has modes at or below a few tooth-passing frequencies (robot modes of 10-20
Hz at 2000 rpm, an absorber at 63 Hz), the interrupted cut couples the chatter frequency w with
w +- j w_T, and the lowest boundary point can sit between the modes, where the mean force has no
crossing at all (the sweep's absorber poses: 9.9 mm at 25.9 Hz between robot modes at 14-16 Hz
and the absorber at 63 Hz; the zeroth order's lowest crossing 14.8 mm at a spindle mode). The
winding count found those and the repair brought the answer down, at 10-50x the cost of a solve.

The equation. With H(t) = sum_k H_k exp(i k w_T t) and a Floquet solution
x(t) = exp(i w t) sum_j x_j exp(i j w_T t), the tool-tip milling equation gives, harmonic by
harmonic (exp(-i (w + j w_T) tau) = exp(-i w tau) as w_T tau = 2 pi),

    x_j = -a (1 - exp(-i w tau)) G(w + j w_T) sum_k H_(j - k) x_k,

so a = -1 / ((1 - exp(-i w tau)) Lambda) for every eigenvalue Lambda of the block matrix
[G(w + j w_T) H_(j - k)], j, k = -J .. J (J = 0: the zeroth order). A boundary point is where a
is real and positive. The harmonics are truncated (the force jumps at tooth entry and exit, so
H_k falls off like 1 / k), which is why this only seeds the search: every seed is refined by
Newton on the exact characteristic equation and the answer is verified by the winding count.
"""

from __future__ import annotations

import numpy as np

from posedyn.stability.cutting import Cut, force_matrix

#: Harmonics either side of the chatter frequency (J).
HARMONICS = 2
#: Modes up to this many tooth-passing frequencies are resolved by the harmonics (J + 1 / 2).
REACH = HARMONICS + 0.5
#: Gauss-Legendre nodes per smooth interval of H over one tooth pitch (H is a trigonometric
#: polynomial of low degree between the entry and exit angles: exact to round-off).
QUADRATURE_NODES = 16
#: Frequency grid on (0, w_T / 2]: uniform points, plus bands of +-BAND_ZETAS zeta w around each
#: mode folded into that range, POINTS_PER_ZETA points per zeta w.
UNIFORM_POINTS = 48
BAND_ZETAS = 6.0
POINTS_PER_ZETA = 3.0


def force_harmonics(cut: Cut, count: int) -> np.ndarray:
    """H_k for k = -count .. count, (2 count + 1, 2, 2): H(t) = sum_k H_k exp(i k w_T t), i.e.
    H_k = (N / 2 pi) int_0^(2 pi / N) H(phi) exp(-i k N phi) d phi over one tooth pitch, by
    Gauss-Legendre quadrature on the intervals between the teeth's entry and exit angles."""
    pitch = 2.0 * np.pi / cut.teeth
    st, ex = cut.engagement_rad
    events = np.mod(np.array([st - j * pitch for j in range(cut.teeth)] + [ex - j * pitch for j in range(cut.teeth)]), pitch)
    edges = np.unique(np.concatenate([[0.0, pitch], events]))
    x, w = np.polynomial.legendre.leggauss(QUADRATURE_NODES)
    lo, hi = edges[:-1], edges[1:]
    phi = (0.5 * (lo + hi)[:, None] + 0.5 * (hi - lo)[:, None] * x[None, :]).ravel()
    weight = (0.5 * (hi - lo)[:, None] * w[None, :]).ravel()
    k = np.arange(-count, count + 1)
    phase = np.exp(-1j * k[:, None] * cut.teeth * phi[None, :]) * weight[None, :]
    return np.einsum("kp,pij->kij", phase, force_matrix(cut, phi)) / pitch


def frequency_grid(free_lam: np.ndarray, w_t: float) -> np.ndarray:
    """Chatter frequencies (rad/s) on (0, w_T / 2] for `hill_seeds`: UNIFORM_POINTS plus the
    bands around every mode resonance w_r seen through a harmonic, +-w_r - j w_T, |j| <= J."""
    top = 0.5 * w_t
    parts = [np.linspace(top / UNIFORM_POINTS, top, UNIFORM_POINTS)]
    lam = free_lam[free_lam.imag > 0]
    for w_r, size, decay in zip(lam.imag, np.abs(lam), -lam.real):
        zeta_w = max(float(decay), 1e-3 * size)
        half = max(BAND_ZETAS * zeta_w, 0.02 * size)
        for centre in np.concatenate([w_r - np.arange(-HARMONICS, HARMONICS + 1) * w_t, -w_r - np.arange(-HARMONICS, HARMONICS + 1) * w_t]):
            if centre + half > 0.0 and centre - half < top:
                count = int(min(2000, max(16, np.ceil(2.0 * half / zeta_w * POINTS_PER_ZETA))))
                parts.append(np.linspace(centre - half, centre + half, count))
    grid = np.unique(np.concatenate(parts))
    return grid[(grid > 0.0) & (grid <= top)]


def hill_seeds(frf, free_lam: np.ndarray, cut: Cut, tau: float):
    """(depth m, theta = w tau in (0, pi]) of the boundary points of Hill's method with HARMONICS
    harmonics, where the structure has a mode within REACH tooth-passing frequencies (empty
    arrays otherwise: the zeroth-order seeds suffice). `frf(omega)` -> tool-tip receptance
    (..., 2, 2) of the (feed-turned) structure, `free_lam` its free eigenvalues (rad/s). Crossings
    are sign changes of Im a along each eigenvalue branch with Re a > 0 (branches followed from
    one frequency to the next by the nearest eigenvalue)."""
    w_t = 2.0 * np.pi / tau
    if not np.any((free_lam.imag > 0) & (np.abs(free_lam) < REACH * w_t)):
        return np.zeros(0), np.zeros(0)
    omega = frequency_grid(free_lam, w_t)
    j = np.arange(-HARMONICS, HARMONICS + 1)
    P = len(j)
    G = frf(omega[:, None] + j[None, :] * w_t)  # (W, P, 2, 2)
    Hk = force_harmonics(cut, 2 * HARMONICS)
    Hblock = Hk[(j[:, None] - j[None, :]) + 2 * HARMONICS]  # (P, P, 2, 2): H_(j - k)
    with np.errstate(invalid="ignore"):
        B = np.matmul(G[:, :, None], Hblock[None]).transpose(0, 1, 3, 2, 4).reshape(len(omega), 2 * P, 2 * P)
    finite = np.all(np.isfinite(B), axis=(1, 2))  # a grid point on an undamped resonance
    omega, B = omega[finite], B[finite]
    if len(omega) < 2:
        return np.zeros(0), np.zeros(0)
    lam = np.linalg.eigvals(B)
    # follow each branch: the nearest eigenvalue at the next frequency
    nxt = np.argmin(np.abs(lam[1:, None, :] - lam[:-1, :, None]), axis=2)  # (W - 1, 2P)
    with np.errstate(all="ignore"):
        a = -1.0 / ((1.0 - np.exp(-1j * omega * tau))[:, None] * lam)
    rows = np.arange(1, len(omega))[:, None]
    a0, a1 = a[:-1], a[rows, nxt]
    tiny = np.abs(lam) <= 1e-9 * np.abs(lam).max()
    with np.errstate(invalid="ignore"):
        cross = (np.sign(a0.imag) != np.sign(a1.imag)) & (a0.real > 0) & (a1.real > 0) & np.isfinite(a0) & np.isfinite(a1)
        cross &= np.abs(a1 - a0) <= 0.5 * np.maximum(np.abs(a0), np.abs(a1))  # not a jump through infinity
    cross &= ~tiny[:-1] & ~tiny[rows, nxt]
    i, b = np.nonzero(cross)
    if not len(i):
        return np.zeros(0), np.zeros(0)
    t = a0[i, b].imag / (a0[i, b].imag - a1[i, b].imag)
    depth = a0[i, b].real + t * (a1[i, b].real - a0[i, b].real)
    w = omega[i] + t * (omega[i + 1] - omega[i])
    order = np.argsort(depth)
    return depth[order], (w * tau)[order]
