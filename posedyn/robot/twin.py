"""Elastodynamic twin of the robot at a pose: lumped joint stiffness on rigid links.

    M(q) theta'' + C theta' + K_theta theta = J(q)^T f

with M(q) from Pinocchio's composite rigid-body algorithm (links, spindle payload), K_theta =
diag(k_j) joint stiffnesses and modal damping zeta_r. The generalized eigenproblem
K_theta phi = w^2 M phi (phi^T M phi = 1) gives the robot modes; their tool-tip shapes
u_r = J_lin(q) phi_r make the tool-tip receptance

    H(w) = sum_r u_r u_r^T / (w_r^2 - w^2 + 2 i zeta_r w_r w)

so mode r seen in direction d has modal stiffness k_rd = w_r^2 / u_rd^2 (seed 004 eq. 5,
seed 003 eqs. 15-17). Pose-independent spindle-tool modes (seed 001 Table 4 style) are added
per direction. Nothing here does I/O.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin
from scipy.linalg.lapack import dsygvd

from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError
from posedyn.robot.kinematics import Robot
from posedyn.table import DIRECTIONS, Mode


@dataclass(frozen=True)
class TwinParameters:
    """Joint stiffnesses (N m / rad, A1..A6), robot-mode damping ratio, pose-independent
    spindle-tool modes per direction, how many robot modes each direction reports, an extra
    point mass on the flange (device mounted on the spindle housing; 0 by default), one at the
    tool tip (a sensor; 0 by default) and the joints' softening under their gravity torque (0 by
    default)."""

    joint_stiffness_nm_per_rad: tuple[float, ...] = (3.0e6, 4.0e6, 2.0e6, 6.0e5, 6.0e5, 4.5e5)
    zeta: float = 0.03
    spindle_modes: dict = field(default_factory=dict)
    robot_modes_per_direction: int = 6  # every robot mode: fewer can leave out the one that chatters (`least_kept_compliance`)
    flange_mass_kg: float = 0.0
    flange_mass_offset_m: tuple[float, float, float] = (0.15, 0.0, 0.12)
    gravity_softening_per_knm: float = 0.0  # c: joint j's stiffness k_j / (1 + c |tau_g,j(q)| / 1 kN m) under its gravity torque
    tip_mass_kg: float = 0.0  # a point mass at the tool tip (an impact test's accelerometer)

    def __post_init__(self):
        k = np.asarray(self.joint_stiffness_nm_per_rad, dtype=float)
        if k.shape != (6,) or not np.all(np.isfinite(k) & (k > 0)):
            raise InputError("six joint stiffnesses > 0 N m/rad", got=self.joint_stiffness_nm_per_rad, column="joint_stiffness_nm_per_rad")
        if not 0 < self.zeta < 1:
            raise InputError("a damping ratio in (0, 1)", got=self.zeta, column="zeta")
        if not 1 <= self.robot_modes_per_direction <= 6:
            raise InputError("1 to 6 robot modes per direction", got=self.robot_modes_per_direction, column="robot_modes_per_direction")
        if not (np.isfinite(self.gravity_softening_per_knm) and self.gravity_softening_per_knm > -0.2):
            raise InputError("a gravity softening > -0.2 per kN m", got=self.gravity_softening_per_knm, column="gravity_softening_per_knm")
        if not (np.isfinite(self.tip_mass_kg) and self.tip_mass_kg >= 0):
            raise InputError("a tool-tip mass >= 0 kg", got=self.tip_mass_kg, column="tip_mass_kg")
        if not (np.isfinite(self.flange_mass_kg) and self.flange_mass_kg >= 0):
            raise InputError("a flange mass >= 0 kg", got=self.flange_mass_kg, column="flange_mass_kg")
        for d, modes in self.spindle_modes.items():
            if d not in DIRECTIONS or not all(isinstance(m, Mode) for m in modes):
                raise InputError("spindle modes as {direction: (Mode, ...)}", got=d, column="spindle_modes")

    def scaled(self, stiffness_scale) -> "TwinParameters":
        """The same parameters with each joint stiffness multiplied by a factor."""
        scale = np.broadcast_to(np.asarray(stiffness_scale, dtype=float), (6,))
        return replace(self, joint_stiffness_nm_per_rad=tuple(np.asarray(self.joint_stiffness_nm_per_rad) * scale))


@dataclass(frozen=True, eq=False)
class TwinModes:
    """Robot modes at one pose: fn_hz (6,), zeta (6,), tool-tip shapes (3, 6) in 1/sqrt(kg)
    (base-frame x, y, z), plus the pose-independent spindle modes."""

    fn_hz: np.ndarray
    zeta: np.ndarray
    tip_shapes: np.ndarray
    spindle_modes: dict

    def stiffness(self, direction: str) -> np.ndarray:
        """k_rd = w_r^2 / u_rd^2 for every robot mode r (N/m; inf where the mode does not show)."""
        u = self.tip_shapes[DIRECTIONS.index(direction)]
        with np.errstate(divide="ignore"):
            return (2 * np.pi * self.fn_hz) ** 2 / u**2

    def dynamics(self, include_spindle: bool = True) -> ToolTipDynamics:
        """Tool-tip x-y modal model with the full (coupled) robot mode shapes."""
        fn = list(self.fn_hz)
        zeta = list(self.zeta)
        shapes = [self.tip_shapes[:2]]
        if include_spindle:
            for d in ("x", "y"):
                for m in self.spindle_modes.get(d, ()):
                    fn.append(m.fn_hz)
                    zeta.append(m.zeta)
                    column = np.zeros((2, 1))
                    column[DIRECTIONS.index(d), 0] = 1.0 / np.sqrt(m.m_kg)
                    shapes.append(column)
        return ToolTipDynamics(fn_hz=fn, zeta=zeta, shapes=np.hstack(shapes))


def mass_matrix(robot: Robot, q: np.ndarray, params: TwinParameters, data: pin.Data | None = None) -> np.ndarray:
    """Joint-space mass matrix M(q) (CRBA, symmetrised), with the optional flange and tool-tip
    point masses added through their Jacobians: M += m J_p^T J_p."""
    data = data or robot.model.createData()
    M = pin.crba(robot.model, data, np.asarray(q, dtype=float))
    M = np.triu(M) + np.triu(M, 1).T
    if params.flange_mass_kg > 0:
        J = _point_jacobian(robot, q, params.flange_mass_offset_m, data)
        M = M + params.flange_mass_kg * J.T @ J
    if params.tip_mass_kg > 0:
        J = robot.jacobian(q, data)[:3]
        M = M + params.tip_mass_kg * J.T @ J
    return M


def _point_jacobian(robot: Robot, q, offset_m, data) -> np.ndarray:
    """Linear Jacobian (3 x 6) of a point fixed to the last link at `offset_m` (flange frame)."""
    pin.computeJointJacobians(robot.model, data, np.asarray(q, dtype=float))
    pin.updateFramePlacements(robot.model, data)
    J = pin.getJointJacobian(robot.model, data, 6, pin.LOCAL)
    placement = pin.SE3(np.eye(3), np.asarray(offset_m, dtype=float))
    J_point = placement.toActionMatrixInverse() @ J  # local frame of the point
    R = (data.oMi[6] * placement).rotation
    return R @ J_point[:3]


def normal_modes(M: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """K phi = w^2 M phi with phi^T M phi = I: squared angular frequencies (ascending) and shapes.
    LAPACK's dsygvd called as scipy.linalg.eigh(K, M) calls it (the same results to the bit),
    without its per-call checks: 12 us instead of 39 us for 6 x 6, and the gap workflow's twin
    candidates solve it at every pose for every trial value."""
    w2, phi, info = dsygvd(np.asarray(K, dtype=float), np.asarray(M, dtype=float), itype=1, jobz="V", uplo="L")
    if info != 0:
        raise np.linalg.LinAlgError(f"K phi = w^2 M phi: LAPACK dsygvd failed (info {info}; M not positive definite?)")
    return w2, phi


def joint_stiffness(params: TwinParameters, gravity_nm: np.ndarray) -> np.ndarray:
    """Joint stiffnesses (N m / rad) at a pose: k_j / (1 + c |tau_g,j(q)| / 1000 N m), tau_g the
    gravity torques of the robot's links and spindle at q (`PoseInertia.gravity_nm`; a flange
    device's own weight is left out). c = 0: the constant k_j."""
    k = np.asarray(params.joint_stiffness_nm_per_rad, dtype=float)
    if params.gravity_softening_per_knm == 0.0:
        return k
    return k / np.maximum(1.0 + params.gravity_softening_per_knm * np.abs(gravity_nm) / 1000.0, 0.05)


