"""The computation behind the service: a pose (and cut overrides) in, the `posedyn schedule`
entry out, from a trained model. No network here; the service runs it in worker processes."""

from __future__ import annotations

import hashlib
import threading
from dataclasses import replace
from pathlib import Path

import numpy as np

from absorber.chain import ScheduleConfig, schedule_entries
from absorber.coil import Coil
from absorber.field_plan import FieldPlanner
from absorber.files import read_absorber, read_actuator, read_drive
from posedyn.errors import InputError
from posedyn.io.cut import read_cut
from posedyn.io.model_dir import load_model, model_robot
from posedyn.io.tool_file import read_tool
from posedyn.robot import tool_pose
from posedyn.table import PoseSet
from posedyn.tool_change import tool_changed_table
from service.zenoh_service.protocol import RequestError


def model_version(training_hash: str, robust_samples: int = 0, tools: tuple[Path, Path] | None = None, pivot_mm: float = 150.0,
                  settings: tuple[Path | None, ...] = ()) -> str:
    """What the published entries depend on besides a request's cut overrides: the model, the
    robust sampling, a tool change and the `settings` files the service was started with (its
    default cut, absorber, actuator and twin; None: not given). Plans kept from a run with other
    settings are recomputed, not republished: a plan sent without cut overrides on the 2000 rpm
    cut was republished unchanged after a restart on a 200 rpm cut."""
    version = training_hash if not robust_samples else f"{training_hash}+robust{robust_samples}"
    if tools is not None:
        digest = hashlib.sha256(b"".join(Path(p).read_bytes() for p in tools) + repr(float(pivot_mm)).encode()).hexdigest()[:12]
        version += f"+tool{digest}"
    if settings:
        digest = hashlib.sha256(b"\0".join(b"-" if p is None else Path(p).read_bytes() for p in settings)).hexdigest()[:12]
        version += f"+settings{digest}"
    return version


class ScheduleEngine:
    """A loaded model, the default cut and the absorber and controller settings.

    Poses are checked before any prediction, in this order: inverse kinematics on the model's twin (else the
    given twin file, else the shipped KR R2700 twin) must succeed (`unreachable_pose`), and each of the model's pose features
    must lie within its training range widened by a quarter of that range, at least 50 mm or
    15 deg, and a column all training poses share within 50 mm or 15 deg of it
    (`outside_workspace`, `PoseModel.workspace_bounds`: a Gaussian process far from its data
    returns its prior, and one that never saw a column change cannot know its effect)."""

    def __init__(self, model_dir: Path, cut: Path, absorber: Path | None = None, actuator: Path | None = None, twin: Path | None = None,
                 robust_samples: int = 0, tools: tuple[Path, Path] | None = None, pivot_mm: float = 150.0):
        self.model = load_model(model_dir)
        self.robust_samples = robust_samples
        self.tools = None if tools is None else (read_tool(tools[0]), read_tool(tools[1]), pivot_mm * 1e-3)
        if self.tools is not None and robust_samples:
            raise InputError("robust samples without a tool change (the coupled modes carry no predictive distribution yet)", got="both", column="robust_samples")
        self.model_version = model_version(self.model.training_hash_, robust_samples, tools, pivot_mm, (cut, absorber, actuator, twin))
        self.cut, self.rpm, self.steps = read_cut(cut)
        self.absorber = read_absorber(absorber)
        self.drive = read_drive(absorber)
        self.control = read_actuator(actuator)
        self.robot = model_robot(self.model, twin)  # the one rule: the model's twin, else the given one, else the shipped twin
        self._lock = threading.Lock()  # Pinocchio's scratch data is not shared between threads

    def entry(self, pose: dict, cut: dict) -> dict:
        """The schedule entry of one pose (RequestError for a pose or cut it cannot serve)."""
        poses = self.pose_set(pose)
        config = self.config(cut)
        table = self.model.predict_table(poses)
        distributions = self.model.predict_distributions(poses, table) if config.robust_samples else None
        if self.tools is not None:
            table = tool_changed_table(table, *self.tools)
        return schedule_entries(table, config, distributions)[0]

    def trajectory(self, targets_hz: list[float], times_s: list[float]) -> dict:
        """The coil's voltage, current and field through the targets at the times
        (`absorber.field_plan`; the service's absorber and its file's drive, the default coil)."""
        coil, drive = Coil(), self.drive
        plan = FieldPlanner(len(times_s) - 1, self.absorber, coil, drive).solve(times_s, targets_hz)
        if plan.solver["status"] != "solved":  # IPOPT's last iterate is no trajectory to follow (95 % off in re-simulation, seen)
            return {"solver": plan.solver, "error": "the coil planner did not converge: no trajectory"}
        return {"voltage_v": plan.voltage_v.tolist(), "current_a": plan.current_a.tolist(), "field_mt": (1e3 * plan.field_t).tolist(),
                "temperature_c": plan.temperature_c.tolist(), "frequency_hz": plan.frequency_hz.tolist(), "solver": plan.solver}

    def config(self, cut: dict) -> ScheduleConfig:
        """The schedule settings with a request's cut overrides."""
        try:
            overrides = {k: cut[k] for k in ("teeth", "radial_immersion", "milling", "feed_angle_deg") if k in cut}
            if "kt_mpa" in cut:
                overrides["kt_pa"] = cut["kt_mpa"] * 1e6
            if "kn_mpa" in cut:
                overrides["kn_pa"] = cut["kn_mpa"] * 1e6
            the_cut = replace(self.cut, **overrides)
            return ScheduleConfig(the_cut, cut.get("rpm", self.rpm), self.absorber, control=self.control, steps=self.steps, robust_samples=self.robust_samples)
        except InputError as exc:
            raise RequestError("invalid_field", f"cut: {exc}") from None

    def pose_set(self, pose: dict):
        try:
            poses = PoseSet.from_columns((pose["pose_id"],), {k: [v] for k, v in pose.items() if k != "pose_id"})
        except InputError as exc:
            raise RequestError("invalid_field", f"pose: {exc}") from None
        columns = poses.numeric_columns()
        missing = [f for f in self.model.features_ if f not in columns]
        if missing:
            raise RequestError("missing_field", f"pose.{missing[0]}: the model needs it (its features are {self.model.features_})")
        if self.robot is not None:  # out of reach first: where the robot cannot go, the model's workspace is moot
            try:
                with self._lock:
                    joints = self.robot.inverse(tool_pose(poses, 0))
            except InputError as exc:
                raise RequestError("unreachable_pose", f"pose: no inverse kinematics solution ({exc})") from None
            poses = replace(poses, joints_deg=np.degrees(np.asarray(joints)).reshape(1, 6))
        outside = self.model.outside_workspace(poses)  # (a column all training poses shared: checked where given)
        if outside:
            raise RequestError("outside_workspace", f"{outside[0]} (the model's workspace: the training poses' range widened by a quarter, at least 50 mm or 15 deg)")
        return poses


def canonical(pose: dict, cut: dict) -> str:
    """A cache key for a (pose, cut) request, independent of the pose's id and of field order."""
    numbers = {k: v for k, v in pose.items() if k != "pose_id"}
    return repr((sorted((k, float(v)) for k, v in numbers.items()), sorted((k, v if isinstance(v, str) else float(v)) for k, v in cut.items())))
