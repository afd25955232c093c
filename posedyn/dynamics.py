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
    shapes_force: np.ndarray | None = None  # force-side (right) shapes where they differ (non-symmetric coupling)

    def __post_init__(self):
        fn = np.array(self.fn_hz, dtype=float).reshape(-1)
        zeta = np.array(self.zeta, dtype=float).reshape(-1)
        shapes = np.array(self.shapes, dtype=float).reshape(2, -1)
        if len(fn) == 0 or not (len(fn) == len(zeta) == shapes.shape[1]):
            raise InputError("at least one mode, with fn_hz, zeta and shapes of equal length", got=(len(fn), len(zeta), shapes.shape))
        if not (np.all(np.isfinite(fn)) and np.all(fn > 0)):
            raise InputError("natural frequencies > 0", got=fn.tolist(), column="fn_hz")
        if self.coupling is None and not np.all((zeta > 0) & (zeta < 1)):
            raise InputError("damping ratios in (0, 1)", got=zeta.tolist(), column="zeta")
        if self.coupling is not None and not np.all(np.isfinite(zeta) & (zeta > 0)):
            # the diagonal of a coupled structure's damping may exceed critical: an absorber's
            # damper across a light spindle mode (5 kg, 1000 N s/m on a 6 kHz mode of 2 g)
            raise InputError("diagonal damping ratios > 0", got=zeta.tolist(), column="zeta")
        if not np.all(np.isfinite(shapes)) or (self.coupling is None and np.any(np.all(shapes == 0, axis=0))):
            raise InputError("finite mode shapes with a non-zero x or y component", column="shapes")
        for name, value in (("fn_hz", fn), ("zeta", zeta), ("shapes", shapes)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        if self.shapes_force is not None:
            right = np.array(self.shapes_force, dtype=float).reshape(shapes.shape)
            if not np.all(np.isfinite(right)):
                raise InputError("finite force-side mode shapes", column="shapes_force")
            right.setflags(write=False)
            object.__setattr__(self, "shapes_force", right)
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
    def force_shapes(self) -> np.ndarray:
        """Phi_R: how a tool-tip force drives each coordinate (Phi_R^T F); equal to `shapes` for a
        symmetric structure."""
        return self.shapes if self.shapes_force is None else self.shapes_force

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
        """The x and y modes of one pose of a modal table (z modes play no part in the 2-D cut).

        A mode number whose x row carries k_xy and whose y row carries k_yx is one coupled mode:
        with w its angular frequency (mean of the two rows) and the displacement-side (left) and
        force-side (right) shapes phi_L, phi_R, H_ab = phi_La phi_Rb / (w^2 - ...), so
        phi_Lx = phi_Rx = w / sqrt(k_x), phi_Ry = w^2 / (k_xy phi_Lx), phi_Ly = w^2 / (k_yx phi_Rx)
        (the y direct term then follows from the three others, exactly for a rank-one mode)."""
        if pose_id is None:
            if len(table.poses) != 1:
                raise InputError("a pose_id (the table has several poses)", got=list(table.poses.pose_id)[:5], column="pose_id")
            pose_id = table.poses.pose_id[0]
        p = table.poses.index(pose_id)
        rows = {(d, int(m)): i for i, (q, d, m) in enumerate(zip(table.pose_index, table.direction, table.mode)) if q == p and d in ("x", "y")}
        if not rows:
            raise InputError(f"x or y modes for pose '{pose_id}'", got="none", column="direction")
        kxy, kyx = table.cross.get("k_xy_n_per_m"), table.cross.get("k_yx_n_per_m")
        fn, zeta, left, right = [], [], [], []
        done = set()
        for (d, m), i in sorted(rows.items(), key=lambda item: (item[0][1], item[0][0])):
            if (d, m) in done:
                continue
            j = rows.get(("y", m)) if d == "x" else None
            if j is not None and kxy is not None and kyx is not None and np.isfinite(kxy[i]) and np.isfinite(kyx[j]):
                w = 2 * np.pi * 0.5 * (table.fn_hz[i] + table.fn_hz[j])
                lx = w / np.sqrt(table.k_n_per_m[i])
                ry = w * w / (kxy[i] * lx)
                ly = w * w / (kyx[j] * lx)
                fn.append(w / (2 * np.pi))
                zeta.append(0.5 * (table.zeta[i] + table.zeta[j]))
                left.append([lx, ly])
                right.append([lx, ry])
                done |= {("x", m), ("y", m)}
                continue
            mode = Mode(float(table.fn_hz[i]), float(table.zeta[i]), float(table.k_n_per_m[i]))
            column = [1.0 / np.sqrt(mode.m_kg), 0.0] if d == "x" else [0.0, 1.0 / np.sqrt(mode.m_kg)]
            fn.append(mode.fn_hz)
            zeta.append(mode.zeta)
            left.append(column)
            right.append(column)
            done.add((d, m))
        left, right = np.array(left).T, np.array(right).T
        return cls(fn_hz=fn, zeta=zeta, shapes=left, shapes_force=None if np.array_equal(left, right) else right)

    @property
    def n_modes(self) -> int:
        return len(self.fn_hz)

    @property
    def wn_rad_s(self) -> np.ndarray:
        return 2.0 * np.pi * self.fn_hz

    def rotated(self, angle_rad: float) -> "ToolTipDynamics":
        """The same structure seen in axes turned by `angle_rad` about z (feed along the new x)."""
        c, s = np.cos(angle_rad), np.sin(angle_rad)
        R = np.array([[c, s], [-s, c]])
        right = None if self.shapes_force is None else R @ self.shapes_force
        return ToolTipDynamics(self.fn_hz, self.zeta, R @ self.shapes, self.coupling, right)

    def frf(self, omega_rad_s) -> np.ndarray:
        """Receptance matrix G(i w) = Phi diag(1 / (w_r^2 - w^2 + 2 i zeta_r w_r w)) Phi^T, shape (..., 2, 2)."""
        w = np.asarray(omega_rad_s, dtype=float)[..., None]
        if self.coupling is not None:
            K, C = self.coupling
            dynamic = K - (w[..., None] ** 2) * np.eye(len(K)) + 1j * w[..., None] * C
            return self.shapes @ np.linalg.solve(dynamic, np.broadcast_to(self.force_shapes.T, dynamic.shape[:-1] + (2,)))
        wn = self.wn_rad_s
        modal = 1.0 / (wn**2 - w**2 + 2j * self.zeta * wn * w)
        return np.einsum("ir,...r,jr->...ij", self.shapes, modal, self.force_shapes)


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
