"""Critical depth and chatter frequency of many structures at one spindle speed (pose sweeps).

`StabilityModel` batches over speeds and depths for one structure. A workspace sweep asks the
opposite question: one cut and one speed, thousands of structures (one per pose). Structures
with the same number of modes are stacked here, so that the step matrices, the eigenvalue
solver and the depth bracketing run once over the whole batch (the same semi-discretization,
`sdm.stacked_step_matrices`, and the same bracketing, `chatter.critical_crossing`, as `StabilityModel`).

The cutting force sees the structure only through the tool-tip displacement u = Phi_L q (two
coordinates), so the monodromy matrix is formed on [z_0; u_{-1}; ...; u_{-m}] (N = 2n + 2m)
instead of on the modal history (N = 2n + n m): the nonzero multipliers are the same (the two
maps are products A B and B A of the same factors) and LAPACK's dense eigensolver on the small
matrix is the fastest exact route for a batch (n = 10, m = 20: N = 60 instead of 220).

The bracketing ladder starts at a closed-form estimate of each structure's absolute limit, the
smallest single-mode zeroth-order limit a_r = 2 zeta_r (1 + zeta_r) w_r^2 / h_r with
h_r = phi_r^T H0 phi_r the mode's share of the mean force matrix (mass-normalised modes), instead
of a ZOA scan per pose; the ladder widens by itself when the crossing lies outside it.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError
from posedyn.stability import sdm
from posedyn.stability.cutting import Cut, interval_force_matrices, mean_force_matrix
from posedyn.stability.model import CriticalDepths, Discretization, critical_crossing, chatter_frequencies

#: Batch elements per step-matrix and eigensolver pass: small enough to stay in cache (64: 25 ms
#: per sweep pose against 34 ms at 500).
CHUNK = 64


class BatchStability:
    """Structures (all with the same number of modes), one cut, one speed (or one speed per
    structure: the same structure repeated at many speeds gives its lobes)."""

    def __init__(self, structures: Sequence[ToolTipDynamics], cut: Cut, rpm, disc: Discretization = Discretization()):
        if not structures:
            raise InputError("at least one structure", got=0, column="structures")
        n = structures[0].n_modes
        if any(d.n_modes != n for d in structures):
            raise InputError(f"structures with {n} modes each (group them by mode count)", got=sorted({d.n_modes for d in structures}), column="structures")
        rpm = np.broadcast_to(np.asarray(rpm, dtype=float), (len(structures),))
        if not np.all(np.isfinite(rpm) & (rpm > 0)):
            raise InputError("spindle speeds > 0 rpm", got=rpm[~(np.isfinite(rpm) & (rpm > 0))][0], column="rpm")
        self.cut, self.rpm, self.disc = cut, rpm, disc
        angle = np.deg2rad(cut.feed_angle_deg)
        turned = [d.rotated(angle) for d in structures]
        self.stiffness = np.stack([d.stiffness_matrix for d in structures])
        self.damping = np.stack([d.damping_matrix for d in structures])
        self.shapes = np.stack([d.shapes for d in turned])  # (P, 2, n)
        force_shapes = np.stack([d.force_shapes for d in turned])
        H = interval_force_matrices(cut, disc.steps)
        self.inputs = np.einsum("pir,sij->psrj", force_shapes, H)  # Phi_R^T H_i (P, m, n, 2)
        self.w_modal = np.einsum("psrj,pjq->psrq", self.inputs, self.shapes)  # (P, m, n, n)
        self.dt_s = np.asarray(cut.tooth_period_s(rpm), dtype=float) / disc.steps
        h = np.einsum("pir,ij,pjr->pr", force_shapes, mean_force_matrix(cut), self.shapes)
        wn, zeta = np.stack([d.wn_rad_s for d in structures]), np.stack([d.zeta for d in structures])
        with np.errstate(divide="ignore", invalid="ignore"):
            single = np.where(h > 0, 2.0 * zeta * (1.0 + zeta) * wn**2 / h, np.inf)
        self.scale_m = single.min(axis=1)

    def __len__(self) -> int:
        return len(self.stiffness)

    def step_matrices(self, elements: np.ndarray, depth_m: np.ndarray) -> sdm.StepMatrices:
        return sdm.stacked_step_matrices(
            self.stiffness[elements], self.damping[elements], self.w_modal[elements], depth_m, self.dt_s[elements], self.disc.order
        )

    def tool_tip_monodromy(self, elements: np.ndarray, depth_m: np.ndarray) -> np.ndarray:
        """Monodromy matrices (B, N, N) on [z_0; u_{-1}; ...; u_{-m}], N = 2n + 2m, less the history
        slots that no step reads."""
        steps = sdm.stacked_step_matrices(
            self.stiffness[elements], self.damping[elements], self.w_modal[elements], depth_m, self.dt_s[elements], self.disc.order, inputs=self.inputs[elements]
        )
        P, Fb, Fa = steps._batch_first  # (m, B, 2n, 2n), (m, B, 2n, 2)
        m, batch, two_n, r = Fb.shape
        n = two_n // 2
        shapes = self.shapes[elements]  # (B, 2, n)
        size = two_n + m * r
        eye = np.broadcast_to(np.eye(size), (batch, size, size))
        z = eye[:, :two_n]
        hist = [None] * (2 * m + 1)  # hist[k] = u_{k-m}
        for j in range(1, m + 1):
            hist[m - j] = eye[:, two_n + (j - 1) * r : two_n + j * r]
        hist[m] = shapes @ z[:, :n]
        for i in range(m):
            z = P[i] @ z + Fb[i] @ hist[i] + Fa[i] @ hist[i + 1]
            hist[m + i + 1] = shapes @ z[:, :n]
        psi = np.concatenate([z] + [hist[2 * m - j] for j in range(1, m + 1)], axis=1)
        # History slots that no cutting step reads are zero columns (zero multipliers only): drop them.
        cutting = np.any(self.inputs != 0.0, axis=(0, 2, 3))  # (m,)
        read = np.zeros(m + 1, dtype=bool)  # read[j]: slot of u_{-j}
        read[m - np.flatnonzero(cutting)] = True
        read[m - 1 - np.flatnonzero(cutting)] = True
        keep = np.concatenate([np.arange(two_n)] + [two_n + (j - 1) * r + np.arange(r) for j in range(1, m + 1) if read[j]])
        return psi[:, keep[:, None], keep[None, :]]

    def multipliers(self, elements, depth_m) -> np.ndarray:
        """Dominant multiplier (Im >= 0) for each broadcast (structure index, depth) pair."""
        elements, depth = np.broadcast_arrays(np.asarray(elements, dtype=int), np.asarray(depth_m, dtype=float))
        flat_e, flat_d = elements.reshape(-1), depth.reshape(-1)
        if np.any(~np.isfinite(flat_d) | (flat_d < 0)):
            raise InputError("depths >= 0", got=flat_d[~np.isfinite(flat_d) | (flat_d < 0)][0], column="depth")
        out = np.empty(len(flat_e), dtype=complex)
        for start in range(0, len(flat_e), CHUNK):
            part = slice(start, start + CHUNK)
            eig = np.linalg.eigvals(self.tool_tip_monodromy(flat_e[part], flat_d[part]))
            best = np.take_along_axis(eig, np.argmax(np.abs(eig), axis=1)[:, None], axis=1)[:, 0]
            out[part] = np.where(best.imag < 0, best.conj(), best)
        return out.reshape(elements.shape)

    def critical_depths(self, frequencies: bool = True, rel_tol: float = 1e-6, guess_m=None, guess_span: float = 2.0, rungs: int | None = None) -> CriticalDepths:
        """Critical depth and dominant chatter frequency of every structure at its speed."""
        depth, depth_unstable, mu = critical_crossing(self.multipliers, self.scale_m, rel_tol, guess_m, guess_span, rungs)
        count = len(self)
        dominant = np.full(count, np.nan)
        family = [()] * count
        if frequencies:
            finite = np.flatnonzero(np.isfinite(depth))
            for start in range(0, len(finite), CHUNK):
                part = finite[start : start + CHUNK]
                steps = self.step_matrices(part, depth_unstable[part])
                for j, (dom, fam) in zip(part, chatter_frequencies(self.shapes[part], steps, mu[part])):
                    dominant[j], family[j] = dom, fam
        return CriticalDepths(rpm=self.rpm.copy(), depth_m=depth, multiplier=mu, dominant_chatter_hz=dominant, family=tuple(family))
