"""Per-pose absorber schedules: modes -> dominant chatter -> target frequency -> field -> current.

For each pose: the critical depth and dominant chatter frequency without the absorber
(semi-discretization), the target absorber frequency by policy, the field that tunes the MRF
absorber to it (clamped to the coil's and the fluid's range, with a flag), the coil current,
the critical depth with the absorber coupled to the tool tip (semi-discretization again), and
the field interval that covers the target's +-2 std (from the predicted modes' uncertainty).

Policies:
- `match` (seed 004): target = dominant chatter frequency.
- `sims`: the target (within the absorber's range) that maximises the zeroth-order absolute
  stability limit of host plus absorber, the absorber's mass and field-dependent damping
  included (seed 002's max-min Re G for the real, coupled structure).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize_scalar

from absorber.coil import Coil
from absorber.coupling import with_absorber
from absorber.mrf import MRFAbsorber
from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError, check_choice
from posedyn.stability import Cut, Discretization, StabilityModel
from posedyn.stability import zoa

POLICIES = ("match", "sims")


@dataclass(frozen=True)
class ScheduleConfig:
    cut: Cut
    rpm: float
    absorber: MRFAbsorber = field(default_factory=MRFAbsorber)
    coil: Coil = field(default_factory=Coil)
    policy: str = "match"
    steps: int = 40
    directions: tuple[str, ...] = ("x", "y")

    def __post_init__(self):
        check_choice("policy", self.policy, POLICIES)
        if not (math.isfinite(self.rpm) and self.rpm > 0):
            raise InputError("a spindle speed > 0 rpm", got=self.rpm, column="rpm")


def coupled(dyn: ToolTipDynamics, config: ScheduleConfig, field_t: float) -> ToolTipDynamics:
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


def absorber_setting(dyn: ToolTipDynamics, config: ScheduleConfig, chatter_hz: float):
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


def schedule_pose(pose_id: str, dyn: ToolTipDynamics, config: ScheduleConfig, fn_std_hz: float = 0.0) -> dict:
    model = StabilityModel(dyn, config.cut, Discretization(config.steps))
    bare = model.critical_depths([config.rpm])
    depth, chatter_hz = float(bare.depth_m[0]), float(bare.dominant_chatter_hz[0])
    if not math.isfinite(chatter_hz):
        chatter_hz = float(dyn.fn_hz[np.argmin(dyn.fn_hz)])
    target, setting, current, feasible = absorber_setting(dyn, config, chatter_hz)
    absorber = config.absorber
    spread = 2.0 * fn_std_hz * target / max(chatter_hz, 1e-12)
    interval = [absorber.field_for_frequency(max(target - spread, 1e-6), clamp=True).field_t, absorber.field_for_frequency(target + spread, clamp=True).field_t]
    structure = coupled(dyn, config, setting.field_t)
    with_model = StabilityModel(structure, config.cut, Discretization(config.steps))
    depth_with = float(with_model.critical_depths([config.rpm], frequencies=False).depth_m[0])
    absolute = zoa.absolute_limit_m(dyn, config.cut)
    absolute_with = zoa.absolute_limit_m(structure, config.cut)
    return {
        "pose_id": pose_id,
        "critical_depth_mm": _mm(depth),
        "dominant_chatter_hz": chatter_hz,
        "absorber": {
            "policy": config.policy,
            "target_hz": target,
            "field_mt": setting.field_t * 1e3,
            "current_a": current if math.isfinite(current) else None,
            "feasible": bool(feasible),
            "field_mt_interval": [b * 1e3 for b in interval],
        },
        "critical_depth_with_absorber_mm": _mm(depth_with),
        "absolute_limit_mm": _mm(absolute),
        "absolute_limit_with_absorber_mm": _mm(absolute_with),
    }


def _mm(depth_m: float):
    return depth_m * 1e3 if math.isfinite(depth_m) else None


def schedule_entries(table, config: ScheduleConfig, control) -> list[dict]:
    """The `posedyn schedule` entry of every pose of a modal table: `schedule_pose` on the pose's
    tool-tip model (with the lowest x-y mode's fn std), the pose's modes, and its controller
    entry (`absorber.active.control_entries` with ControlConfig `control`)."""
    from absorber.active import control_entries

    controllers = {e["pose_id"]: e for e in control_entries(table, control)}
    std = table.std.get("std_fn_hz")
    entries = []
    for p, pose_id in enumerate(table.poses.pose_id):
        dyn = ToolTipDynamics.from_table(table, pose_id)
        rows = [i for i in range(len(table)) if table.pose_index[i] == p and table.direction[i] in ("x", "y")]
        lowest = min(rows, key=lambda i: table.fn_hz[i])
        fn_std = float(std[lowest]) if std is not None and np.isfinite(std[lowest]) else 0.0
        entry = schedule_pose(pose_id, dyn, config, fn_std)
        entry["modes"] = [
            {"direction": str(table.direction[i]), "mode": int(table.mode[i]), "fn_hz": float(table.fn_hz[i]), "zeta": float(table.zeta[i]), "k_n_per_m": float(table.k_n_per_m[i])}
            for i in range(len(table))
            if table.pose_index[i] == p
        ]
        entry["controller"] = controllers[pose_id]
        entries.append(entry)
    return entries

