"""The semi-discretization written out straightforwardly, as seed 004 states it (eqs. 9-12):
a dense (2n + m n)-square D_i per step, their product, LAPACK eigenvalues.

Kept as the independent baseline that tests and `bench/` compare the structured engine
(`sdm`) with: every matrix here comes from scipy's expm and an explicit solve, nothing is shared
with the closed forms and recursions of `sdm` except the averaged cutting-force matrices.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from posedyn.dynamics import ToolTipDynamics
from posedyn.stability.cutting import Cut, interval_force_matrices


def monodromy(dyn: ToolTipDynamics, cut: Cut, rpm: float, depth_m: float, steps: int) -> np.ndarray:
    """Psi = D_{m-1} ... D_0 for E_i = [z_i; q_{i-1}; ...; q_{i-m}], zeroth order (w_a = w_b = 1/2)."""
    n, m = dyn.n_modes, steps
    turned = dyn.rotated(np.deg2rad(cut.feed_angle_deg))
    H = interval_force_matrices(cut, m)
    dt = float(cut.tooth_period_s(rpm)) / m
    wn, zeta = dyn.wn_rad_s, dyn.zeta
    size = 2 * n + m * n
    psi = np.eye(size)
    for i in range(m):
        W = turned.force_shapes.T @ H[i] @ turned.shapes  # Phi_R^T H_i Phi_L
        A = np.zeros((2 * n, 2 * n))
        A[:n, n:] = np.eye(n)
        A[n:, :n] = -np.diag(wn**2) - depth_m * W
        A[n:, n:] = -np.diag(2 * zeta * wn)
        B = np.zeros((2 * n, n))
        B[n:] = depth_m * W
        P = scipy.linalg.expm(A * dt)
        R = np.linalg.solve(A.T, (P - np.eye(2 * n)).T).T @ B  # (exp(A dt) - I) A^-1 B
        D = np.zeros((size, size))
        D[: 2 * n, : 2 * n] = P
        D[: 2 * n, size - 2 * n : size - n] += 0.5 * R  # w_a R q_{i-m+1}
        D[: 2 * n, size - n :] += 0.5 * R  # w_b R q_{i-m}
        D[2 * n : 3 * n, :n] = np.eye(n)  # q_i enters the history
        D[3 * n :, 2 * n : size - n] = np.eye((m - 1) * n)  # the history shifts by one slot
        psi = D @ psi
    return psi


def spectral_radius(dyn: ToolTipDynamics, cut: Cut, rpm: float, depth_m: float, steps: int) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(monodromy(dyn, cut, rpm, depth_m, steps)))))