@dataclass(frozen=True, eq=False)
class PoseInertia:
    """What the modes at joint angles q need besides the joint stiffnesses: the mass matrix with
    the flange and tool-tip point masses (`mass_matrix`), the tool-tip linear Jacobian (3 x 6) and
    the gravity torques (N m, pinocchio's generalized gravity). A fit that changes only the
    stiffnesses (`scaled`, the softening) computes it once per pose."""

    mass: np.ndarray
    jacobian: np.ndarray
    gravity_nm: np.ndarray


def pose_inertia(robot: Robot, q: np.ndarray, params: TwinParameters, data: pin.Data | None = None) -> PoseInertia:
    """`PoseInertia` at q (rad) with the flange and tip masses of `params`."""
    data = data or robot.model.createData()
    q = np.asarray(q, dtype=float)
    M = mass_matrix(robot, q, params, data)
    gravity = np.array(pin.computeGeneralizedGravity(robot.model, data, q))
    return PoseInertia(M, robot.jacobian(q, data)[:3], gravity)


def modes_at(inertia: PoseInertia, params: TwinParameters) -> TwinModes:
    """Modes of the robot from its inertia at a pose and the joint stiffnesses of `params`:
    K phi = w^2 M phi, K = diag(joint stiffness), tool-tip shapes J phi."""
    w2, phi = normal_modes(inertia.mass, np.diag(joint_stiffness(params, inertia.gravity_nm)))
    return TwinModes(
        fn_hz=np.sqrt(w2) / (2 * np.pi),
        zeta=np.full(6, params.zeta),
        tip_shapes=inertia.jacobian @ phi,
        spindle_modes=_tip_loaded(params.spindle_modes, params.tip_mass_kg),
    )


def twin_modes(robot: Robot, q: np.ndarray, params: TwinParameters, data: pin.Data | None = None) -> TwinModes:
    """Modes of the robot at joint angles q (rad)."""
    return modes_at(pose_inertia(robot, q, params, data), params)


def _tip_loaded(spindle_modes: dict, tip_mass_kg: float) -> dict:
    """Spindle-tool modes with a point mass at the tool tip: each mode's modal mass m = k / w^2
    grows by it, so w' = w sqrt(m / (m + m_tip)), zeta' = zeta sqrt(m / (m + m_tip)) (same k and
    c); the robot modes carry it through the mass matrix."""
    if tip_mass_kg == 0.0:
        return dict(spindle_modes)
    out = {}
    for d, modes in spindle_modes.items():
        loaded = []
        for mode in modes:
            mass = mode.k_n_per_m / (2 * np.pi * mode.fn_hz) ** 2
            ratio = np.sqrt(mass / (mass + tip_mass_kg))
            loaded.append(Mode(float(mode.fn_hz * ratio), float(mode.zeta * ratio), mode.k_n_per_m))
        out[d] = tuple(loaded)
    return out
