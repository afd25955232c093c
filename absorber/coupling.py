"""A tuned absorber on the tool tip as extra degrees of freedom of the structure.

The absorber mass m_a moves as x_a in each direction it acts in and is joined to the tool tip
(the spindle housing, which the low robot modes move with the tool) by a spring k_a and a
viscous damper c_a = 2 zeta_a sqrt(k_a m_a). With host modal coordinates q (U = Phi q) and the
mass-normalised absorber coordinate p = sqrt(m_a) x_a along the unit direction d:

    K = [[W0 + k_a phi phi^T, -k_a phi / sqrt(m_a)], [-k_a phi^T / sqrt(m_a), k_a / m_a]],  phi = Phi^T d

and C likewise with c_a (plus the host's modal damping). The tool tip does not see p directly,
so the shapes get zero columns. The MRF absorber of seed 004 shears an annular elastomer and
MRF plates in the plane: it acts in x and in y with the same stiffness (one coordinate each).
"""

from __future__ import annotations

import math

import numpy as np

from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError, check_non_negative, check_positive

AXES = {"x": np.array([1.0, 0.0]), "y": np.array([0.0, 1.0])}


def with_absorber(dyn: ToolTipDynamics, mass_kg: float, k_n_per_m: float, zeta: float, directions=("x", "y")) -> ToolTipDynamics:
    check_positive("mass_kg", mass_kg)
    check_positive("k_n_per_m", k_n_per_m)
    check_non_negative("zeta", zeta)
    if not directions or any(d not in AXES for d in directions):
        raise InputError("absorber directions among x, y", got=directions, column="directions")
    n = dyn.n_modes
    extra = len(directions)
    size = n + extra
    K = np.zeros((size, size))
    C = np.zeros((size, size))
    K[:n, :n] = dyn.stiffness_matrix
    C[:n, :n] = dyn.damping_matrix
    c_a = 2.0 * zeta * math.sqrt(k_n_per_m * mass_kg)
    root = math.sqrt(mass_kg)
    for j, d in enumerate(directions):
        left, right = dyn.shapes.T @ AXES[d], dyn.force_shapes.T @ AXES[d]  # tool-tip motion, force entry
        a = n + j
        for M, value in ((K, k_n_per_m), (C, c_a)):
            M[:n, :n] += value * np.outer(right, left)
            M[:n, a] -= value * right / root
            M[a, :n] -= value * left / root
            M[a, a] += value / mass_kg
    pad = np.zeros((2, extra))
    built = ToolTipDynamics.from_matrices(K, C, np.hstack([dyn.shapes, pad]))
    if dyn.shapes_force is None:
        return built
    return ToolTipDynamics(built.fn_hz, built.zeta, built.shapes, built.coupling, np.hstack([dyn.force_shapes, pad]))
