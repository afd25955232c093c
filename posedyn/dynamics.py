"""Tool-tip dynamics in the milling plane as a modal model.

    U(t) = [x, y]^T = Phi q(t),    q_r'' + 2 zeta_r w_r q_r' + w_r^2 q_r = Phi_r^T F(t)

with `shapes` = Phi (2 x n), the mass-normalised mode shapes seen at the tool tip (1/sqrt(kg)).
A mode measured in one direction with modal stiffness k has shape 1/sqrt(m) in that direction
and 0 in the other (m = k / w_n^2), so its receptance is 1 / (k (1 - r^2 + 2 i zeta r)); a mode
with shape components in both directions couples x and y (seed 003 eqs. 15-17, seed 004 eq. 5).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

import numpy as np

from posedyn.errors import InputError
from posedyn.table import ModalTable, Mode


@dataclass(frozen=True, eq=False)
class ToolTipDynamics:
    """n modes at the tool tip: natural frequencies, damping ratios and x/y mode shapes.

    A coupled structure (host plus absorber, non-proportional damping) gives its full
    mass-normalised stiffness and damping matrices in `coupling`: q'' + C q' + K q = Phi^T F with
    K, C = coupling; fn_hz and zeta then describe the diagonal only (for frequency grids)."""

    fn_hz: np.ndarray
    zeta: np.ndarray
    shapes: np.ndarray
    coupling: tuple | None = None

    def __post_init__(self):
        fn = np.array(self.fn_hz, dtype=float).reshape(-1)
        zeta = np.array(self.zeta, dtype=float).reshape(-1)
        shapes = np.array(self.shapes, dtype=float).reshape(2, -1)
        if len(fn) == 0 or not (len(fn) == len(zeta) == shapes.shape[1]):
            raise InputError("at least one mode, with fn_hz, zeta and shapes of equal length", got=(len(fn), len(zeta), shapes.shape))
        if not (np.all(np.isfinite(fn)) and np.all(fn > 0)):
            raise InputError("natural frequencies > 0", got=fn.tolist(), column="fn_hz")
        if not np.all((zeta > 0) & (zeta < 1)):
            raise InputError("damping ratios in (0, 1)", got=zeta.tolist(), column="zeta")
        if not np.all(np.isfinite(shapes)) or (self.coupling is None and np.any(np.all(shapes == 0, axis=0))):
            raise InputError("finite mode shapes with a non-zero x or y component", column="shapes")
        for name, value in (("fn_hz", fn), ("zeta", zeta), ("shapes", shapes)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        if self.coupling is not None:
            K, C = (np.array(a, dtype=float) for a in self.coupling)
            if K.shape != (len(fn), len(fn)) or C.shape != K.shape:
                raise InputError(f"coupling matrices of shape ({len(fn)}, {len(fn)})", got=(K.shape, C.shape), column="coupling")
            object.__setattr__(self, "coupling", (K, C))

    @classmethod
    def from_matrices(cls, K: np.ndarray, C: np.ndarray, shapes: np.ndarray) -> "ToolTipDynamics":
        """A coupled structure in mass-normalised coordinates."""
        K, C = np.asarray(K, dtype=float), np.asarray(C, dtype=float)
        wn = np.sqrt(np.diag(K))
        return cls(fn_hz=wn / (2 * np.pi), zeta=np.diag(C) / (2 * wn), shapes=shapes, coupling=(K, C))

    @property
    def stiffness_matrix(self) -> np.ndarray:
        return self.coupling[0] if self.coupling is not None else np.diag(self.wn_rad_s**2)

    @property
    def damping_matrix(self) -> np.ndarray:
        return self.coupling[1] if self.coupling is not None else np.diag(2.0 * self.zeta * self.wn_rad_s)

    @classmethod
    def from_modes(cls, x: Iterable[Mode] = (), y: Iterable[Mode] = ()) -> "ToolTipDynamics":
        """Uncoupled modes measured in x and in y."""
        x, y = tuple(x), tuple(y)
        modes = x + y
        shapes = np.zeros((2, len(modes)))
        for r, mode in enumerate(modes):
            shapes[0 if r < len(x) else 1, r] = 1.0 / np.sqrt(mode.m_kg)
        return cls(
            fn_hz=[m.fn_hz for m in modes],
            zeta=[m.zeta for m in modes],
            shapes=shapes,
        )

    @classmethod
    def from_table(cls, table: ModalTable, pose_id: str | None = None) -> "ToolTipDynamics":
        """The x and y modes of one pose of a modal table (z modes play no part in the 2-D cut)."""
        if pose_id is None:
            if len(table.poses) != 1:
                raise InputError("a pose_id (the table has several poses)", got=list(table.poses.pose_id)[:5], column="pose_id")
            pose_id = table.poses.pose_id[0]
        x, y = table.modes(pose_id, "x"), table.modes(pose_id, "y")
        if not x and not y:
            raise InputError(f"x or y modes for pose '{pose_id}'", got="none", column="direction")
        return cls.from_modes(x, y)

    @property
    def n_modes(self) -> int:
        return len(self.fn_hz)

    @property
    def wn_rad_s(self) -> np.ndarray:
        return 2.0 * np.pi * self.fn_hz

    def rotated(self, angle_rad: float) -> "ToolTipDynamics":
        """The same structure seen in axes turned by `angle_rad` about z (feed along the new x)."""
        c, s = np.cos(angle_rad), np.sin(angle_rad)
        return ToolTipDynamics(self.fn_hz, self.zeta, np.array([[c, s], [-s, c]]) @ self.shapes, self.coupling)

    def frf(self, omega_rad_s) -> np.ndarray:
        """Receptance matrix G(i w) = Phi diag(1 / (w_r^2 - w^2 + 2 i zeta_r w_r w)) Phi^T, shape (..., 2, 2)."""
        w = np.asarray(omega_rad_s, dtype=float)[..., None]
        if self.coupling is not None:
            K, C = self.coupling
            dynamic = K - (w[..., None] ** 2) * np.eye(len(K)) + 1j * w[..., None] * C
            return self.shapes @ np.linalg.solve(dynamic, np.broadcast_to(self.shapes.T, dynamic.shape[:-1] + (2,)))
        wn = self.wn_rad_s
        modal = 1.0 / (wn**2 - w**2 + 2j * self.zeta * wn * w)
        return np.einsum("ir,...r,jr->...ij", self.shapes, modal, self.shapes)


def combine(*parts: ToolTipDynamics) -> ToolTipDynamics:
    """The sum of several receptances (e.g. spindle-robot plus workpiece-fixture, seed 001): their
    modal coordinates side by side, H = H_1 + H_2 + ..."""
    if any(p.coupling is not None for p in parts):
        K = _block([p.stiffness_matrix for p in parts])
        C = _block([p.damping_matrix for p in parts])
        return ToolTipDynamics.from_matrices(K, C, np.hstack([p.shapes for p in parts]))
    return ToolTipDynamics(
        fn_hz=np.concatenate([p.fn_hz for p in parts]),
        zeta=np.concatenate([p.zeta for p in parts]),
        shapes=np.hstack([p.shapes for p in parts]),
    )


def _block(blocks):
    n = sum(len(b) for b in blocks)
    out = np.zeros((n, n))
    i = 0
    for b in blocks:
        out[i : i + len(b), i : i + len(b)] = b
        i += len(b)
    return out
