"""Synthetic modal-test campaigns from the twin, with known truth and optional hidden effects.

For every pose: inverse kinematics, the effects' changes to the twin, the twin's modes, the
`count` lowest robot modes seen in each direction (frequency order, as modal tables number
modes; k_rd = w_r^2 / u_rd^2 per direction) plus the spindle modes (the shipped twin keeps all six
robot modes: its two lowest carry as little as 3 % of the tool tip's compliance in y at some poses of
seed 003's grid, and a mode left out can be the one that chatters; `least_kept_compliance` says
how much a smaller count leaves out), then measurement noise:
each of fn, zeta, k multiplied by exp(N(0, s)) with s the relative noise (log-normal keeps them
positive), and the same s written to the std_* columns. One seed gives the same table bit for
bit.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from posedyn.errors import InputError
from posedyn.robot.kinematics import Robot, ToolPose
from posedyn.robot.poses import pose_set as tool_pose_set
from posedyn.robot.twin import TwinModes, TwinParameters, twin_modes
from posedyn.robot.twin_effects import Effect
from posedyn.table import DIRECTIONS, ModalTable


@dataclass(frozen=True)
class GridPose:
    """A campaign pose: its label, tool pose, and how the table records its orientation."""

    label: str
    pose: ToolPose
    beta_deg: float | None = None  # None: record A/B/C


@dataclass(frozen=True)
class Noise:
    """Relative measurement noise (1 sigma, in percent) of fn, zeta and k."""

    fn_pct: float = 0.5
    zeta_pct: float = 10.0
    k_pct: float = 5.0

    def __post_init__(self):
        for name in ("fn_pct", "zeta_pct", "k_pct"):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0 <= value < 100):
                raise InputError("a noise level in [0, 100) percent", got=value, column=name)


def pose_modes(robot: Robot, grid_pose: GridPose, params: TwinParameters, effects=(), data=None) -> tuple[np.ndarray, TwinModes]:
    """Joint angles and modes at one pose with the effects applied."""
    data = data or robot.model.createData()
    q = robot.inverse(grid_pose.pose, data)
    for effect in effects:
        params = effect.twin_parameters(params, grid_pose)
    modes = twin_modes(robot, q, params, data)
    for effect in effects:
        modes = effect.modes(modes, grid_pose)
    return q, modes


def direction_rows(modes: TwinModes, direction: str, count: int):
    """(fn, zeta, k) of the `count` lowest robot modes as seen in `direction` (frequency order,
    as modal tables number modes), then the spindle modes of that direction."""
    k = modes.stiffness(direction)
    rows = [(modes.fn_hz[r], modes.zeta[r], k[r]) for r in range(count)]
    rows += [(m.fn_hz, m.zeta, m.k_n_per_m) for m in modes.spindle_modes.get(direction, ())]
    return rows


def kept_compliance(modes: TwinModes, direction: str, count: int) -> float:
    """The share of the tool tip's static robot compliance in `direction`, sum_r 1 / k_rd, that
    the `count` lowest robot modes carry (what a table of `direction_rows` keeps; 1 with all)."""
    compliance = 1.0 / modes.stiffness(direction)
    total = compliance.sum()
    return float(compliance[:count].sum() / total) if total > 0 else 1.0


def least_kept_compliance(robot: Robot, poses: list[GridPose], params: TwinParameters, effects: tuple[Effect, ...] = (),
                          directions: tuple[str, ...] = ("x", "y", "z")) -> tuple[float, str, str]:
    """(share, pose label, direction) where a campaign's tables keep the least of the tool tip's
    static robot compliance (`kept_compliance`); (1, "", "") when they keep every robot mode."""
    least = (1.0, "", "")
    if params.robot_modes_per_direction >= robot.model.nv:  # one robot mode per joint: all of them kept, nothing to recompute
        return least
    data = robot.model.createData()
    for grid_pose in poses:
        _, modes = pose_modes(robot, grid_pose, params, effects, data)
        for direction in directions:
            share = kept_compliance(modes, direction, params.robot_modes_per_direction)
            if share < least[0]:
                least = (share, grid_pose.label, direction)
    return least


def generate_campaign(
    robot: Robot,
    poses: list[GridPose],
    params: TwinParameters,
    noise: Noise = Noise(),
    seed: int = 0,
    effects: tuple[Effect, ...] = (),
    directions: tuple[str, ...] = ("x", "y", "z"),
    source: str = "twin",
) -> ModalTable:
    if not poses:
        raise InputError("at least one pose in the grid", got=0)
    bad = [d for d in directions if d not in DIRECTIONS]
    if bad:
        raise InputError("directions among x, y, z", got=bad, column="directions")
    rng = np.random.default_rng(seed)
    sigma = np.array([noise.fn_pct, noise.zeta_pct, noise.k_pct]) / 100.0
    data = robot.model.createData()
    columns = {key: [] for key in ("pose_index", "direction", "mode", "fn_hz", "zeta", "k_n_per_m")}
    std = {"std_fn_hz": [], "std_zeta": [], "std_k_n_per_m": []}
    joints = []
    for index, grid_pose in enumerate(poses):
        q, modes = pose_modes(robot, grid_pose, params, effects, data)
        joints.append(np.degrees(q))
        for direction in directions:
            for number, (fn, zeta, k) in enumerate(direction_rows(modes, direction, params.robot_modes_per_direction), 1):
                factors = np.exp(rng.normal(0.0, 1.0, 3) * sigma)
                measured = np.array([fn, zeta, k]) * factors
                measured[1] = min(measured[1], 0.99)
                columns["pose_index"].append(index)
                columns["direction"].append(direction)
                columns["mode"].append(number)
                columns["fn_hz"].append(measured[0])
                columns["zeta"].append(measured[1])
                columns["k_n_per_m"].append(measured[2])
                std["std_fn_hz"].append(measured[0] * sigma[0])
                std["std_zeta"].append(measured[1] * sigma[1])
                std["std_k_n_per_m"].append(measured[2] * sigma[2])
    tool_poses = [replace(g.pose, label=g.label) for g in poses]
    pose_set = replace(tool_pose_set(tool_poses, [g.beta_deg for g in poses]), joints_deg=np.array(joints))
    n = len(columns["fn_hz"])
    return ModalTable(poses=pose_set, std=std, source=(source,) * n, **columns)
