"""The per-pose chain, the one computation every caller runs for a pose (the `schedule` and
`chatter`-style commands, the sweep, the Zenoh service, the gap workflow's depth rows):

    modes -> critical depth and dominant chatter (semi-discretization, batched over poses)
          -> absorber target by policy -> field (clamped, flagged) -> coil current
          -> critical depth with the absorber coupled to the tool tip
          -> absolute limits (zeroth order), the field interval covering the target's +-2 std
          -> the active-damping controller entry (DVF gain, virtual absorber; seed 000)

Policies:
- `match` (seed 004): target = dominant chatter frequency.
- `sims`: the target (within the absorber's range) that maximises the zeroth-order absolute
  stability limit of host plus absorber, the absorber's mass and field-dependent damping
  included (seed 002's max-min Re G for the real, coupled structure).

Stability is `posedyn.stability.critical_points`, batched over the poses: the converged engine
by default (every result carries the accuracy it reached), the semi-discretization when the
config's `steps` overrides it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize_scalar

from absorber.active_damping import ControlConfig, controller_entry
from absorber.coil import Coil
from absorber.coupling import with_absorber
from absorber.mrf import FieldSetting, MRFAbsorber
from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError, check_choice
from posedyn.robot import pose_rotation
from posedyn.stability import Cut, StabilityResult, critical_points, zoa
from posedyn.table import ModalTable

POLICIES = ("match", "sims")


@dataclass(frozen=True)
class ScheduleConfig:
    """The cut and speed, the devices and the settings of the chain."""

    cut: Cut
    rpm: float
    absorber: MRFAbsorber = field(default_factory=MRFAbsorber)
    coil: Coil = field(default_factory=Coil)
    control: ControlConfig = field(default_factory=ControlConfig)
    policy: str = "match"
    steps: int | None = None  # expert override: semi-discretization steps instead of the converged engine
    directions: tuple[str, ...] = ("x", "y")
    absolute_limits: bool = True  # the zeroth-order absolute limits (0.4-0.8 s a structure; sweeps skip them)

    def __post_init__(self):
        check_choice("policy", self.policy, POLICIES)
        if not (math.isfinite(self.rpm) and self.rpm > 0):
            raise InputError("a spindle speed > 0 rpm", got=self.rpm, column="rpm")
        if self.steps is not None and (not isinstance(self.steps, int) or self.steps < 4):
            raise InputError("an integer number of steps >= 4 (or none: the converged engine)", got=self.steps, column="steps")


@dataclass(frozen=True, eq=False)
class PoseModes:
    """One pose's modes: its tool-tip dynamics, its table rows (direction, mode, fn_hz, zeta,
    k_n_per_m, std_fn_hz) and its tool rotation (base frame)."""

    pose_id: str
    dyn: ToolTipDynamics
    rows: tuple
    rotation: np.ndarray

    @property
    def lowest_xy(self) -> tuple:
        """The row of the lowest x or y mode."""
        return min((r for r in self.rows if r[0] in ("x", "y")), key=lambda r: r[2])


@dataclass(frozen=True)
class AbsorberEntry:
    policy: str
    target_hz: float
    field_t: float
    current_a: float  # NaN where the coil cannot give the field
    feasible: bool
    field_t_interval: tuple[float, float]


@dataclass(frozen=True, eq=False)
class PoseSchedule:
    """The chain's result for one pose (SI units; `to_json` gives the schedule entry)."""

    pose: PoseModes
    critical_depth_m: float
    dominant_chatter_hz: float
    absorber: AbsorberEntry
    critical_depth_with_absorber_m: float
    stability: StabilityResult  # the bare structure's, with the accuracy it reached
    stability_with_absorber: StabilityResult
    absolute_limit_m: float  # NaN where the config skips the absolute limits
    absolute_limit_with_absorber_m: float
    controller: dict | None  # None: no robot mode below 500 Hz in the actuator's direction

    def to_json(self) -> dict:
        a = self.absorber
        return {
            "pose_id": self.pose.pose_id,
            "critical_depth_mm": _mm(self.critical_depth_m),
            "dominant_chatter_hz": self.dominant_chatter_hz,
            "absorber": {
                "policy": a.policy,
                "target_hz": a.target_hz,
                "field_mt": a.field_t * 1e3,
                "current_a": a.current_a if math.isfinite(a.current_a) else None,
                "feasible": a.feasible,
                "field_mt_interval": [b * 1e3 for b in a.field_t_interval],
            },
            "critical_depth_with_absorber_mm": _mm(self.critical_depth_with_absorber_m),
            "absolute_limit_mm": _mm(self.absolute_limit_m),
            "absolute_limit_with_absorber_mm": _mm(self.absolute_limit_with_absorber_m),
            "stability": self.stability.accuracy_json(),
            "stability_with_absorber": self.stability_with_absorber.accuracy_json(),
            "modes": [{"direction": d, "mode": m, "fn_hz": fn, "zeta": z, "k_n_per_m": k} for d, m, fn, z, k, _ in self.pose.rows],
            "controller": self.controller,
        }


def _mm(depth_m: float):
    return depth_m * 1e3 if math.isfinite(depth_m) else None


