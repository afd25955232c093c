"""Receptance coupling substructure analysis with full receptance matrices (seed 003 section 3).

Every receptance is a (frequencies, 4, 4) array in seed 003 eq. 3's order: rows (x, theta_x, y,
theta_y) of the response point, columns (F_x, M_x, F_y, M_y) of the excitation point, so the x-y
cross terms are kept. The tool A (free-free; "1" its tip, "2" its coupling end) is joined to the
spindle-holder side B (its receptance B22 at the joint) through a connection of complex
stiffness K (translation and rotation, seed 003's [K]):

    C11 = A11 - A12 (A22 + K^-1 + B22)^-1 A21                           (coupling)
    B22 + K1^-1 = A21,T1 (A11,T1 - C11,T1)^-1 A12,T1 - A22,T1          (decoupling, reference tool T1)
    C11,T2 = A11,T2 - A12,T2 (A22,T2 + dK^-1 + [B22 + K1^-1])^-1 A21,T2,  dK^-1 = K2^-1 - K1^-1
                                                                        (seed 003 eq. 4)

Rotations are theta = dw/dz with z from the tool tip towards the holder; M is the moment that
does work on theta. Where the assembly's rotational receptances are not measured, seed 003
Appendix A estimates them by first-order finite differences from displacement-to-force FRFs
measured at the tip (point 1) and at a point a distance S up the tool (point a): a moment M at 1
is the couple -M / S at 1 and +M / S at a, a rotation the difference of displacements over S:

    N_1p,1q = (H_ap,1q - H_1p,1q) / S          L_1p,1q = (H_1p,aq - H_1p,1q) / S
    P_1p,1q = (H_ap,aq - H_ap,1q - H_1p,aq + H_1p,1q) / S^2              (p, q in x, y)

(seed 003 eqs. A.1-A.12, written without assuming reciprocity: the robot's cross terms need
not be symmetric). The estimate is that of the point S / 2 up the tool, first order in S.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from posedyn.errors import InputError, check_non_negative, check_positive
from posedyn.tool import Tool, tool_receptances

#: Seed 003 eq. 3's order: (x, theta_x, y, theta_y); the displacement rows and force columns.
DISPLACEMENT = [0, 2]


def couple(a11: np.ndarray, a12: np.ndarray, a21: np.ndarray, a22: np.ndarray, holder22: np.ndarray, connection_compliance: np.ndarray) -> np.ndarray:
    """C11 = A11 - A12 (A22 + K^-1 + B22)^-1 A21, per frequency."""
    return a11 - a12 @ np.linalg.solve(a22 + connection_compliance + holder22, a21)


def decouple(reference_tip: np.ndarray, tool: dict[str, np.ndarray]) -> np.ndarray:
    """B22 + K1^-1, the holder side with the reference tool's connection, from the reference
    assembly's tip receptance C11,T1 and the reference tool's receptances ("11", "12", "21", "22")."""
    return tool["21"] @ np.linalg.solve(tool["11"] - reference_tip, tool["12"]) - tool["22"]


def tool_change(reference_tip: np.ndarray, reference_tool: dict[str, np.ndarray], target_tool: dict[str, np.ndarray],
                compliance_change: np.ndarray | None = None) -> np.ndarray:
    """The target tool's assembly tip receptance C11,T2 from the reference tool's (seed 003 eq. 4);
    `compliance_change` = K2^-1 - K1^-1 (None: the same connection)."""
    holder = decouple(reference_tip, reference_tool)
    change = np.zeros_like(holder) if compliance_change is None else np.broadcast_to(compliance_change, holder.shape)
    return couple(target_tool["11"], target_tool["12"], target_tool["21"], target_tool["22"], holder, change)


@dataclass(frozen=True)
class Connection:
    """The holder-tool joint (seed 003's [K]): translational and rotational stiffness, the same in
    x and y, with viscous damping constants (seed 003 section 5.3 gives both)."""

    translational_n_per_m: float
    rotational_nm_per_rad: float
    translational_damping_ns_per_m: float = 0.0
    rotational_damping_nms_per_rad: float = 0.0

    def __post_init__(self):
        check_positive("translational_n_per_m", self.translational_n_per_m)
        check_positive("rotational_nm_per_rad", self.rotational_nm_per_rad)
        check_non_negative("translational_damping_ns_per_m", self.translational_damping_ns_per_m)
        check_non_negative("rotational_damping_nms_per_rad", self.rotational_damping_nms_per_rad)

    def compliance(self, omega_rad_s: np.ndarray) -> np.ndarray:
        """K^-1 (f, 4, 4), K = k + i w c on the diagonal."""
        w = np.atleast_1d(np.asarray(omega_rad_s, dtype=float))
        out = np.zeros((len(w), 4, 4), dtype=complex)
        t = 1.0 / (self.translational_n_per_m + 1j * w * self.translational_damping_ns_per_m)
        r = 1.0 / (self.rotational_nm_per_rad + 1j * w * self.rotational_damping_nms_per_rad)
        out[:, 0, 0] = out[:, 2, 2] = t
        out[:, 1, 1] = out[:, 3, 3] = r
        return out


def pivot_map(pivot_m: float) -> np.ndarray:
    """T (4, 2): the holder's joint moving as a rigid extension of a part that turns about a point
    `pivot_m` behind the joint (towards the spindle), (x, theta_x, y, theta_y) = T (x, y):
    theta = -w / pivot (z runs from the tip towards the holder); inf: no rotation at the joint."""
    if not pivot_m > 0:
        raise InputError("a pivot distance > 0 (inf: the joint does not turn)", got=pivot_m, column="pivot_m")
    t = np.zeros((4, 2))
    t[0, 0] = t[2, 1] = 1.0
    t[1, 0] = t[3, 1] = -1.0 / pivot_m
    return t


def holder_from_tip(tip_displacement: np.ndarray, tool: dict[str, np.ndarray], connection_compliance: np.ndarray, pivot_m: float) -> np.ndarray:
    """B22 (f, 4, 4) of the spindle-holder side from the assembly's measured or predicted tip
    displacement receptances alone (f, 2, 2; x, y with their cross terms), when no rotation is
    measured: the joint is taken to move as a rigid extension turning about a pivot
    (`pivot_map`), B22 = T b T^T, and the 2 x 2 joint compliance b follows in closed form. With
    Q = A22 + K^-1, W = T^T Q^-1 T, U = (A12 Q^-1 T)_disp, V = (T^T Q^-1 A21)_disp and H0 the tip of
    the tool on a rigid holder, C11 = A11 - A12 (Q + T b T^T)^-1 A21 gives (Woodbury)

        H - H0 = U (b^-1 + W)^-1 V,   b = ([U^-1 (H - H0) V^-1]^-1 - W)^-1.

    An assumption, not seed 003's method (its Appendix A measures a second point): it holds where
    the holder side's motion at the joint is a rotation about one point (robot modes: the wrist;
    spindle modes: less so); README gives its error on a model whose holder bends."""
    T = pivot_map(pivot_m)
    Q = tool["22"] + connection_compliance
    Qi_T = np.linalg.solve(Q, np.broadcast_to(T, Q.shape[:-2] + T.shape))
    Qi_A21 = np.linalg.solve(Q, tool["21"])
    W = T.T @ Qi_T
    U = (tool["12"] @ Qi_T)[:, DISPLACEMENT, :]
    V = (T.T @ Qi_A21)[:, :, DISPLACEMENT]
    H0 = (tool["11"] - tool["12"] @ Qi_A21)[:, DISPLACEMENT][:, :, DISPLACEMENT]
    middle = np.linalg.solve(U, np.asarray(tip_displacement) - H0) @ np.linalg.inv(V)
    b = np.linalg.inv(np.linalg.inv(middle) - W)
    return T @ b @ T.T


def connection_compliance(translational_n_per_m: float, rotational_nm_per_rad: float, loss_factor: float = 0.0) -> np.ndarray:
    """K^-1 of a connection with the same translational and rotational stiffness in x and y and
    hysteretic damping (K (1 + i eta)), (4, 4); an infinite stiffness is a rigid joint (0)."""
    out = np.zeros((4, 4), dtype=complex)
    for i, k in ((0, translational_n_per_m), (1, rotational_nm_per_rad), (2, translational_n_per_m), (3, rotational_nm_per_rad)):
        if not k > 0:
            raise InputError("connection stiffnesses > 0", got=k, column="connection")
        out[i, i] = 0.0 if np.isinf(k) else 1.0 / (k * (1.0 + 1j * loss_factor))
    return out


def finite_difference_tip(measured: np.ndarray, spacing_m: float) -> np.ndarray:
    """The tip's full receptance (f, 4, 4) from the 16 displacement-to-force FRFs of seed 003
    eq. 5, `measured` (f, 4, 4) with rows and columns (1x, 1y, ax, ay), points S = `spacing_m`
    apart (seed 003 Appendix A; formulas in the module docstring)."""
    if not spacing_m > 0:
        raise InputError("a spacing S > 0 between the tip and the second point", got=spacing_m, column="spacing_m")
    measured = np.asarray(measured)
    if measured.shape[-2:] != (4, 4):
        raise InputError("displacement FRFs between (1x, 1y, ax, ay), shape (..., 4, 4)", got=measured.shape, column="measured")
    S = spacing_m
    out = np.zeros(measured.shape, dtype=complex)
    for p in range(2):
        for q in range(2):
            h11, h1a = measured[..., p, q], measured[..., p, 2 + q]
            ha1, haa = measured[..., 2 + p, q], measured[..., 2 + p, 2 + q]
            r, c = 2 * p, 2 * q
            out[..., r, c] = h11
            out[..., r + 1, c] = (ha1 - h11) / S  # N
            out[..., r, c + 1] = (h1a - h11) / S  # L
            out[..., r + 1, c + 1] = (haa - ha1 - h1a + h11) / S**2  # P
    return out


def target_tip(tip_displacement: np.ndarray, omega_rad_s: np.ndarray, reference: tuple[Tool, Connection], target: tuple[Tool, Connection],
               pivot_m: float) -> np.ndarray:
    """The target tool's tip displacement receptances (f, 2, 2; x, y and cross terms) from the
    reference tool's assembly tip displacement receptances alone (measured, or a pose model's
    prediction): the holder side by `holder_from_tip`, then the target coupled through its own
    joint (seed 003 eq. 4 with B22 + K1^-1 split into B22 and the reference joint)."""
    ref_tool = tool_receptances(reference[0], omega_rad_s)
    ref_joint = reference[1].compliance(omega_rad_s)
    holder = holder_from_tip(tip_displacement, ref_tool, ref_joint, pivot_m)
    tool = tool_receptances(target[0], omega_rad_s)
    coupled = couple(tool["11"], tool["12"], tool["21"], tool["22"], holder, target[1].compliance(omega_rad_s))
    return coupled[:, DISPLACEMENT][:, :, DISPLACEMENT]


def identify_connection(reference_tip: np.ndarray, measured_target_tip: np.ndarray, omega_rad_s: np.ndarray, reference: tuple[Tool, Connection],
                        target_tool: Tool, initial: Connection) -> Connection:
    """The target tool's joint from one measurement of its tip (seed 003 section 5.3 tunes it by
    hand at one posture): the translational and rotational stiffness and damping that make the
    tool change reproduce the measured direct FRFs (x and y, f x 2 x 2 displacement block), least
    squares on the complex logarithm's real and imaginary parts (log |H| and phase, equal weight
    over the band), the parameters in logs, from `initial`. `reference_tip` is the reference
    assembly's full (f, 4, 4) tip receptance at that posture."""
    ref_tool, target = tool_receptances(reference[0], omega_rad_s), tool_receptances(target_tool, omega_rad_s)
    holder = decouple(reference_tip, ref_tool) - reference[1].compliance(omega_rad_s)
    measured = np.log(np.stack([measured_target_tip[:, 0, 0], measured_target_tip[:, 1, 1]]))

    def make(x) -> Connection:
        return Connection(*np.exp(x))

    def residual(x):
        tip = couple(target["11"], target["12"], target["21"], target["22"], holder, make(x).compliance(omega_rad_s))
        diff = np.log(np.stack([tip[:, 0, 0], tip[:, 2, 2]])) - measured
        diff.imag = (diff.imag + np.pi) % (2 * np.pi) - np.pi
        return np.concatenate([diff.real.ravel(), diff.imag.ravel()])

    start = [initial.translational_n_per_m, initial.rotational_nm_per_rad, max(initial.translational_damping_ns_per_m, 1e-3), max(initial.rotational_damping_nms_per_rad, 1e-6)]
    result = least_squares(residual, np.log(start), method="trf", x_scale=1.0)
    return make(result.x)
