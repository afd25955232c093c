"""The robot: kinematics from a URDF through Pinocchio.

`Robot` holds Pinocchio's immutable `Model` and the tool-tip frame; every function that needs
work buffers makes a scratch `Data` (or takes one), as Pinocchio intends. Poses are tool-tip
positions in the base frame (m inside the code) plus a tool-frame rotation; the tool frame has
its x axis along the tool (out of the spindle), as KUKA's $TOOL does, so:

- KUKA A/B/C: R = Rz(A) Ry(B) Rx(C) (ZYX Euler angles);
- seed 003's redundant angle beta about a tool axis held along base -z:
  R = Ry(pi/2) Rx(pi + beta) (x_tool = -z_base, turned by beta about it; at beta = 0 the tool
  z axis points back towards the robot, -x_base, so the flange faces away from the base).

Inverse kinematics: a geometric solution for the arm (front, elbow up) and the wrist (the
branch with A5 >= 0, the one the tool-down poses of a milling cell use), refined by Newton
steps on Pinocchio's forward kinematics to machine precision, then checked against the joint
limits. Unreachable poses and limit violations raise `InputError` with the pose and the joint.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from posedyn.errors import InputError

TOOL_FRAME = "tool_tip"
PAYLOAD_LINK = "spindle"


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def rotation_from_abc(a_rad: float, b_rad: float, c_rad: float) -> np.ndarray:
    """KUKA A/B/C: R = Rz(A) Ry(B) Rx(C)."""
    return rot_z(a_rad) @ rot_y(b_rad) @ rot_x(c_rad)


def abc_from_rotation(R: np.ndarray) -> tuple[float, float, float]:
    """Inverse of `rotation_from_abc` (B in [-pi/2, pi/2]; at B = +-pi/2 only A -+ C is defined,
    and C is set to 0)."""
    b = math.asin(max(-1.0, min(1.0, -R[2, 0])))
    if abs(math.cos(b)) > 1e-9:
        return math.atan2(R[1, 0], R[0, 0]), b, math.atan2(R[2, 1], R[2, 2])
    return math.atan2(-R[0, 1], R[1, 1]), b, 0.0


def rotation_from_beta(beta_rad: float) -> np.ndarray:
    """Seed 003: tool axis along base -z, turned by beta about it: R = Ry(pi/2) Rx(pi + beta)."""
    return rot_y(math.pi / 2) @ rot_x(math.pi + beta_rad)


@dataclass(frozen=True)
class ToolPose:
    """Tool-tip position (m, base frame) and tool-frame rotation."""

    position_m: np.ndarray
    rotation: np.ndarray
    label: str = ""

    @classmethod
    def from_beta(cls, x_m: float, y_m: float, z_m: float, beta_rad: float, label: str = "") -> "ToolPose":
        return cls(np.array([x_m, y_m, z_m], dtype=float), rotation_from_beta(beta_rad), label)

    @classmethod
    def from_abc(cls, x_m: float, y_m: float, z_m: float, a_rad: float, b_rad: float, c_rad: float, label: str = "") -> "ToolPose":
        return cls(np.array([x_m, y_m, z_m], dtype=float), rotation_from_abc(a_rad, b_rad, c_rad), label)

    @property
    def se3(self) -> pin.SE3:
        return pin.SE3(np.asarray(self.rotation, dtype=float), np.asarray(self.position_m, dtype=float))


class Robot:
    """A serial robot with a tool-tip frame: Pinocchio `Model` (immutable once built) plus the
    geometry the analytic inverse kinematics needs, read from the model itself."""

    def __init__(self, model: pin.Model, name: str = "", urdf_xml: str | None = None):
        self.model = model
        self.name = name or model.name
        self.urdf_xml = urdf_xml  # the description it was built from (saved with models)
        if not model.existFrame(TOOL_FRAME):
            raise InputError(f"a frame named '{TOOL_FRAME}' in the robot model", got=list(f.name for f in model.frames)[-3:])
        if model.nq != 6:
            raise InputError("a six-axis robot", got=model.nq)
        self.tool_frame = model.getFrameId(TOOL_FRAME)
        self.lower = np.array(model.lowerPositionLimit)
        self.upper = np.array(model.upperPositionLimit)
        # geometry for the analytic seed, from the joint placements (zero configuration)
        placements = [model.jointPlacements[j].translation.copy() for j in range(1, 7)]
        self._base_height = placements[0][2]
        self._shoulder = placements[1][0]
        self._upper_arm = placements[2][0]
        self._forearm = placements[3][[0, 2]]  # along x and the z offset to the wrist centre
        data = model.createData()
        pin.framesForwardKinematics(model, data, pin.neutral(model))
        wrist = data.oMi[6]  # joint 6 frame at zero (origin on the tool axis, past the wrist)
        self._wrist_to_tool = wrist.actInv(data.oMf[self.tool_frame])  # flange-to-tool placement
        self._wrist_offset = placements[5][0]  # joint 5 to joint 6 along x

    @classmethod
    def from_urdf(cls, path: str | os.PathLike, payload_kg: float | None = None) -> "Robot":
        """Load a URDF; `payload_kg` rescales the mass and inertia of the spindle link."""
        path = Path(path)
        try:
            tree = ET.parse(path)
        except (OSError, ET.ParseError) as exc:
            raise InputError("a readable URDF file", got=str(exc), file=str(path)) from None
        if payload_kg is not None:
            if not (math.isfinite(payload_kg) and payload_kg >= 0):
                raise InputError("a payload mass >= 0 kg", got=payload_kg, column="payload_kg")
            _scale_link_mass(tree, PAYLOAD_LINK, payload_kg, str(path))
        xml = ET.tostring(tree.getroot(), encoding="unicode")
        return cls(pin.buildModelFromXML(xml), name=path.stem, urdf_xml=xml)

    @classmethod
    def from_xml(cls, xml: str, name: str = "") -> "Robot":
        return cls(pin.buildModelFromXML(xml), name=name, urdf_xml=xml)

    # --- kinematics ------------------------------------------------------------------------

    def forward(self, q: np.ndarray, data: pin.Data | None = None) -> pin.SE3:
        """Tool-tip placement in the base frame."""
        data = data or self.model.createData()
        pin.framesForwardKinematics(self.model, data, np.asarray(q, dtype=float))
        return data.oMf[self.tool_frame].copy()

    def jacobian(self, q: np.ndarray, data: pin.Data | None = None) -> np.ndarray:
        """6 x 6 tool-tip Jacobian, linear rows first, in base-aligned axes at the tool tip."""
        data = data or self.model.createData()
        return pin.computeFrameJacobian(self.model, data, np.asarray(q, dtype=float), self.tool_frame, pin.LOCAL_WORLD_ALIGNED)

    def inverse(self, pose: ToolPose, data: pin.Data | None = None, tol: float = 1e-12) -> np.ndarray:
        """Joint angles (rad) that put the tool tip at `pose`: analytic seed, Newton refinement,
        joint-limit check."""
        data = data or self.model.createData()
        target = pose.se3
        q = self._geometric_seed(target)
        for _ in range(20):
            current = self.forward(q, data)
            error = pin.log6(current.actInv(target)).vector  # in the tool frame
            if np.linalg.norm(error) < tol:
                break
            J = pin.computeFrameJacobian(self.model, data, q, self.tool_frame, pin.LOCAL)
            q = q + np.linalg.lstsq(J, error, rcond=None)[0]
        else:
            raise InputError("a pose the robot can reach (inverse kinematics did not converge)", got=_describe(pose))
        q = _wrap_to_limits(q, self.lower, self.upper)
        bad = np.flatnonzero((q < self.lower - 1e-9) | (q > self.upper + 1e-9))
        if len(bad):
            j = int(bad[0])
            raise InputError(
                f"joint A{j + 1} within [{math.degrees(self.lower[j]):.1f}, {math.degrees(self.upper[j]):.1f}] deg",
                got=f"{math.degrees(q[j]):.1f} deg for {_describe(pose)}",
            )
        return q

    def _geometric_seed(self, target: pin.SE3) -> np.ndarray:
        """Closed-form arm and wrist angles for the front, elbow-up, A5 >= 0 branch."""
        flange = target * self._wrist_to_tool.inverse()  # joint-6 frame
        wrist_centre = flange.translation - self._wrist_offset * flange.rotation[:, 0]
        x, y, z = wrist_centre
        q1 = math.atan2(y, x)
        r = math.hypot(x, y) - self._shoulder
        h = z - self._base_height
        a2 = self._upper_arm
        fx, fz = self._forearm
        a3 = math.hypot(fx, fz)
        d = math.hypot(r, h)
        cos_elbow = (d * d - a2 * a2 - a3 * a3) / (2 * a2 * a3)
        if not -1.0 <= cos_elbow <= 1.0 or d < 1e-6:
            raise InputError("a tool-tip position inside the robot's reach", got=_describe_se3(target))
        # In the arm plane (r forward, h up): upper arm at elevation t2 = -q2, forearm at
        # elevation t2 + t3 with t3 = atan2(fz, fx) - q3 its angle to the upper arm; elbow up
        # means the forearm bends down from the upper arm's line, t3 < 0.
        t3 = -math.acos(cos_elbow)
        t2 = math.atan2(h, r) - math.atan2(a3 * math.sin(t3), a2 + a3 * math.cos(t3))
        q2 = -t2
        q3 = math.atan2(fz, fx) - t3
        R03 = rot_z(q1) @ rot_y(q2 + q3)
        Rw = R03.T @ flange.rotation  # = Rx(q4) Ry(q5) Rx(q6)
        q5 = math.acos(max(-1.0, min(1.0, Rw[0, 0])))
        if abs(math.sin(q5)) > 1e-9:
            q4 = math.atan2(Rw[1, 0], -Rw[2, 0])
            q6 = math.atan2(Rw[0, 1], Rw[0, 2])
        else:
            q4, q6 = 0.0, math.atan2(Rw[2, 1], Rw[1, 1])
        return np.array([q1, q2, q3, q4, q5, q6])


def _wrap_to_limits(q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Shift each angle by multiples of 2 pi towards the middle of its range where that helps."""
    q = q.copy()
    for j in range(len(q)):
        for shift in (0.0, 2 * math.pi, -2 * math.pi):
            if lower[j] - 1e-9 <= q[j] + shift <= upper[j] + 1e-9:
                q[j] += shift
                break
    return q


def _describe(pose: ToolPose) -> str:
    return (pose.label + " " if pose.label else "") + _describe_se3(pose.se3)


def _describe_se3(placement: pin.SE3) -> str:
    p = placement.translation * 1e3
    return f"tool tip at ({p[0]:.1f}, {p[1]:.1f}, {p[2]:.1f}) mm"


def _scale_link_mass(tree: ET.ElementTree, link_name: str, mass_kg: float, file: str) -> None:
    for link in tree.getroot().iter("link"):
        if link.get("name") == link_name:
            inertial = link.find("inertial")
            mass = inertial.find("mass") if inertial is not None else None
            if mass is None:
                break
            ratio = mass_kg / float(mass.get("value"))
            mass.set("value", repr(float(mass_kg)))
            inertia = inertial.find("inertia")
            for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
                inertia.set(key, repr(float(inertia.get(key)) * ratio))
            return
    raise InputError(f"a link '{link_name}' with an <inertial> block (the payload)", got="missing", file=file)