def table_pose_modes(table: ModalTable) -> list[PoseModes]:
    """The PoseModes of every pose of a modal table (std_fn_hz 0 where the table has none)."""
    std = table.std.get("std_fn_hz")
    out = []
    for p, pose_id in enumerate(table.poses.pose_id):
        rows = tuple(
            (str(table.direction[i]), int(table.mode[i]), float(table.fn_hz[i]), float(table.zeta[i]), float(table.k_n_per_m[i]),
             float(std[i]) if std is not None and np.isfinite(std[i]) else 0.0)
            for i in np.flatnonzero(table.pose_index == p)
        )
        out.append(PoseModes(pose_id, ToolTipDynamics.from_table(table, pose_id), rows, pose_rotation(table.poses, p)))
    return out


def coupled(dyn: ToolTipDynamics, config: ScheduleConfig, field_t: float) -> ToolTipDynamics:
    """Host plus the MRF absorber at a field (`absorber.coupling.with_absorber`)."""
    a = config.absorber
    return with_absorber(dyn, a.mass_kg, a.stiffness_n_per_m(field_t), a.damping_ratio(field_t), config.directions)


def sims_target_hz(dyn: ToolTipDynamics, config: ScheduleConfig, around_hz: float) -> float:
    """The absorber frequency that maximises the ZOA absolute limit of the coupled structure."""
    a = config.absorber
    lo, hi = a.range_hz
    lo, hi = max(lo, 0.5 * around_hz), min(hi, 2.0 * around_hz)
    if hi <= lo:
        return around_hz

    def limit(f):
        return zoa.absolute_limit_m(coupled(dyn, config, a.field_for_frequency(f).field_t), config.cut)

    grid = np.linspace(lo, hi, 25)
    values = [limit(f) for f in grid]
    i = int(np.argmax(values))
    a_, b_ = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    best = minimize_scalar(lambda f: -limit(f), bounds=(a_, b_), method="bounded", options={"xatol": 1e-3})
    return float(best.x) if -best.fun > values[i] else float(grid[i])


def absorber_setting(dyn: ToolTipDynamics, config: ScheduleConfig, chatter_hz: float) -> tuple[float, FieldSetting, float, bool]:
    """(target Hz, FieldSetting, coil current A or NaN, feasible): the policy's target, the
    field that tunes the absorber to it (clamped to its range) and whether the coil can give it."""
    target = chatter_hz if config.policy == "match" else sims_target_hz(dyn, config, chatter_hz)
    setting = config.absorber.field_for_frequency(target, clamp=True)
    feasible = setting.feasible
    try:
        current = config.coil.current_for_field(setting.field_t)
        feasible = feasible and current <= config.coil.max_current_a
    except InputError:
        current, feasible = float("nan"), False
    return target, setting, current, bool(feasible)


def schedule_poses(poses: list[PoseModes], config: ScheduleConfig) -> list[PoseSchedule]:
    """The chain for every pose (see the module docstring)."""
    if not poses:
        return []
    bare = critical_points([p.dyn for p in poses], config.cut, config.rpm, config.steps)
    entries, structures = [], []
    for pose, result in zip(poses, bare):
        depth, chatter_hz = result.depth_m, result.chatter_hz
        if not math.isfinite(chatter_hz):
            chatter_hz = float(pose.dyn.fn_hz[np.argmin(pose.dyn.fn_hz)])
        target, setting, current, feasible = absorber_setting(pose.dyn, config, chatter_hz)
        fn_std = pose.lowest_xy[5]
        spread = 2.0 * fn_std * target / max(chatter_hz, 1e-12)
        interval = (
            config.absorber.field_for_frequency(max(target - spread, 1e-6), clamp=True).field_t,
            config.absorber.field_for_frequency(target + spread, clamp=True).field_t,
        )
        entries.append((depth, chatter_hz, AbsorberEntry(config.policy, target, setting.field_t, current, feasible, interval)))
        structures.append(coupled(pose.dyn, config, setting.field_t))
    with_absorber = critical_points(structures, config.cut, config.rpm, config.steps, frequencies=False)
    out = []
    for pose, (depth, chatter_hz, absorber), structure, result, result_with in zip(poses, entries, structures, bare, with_absorber):
        out.append(PoseSchedule(
            pose=pose,
            critical_depth_m=depth,
            dominant_chatter_hz=chatter_hz,
            absorber=absorber,
            critical_depth_with_absorber_m=result_with.depth_m,
            stability=result,
            stability_with_absorber=result_with,
            absolute_limit_m=zoa.absolute_limit_m(pose.dyn, config.cut) if config.absolute_limits else math.nan,
            absolute_limit_with_absorber_m=zoa.absolute_limit_m(structure, config.cut) if config.absolute_limits else math.nan,
            controller=controller_entry(pose.pose_id, pose.rows, pose.rotation, config.control),
        ))
    return out


def schedule_entries(table: ModalTable, config: ScheduleConfig) -> list[dict]:
    """The `posedyn schedule` entry (JSON-ready) of every pose of a modal table."""
    return [s.to_json() for s in schedule_poses(table_pose_modes(table), config)]
