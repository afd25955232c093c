"""Workspace sweeps: every pose of a grid or a tool path through the whole chain

    modes (+-std) -> critical depth and dominant chatter -> absorber target, field, current ->
    critical depth with the absorber -> DVF gain and actuator force -> surface location error

one chunk of poses at a time. A chunk is a pure function of the sweep's inputs and its poses
(`compute_chunk`), so chunks can run anywhere (a Dask worker) in any order, be written as they
finish and be skipped on a resumed run (`service.sweep_run`).

Stability runs batched over the chunk's poses at the cut's speed (`BatchStability`); the
absorber target follows the schedule's policy (`match` by default: the dominant chatter
frequency, seed 004); the controller is `absorber.active.control_schedule_pose` (seed 000).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from posedyn.errors import InputError, check_choice

#: Columns of results.csv, in order (the pose columns and the per-mode columns come first).
RESULT_COLUMNS = (
    "reachable",
    "lowest_fn_hz",
    "lowest_fn_std_hz",
    "critical_depth_mm",
    "dominant_chatter_hz",
    "target_hz",
    "field_mt",
    "current_a",
    "absorber_feasible",
    "critical_depth_with_absorber_mm",
    "actuator_direction",
    "dvf_gain_ns_per_m",
    "gain_margin_db",
    "controller_force_n",
    "dynamic_stiffness_gain_pct",
    "sle_um",
    "flags",
)


@dataclass(frozen=True)
class SweepSpec:
    """The inputs of a sweep: file paths (absolute; every worker reads them itself) and settings.

    `model` (a model directory) or `twin` (a robot-twin file) gives the modes; `poses` is a grid
    (TOML) or a pose list (CSV); `cut` a cut file, optionally with an `[sle]` section;
    `steps` is the semi-discretization's steps per delay (20: depths within about 1 % of 40)."""

    poses: str
    cut: str
    model: str | None = None
    twin: str | None = None
    absorber: str | None = None
    actuator: str | None = None
    policy: str = "match"
    steps: int = 20
    chunk_size: int = 250

    def __post_init__(self):
        if (self.model is None) == (self.twin is None):
            raise InputError("either a model directory or a twin file", got={"model": self.model, "twin": self.twin}, column="model")
        check_choice("policy", self.policy, ("match", "sims"))
        if not isinstance(self.steps, int) or self.steps < 4:
            raise InputError("an integer number of steps >= 4", got=self.steps, column="steps")
        if not isinstance(self.chunk_size, int) or self.chunk_size < 1:
            raise InputError("a chunk size >= 1", got=self.chunk_size, column="chunk_size")

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    def input_files(self) -> dict[str, str]:
        """Every file the sweep reads, by role (model directories as their two files)."""
        files = {"poses": self.poses, "cut": self.cut}
        for role in ("twin", "absorber", "actuator"):
            if getattr(self, role):
                files[role] = getattr(self, role)
        if self.model:
            files["model.json"] = str(Path(self.model) / "model.json")
            files["arrays.npz"] = str(Path(self.model) / "arrays.npz")
        return files

    def fingerprint(self) -> str:
        """SHA-256 over the settings and the bytes of every input file: a resumed sweep must
        see the same fingerprint as the one that wrote the chunks."""
        h = hashlib.sha256(self.to_json().encode())
        for role, path in sorted(self.input_files().items()):
            h.update(role.encode())
            h.update(_file_bytes(path))
        return h.hexdigest()


def _file_bytes(path: str) -> bytes:
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise InputError("a readable file", got=exc.strerror, file=path) from None


# --- poses ---------------------------------------------------------------------------------


def read_sweep_poses(path: str):
    """The poses of a sweep as a PoseSet, and the twin file a grid names (or None): a grid
    (TOML, `posedyn.io.grid`) or a pose list (CSV with the pose columns, e.g. a tool path)."""
    from posedyn.io import read_pose_table
    from posedyn.table import PoseSet

    if Path(path).suffix.lower() == ".toml":
        from posedyn.io.grid import read_grid
        from posedyn.robot import abc_from_rotation

        grid = read_grid(path)
        beta = all(g.beta_deg is not None for g in grid.poses)
        angles = [[g.beta_deg] if beta else np.degrees(abc_from_rotation(g.pose.rotation)) for g in grid.poses]
        poses = PoseSet(
            pose_id=tuple(g.label for g in grid.poses),
            position_mm=np.array([g.pose.position_m * 1e3 for g in grid.poses]),
            orientation="beta" if beta else "abc",
            orientation_deg=np.array(angles),
        )
        return poses, (str(grid.twin) if grid.twin else None)
    return read_pose_table(path), None


def tool_pose(poses, i: int):
    from posedyn.robot import ToolPose

    x, y, z = poses.position_m[i]
    if poses.orientation == "beta":
        return ToolPose.from_beta(x, y, z, math.radians(poses.orientation_deg[i, 0]), poses.pose_id[i])
    return ToolPose.from_abc(x, y, z, *np.radians(poses.orientation_deg[i]), poses.pose_id[i])


# --- per-process context ---------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class SweepContext:
    """Everything a chunk needs, read once per process: the mode source, the robot for the
    reachability check, the cut, the absorber schedule and control settings, the SLE cut."""

    spec: SweepSpec
    model: object | None
    robot: object | None
    twin_params: object | None
    schedule: object
    control: object
    sle_cut: object | None
    rpm: float
    mode_keys: tuple = field(default_factory=tuple)


@lru_cache(maxsize=4)
def context(spec_json: str, grid_twin: str | None = None) -> SweepContext:
    from absorber.mrf import MRFAbsorber
    from absorber.schedule import ScheduleConfig
    from posedyn.io.cut import read_cut, read_sle_cut
    from posedyn.io.grid import read_twin
    from posedyn.robot import Robot

    from posedyn.cli.control import read_actuator

    spec = SweepSpec(**json.loads(spec_json))
    cut, rpm, _ = read_cut(spec.cut)
    absorber = MRFAbsorber.from_toml(spec.absorber) if spec.absorber else MRFAbsorber()
    schedule = ScheduleConfig(cut, rpm, absorber, policy=spec.policy, steps=spec.steps)
    model = robot = params = None
    if spec.model:
        from posedyn.io.model_dir import load_model

        model = load_model(spec.model)
        if model.twin is not None:
            robot = model.twin[0]
        elif grid_twin:
            twin = read_twin(grid_twin)
            robot = Robot.from_urdf(twin.urdf, payload_kg=twin.payload_kg)
    else:
        twin = read_twin(spec.twin)
        robot, params = Robot.from_urdf(twin.urdf, payload_kg=twin.payload_kg), twin.params
    return SweepContext(spec, model, robot, params, schedule, read_actuator(Path(spec.actuator) if spec.actuator else None), read_sle_cut(spec.cut), rpm)


# --- one chunk -------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class PoseModes:
    """One reachable pose: its tool-tip dynamics and its table rows (direction, mode, fn_hz,
    zeta, k_n_per_m, std_fn_hz)."""

    dyn: object
    rows: list
    rotation: np.ndarray


def _twin_modes(ctx: SweepContext, poses, index: list[int]):
    from posedyn.campaign import GridPose, direction_rows, pose_modes

    data = ctx.robot.model.createData()
    count = ctx.twin_params.robot_modes_per_direction
    out = {}
    for i in index:
        pose = tool_pose(poses, i)
        try:
            _, modes = pose_modes(ctx.robot, GridPose(pose.label, pose), ctx.twin_params, data=data)
        except InputError:
            continue
        rows = [(d, m, fn, z, k, 0.0) for d in ("x", "y", "z") for m, (fn, z, k) in enumerate(direction_rows(modes, d, count), 1)]
        out[i] = PoseModes(modes.dynamics(), rows, pose.rotation)
    return out


def _model_modes(ctx: SweepContext, poses, index: list[int]):
    from posedyn.dynamics import ToolTipDynamics
    from posedyn.table import PoseSet

    reachable, joints = [], []
    data = ctx.robot.model.createData() if ctx.robot is not None else None
    for i in index:
        if ctx.robot is None:
            reachable.append(i)
            continue
        try:
            joints.append(np.degrees(ctx.robot.inverse(tool_pose(poses, i), data)))
            reachable.append(i)
        except InputError:
            continue
    if not reachable:
        return {}
    subset = PoseSet(
        pose_id=tuple(poses.pose_id[i] for i in reachable),
        position_mm=poses.position_mm[reachable],
        orientation=poses.orientation,
        orientation_deg=poses.orientation_deg[reachable],
        joints_deg=np.array(joints) if ctx.robot is not None else None,
    )
    table = ctx.model.predict_table(subset)
    std = table.std.get("std_fn_hz", np.zeros(len(table)))
    out = {}
    for p, i in enumerate(reachable):
        rows = [
            (str(table.direction[r]), int(table.mode[r]), float(table.fn_hz[r]), float(table.zeta[r]), float(table.k_n_per_m[r]), float(std[r]))
            for r in np.flatnonzero(table.pose_index == p)
        ]
        out[i] = PoseModes(ToolTipDynamics.from_table(table, subset.pose_id[p]), rows, tool_pose(poses, i).rotation)
    return out


def compute_chunk(spec_json: str, poses, grid_twin: str | None = None) -> list[dict]:
    """Result rows (dicts, `RESULT_COLUMNS` plus pose and mode columns) for a PoseSet."""
    from absorber.schedule import coupled
    from posedyn.stability import Discretization

    ctx = context(spec_json, grid_twin)
    index = list(range(len(poses)))
    found = _model_modes(ctx, poses, index) if ctx.model is not None else _twin_modes(ctx, poses, index)
    rows = [_pose_columns(poses, i) for i in index]
    for i in index:
        rows[i].update({c: None for c in RESULT_COLUMNS})
        rows[i]["reachable"] = i in found
        rows[i]["flags"] = "" if i in found else "unreachable"
    if not found:
        return rows
    config = ctx.schedule
    disc = Discretization(config.steps)
    for i, pm in found.items():
        for d, m, fn, zeta, k, std in pm.rows:
            rows[i].update({f"fn_{d}{m}_hz": fn, f"std_fn_{d}{m}_hz": std, f"zeta_{d}{m}": zeta, f"k_{d}{m}_n_per_m": k})
        xy = [r for r in pm.rows if r[0] in ("x", "y")]
        lowest = min(xy, key=lambda r: r[2])
        rows[i]["lowest_fn_hz"], rows[i]["lowest_fn_std_hz"] = lowest[2], lowest[5]
    bare = _critical_by_group({i: pm.dyn for i, pm in found.items()}, config.cut, config.rpm, disc, frequencies=True)
    structures = {}
    for i, pm in found.items():
        depth, chatter_hz = bare[i]
        if not math.isfinite(chatter_hz):
            chatter_hz = float(pm.dyn.fn_hz[np.argmin(pm.dyn.fn_hz)])
        entry = _absorber_setting(pm, config, chatter_hz)
        rows[i].update(critical_depth_mm=_mm(depth), dominant_chatter_hz=chatter_hz, **entry["columns"])
        structures[i] = coupled(pm.dyn, config, entry["field_t"])
        if not entry["columns"]["absorber_feasible"]:
            rows[i]["flags"] = _flag(rows[i]["flags"], "outside_absorber_range")
    guess = {i: bare[i][0] for i in found if math.isfinite(bare[i][0])}
    with_absorber = _critical_by_group(structures, config.cut, config.rpm, disc, frequencies=False, guess=guess)
    for i in found:
        rows[i]["critical_depth_with_absorber_mm"] = _mm(with_absorber[i][0])
        rows[i].update(_controller(ctx, found[i]))
        if not rows[i].pop("_force_ok"):
            rows[i]["flags"] = _flag(rows[i]["flags"], "force_limit")
        if ctx.sle_cut is not None:
            from posedyn.sle import sle_m

            rows[i]["sle_um"] = float(sle_m(found[i].dyn, ctx.sle_cut, ctx.rpm)[0]) * 1e6
    return rows


def _critical_by_group(structures: dict, cut, rpm, disc, frequencies: bool, guess: dict | None = None) -> dict:
    """{pose index: (critical depth m, dominant chatter Hz)}, batched per mode count."""
    from posedyn.stability.batch import BatchStability

    out = {}
    groups: dict[int, list[int]] = {}
    for i, dyn in structures.items():
        groups.setdefault(dyn.n_modes, []).append(i)
    for members in groups.values():
        batch = BatchStability([structures[i] for i in members], cut, rpm, disc)
        # Short ladders from a guess: 7 times the single-mode estimate (the limit at a speed
        # lies 3-6 times above it on the twin's workspace), or twice the bare depth for the
        # structure with the absorber (it gains 1-5x). 0.2 % in depth is well inside the
        # discretization error (about 1 % at 20 steps).
        start = 7.0 * batch.scale_m
        if guess is not None:
            start = np.array([2.0 * guess[i] if i in guess else s for i, s in zip(members, start)])
        result = batch.critical_depths(frequencies=frequencies, rel_tol=2e-3, guess_m=start, rungs=2)
        for j, i in enumerate(members):
            out[i] = (float(result.depth_m[j]), float(result.dominant_chatter_hz[j]))
    return out


def _absorber_setting(pm: PoseModes, config, chatter_hz: float) -> dict:
    from absorber.schedule import absorber_setting

    target, setting, current, feasible = absorber_setting(pm.dyn, config, chatter_hz)
    return {
        "field_t": setting.field_t,
        "columns": {
            "target_hz": target,
            "field_mt": setting.field_t * 1e3,
            "current_a": current if math.isfinite(current) else None,
            "absorber_feasible": feasible,
        },
    }


def _controller(ctx: SweepContext, pm: PoseModes) -> dict:
    from absorber.active import actuator_direction, control_schedule_pose

    direction = actuator_direction(pm.rotation, ctx.control.mount_axis)
    modes = [(fn, zeta, k) for d, _, fn, zeta, k, _ in pm.rows if d == direction and fn < 500 and math.isfinite(k)]
    if not modes:
        return {"actuator_direction": direction, "_force_ok": True}
    e = control_schedule_pose("", modes, pm.rotation, ctx.control)
    return {
        "actuator_direction": direction,
        "dvf_gain_ns_per_m": e["dvf_gain_ns_per_m"],
        "gain_margin_db": e["gain_margin_db"] if math.isfinite(e["gain_margin_db"]) else None,
        "controller_force_n": e["max_force_n"],
        "dynamic_stiffness_gain_pct": e["dynamic_stiffness_gain_pct"],
        "_force_ok": e["dvf_gain_ns_per_m"] > 0 and e["virtual_absorber"]["force_ok"],
    }


def _pose_columns(poses, i: int) -> dict:
    row = {"pose_id": poses.pose_id[i]}
    for name, value in zip(("x_mm", "y_mm", "z_mm"), poses.position_mm[i]):
        row[name] = float(value)
    names = ("beta_deg",) if poses.orientation == "beta" else ("a_deg", "b_deg", "c_deg")
    for name, value in zip(names, poses.orientation_deg[i]):
        row[name] = float(value)
    return row


def _flag(flags: str, flag: str) -> str:
    return f"{flags};{flag}" if flags else flag


def _mm(depth_m: float):
    return depth_m * 1e3 if math.isfinite(depth_m) else None


# --- lobes at representative poses -------------------------------------------------------------


def representative_lobes(spec_json: str, poses, rows: list[dict], grid_twin: str | None = None, speeds: int = 80) -> list[dict]:
    """Stability lobes (semi-discretization, `steps` of the sweep) from 0.5 to 1.5 times the
    cut's speed, without and with the absorber at its scheduled field, at the poses with the
    smallest, the median and the largest critical depth."""
    from absorber.schedule import coupled
    from posedyn.stability import Discretization
    from posedyn.stability.batch import BatchStability

    ctx = context(spec_json, grid_twin)
    ranked = sorted((r["critical_depth_mm"], i) for i, r in enumerate(rows) if r.get("critical_depth_mm") is not None and r.get("field_mt") is not None)
    if not ranked:
        return []
    picks = {"softest": ranked[0][1], "median": ranked[len(ranked) // 2][1], "stiffest": ranked[-1][1]}
    index = sorted(set(picks.values()))
    found = _model_modes(ctx, poses, index) if ctx.model is not None else _twin_modes(ctx, poses, index)
    rpm = np.linspace(0.5, 1.5, speeds) * ctx.rpm
    disc = Discretization(ctx.schedule.steps)
    out = []
    for label, i in picks.items():
        if i not in found or any(e["pose_id"] == poses.pose_id[i] for e in out):
            continue
        field_t = rows[i]["field_mt"] * 1e-3
        curves = []
        for dyn in (found[i].dyn, coupled(found[i].dyn, ctx.schedule, field_t)):
            batch = BatchStability([dyn] * speeds, ctx.schedule.cut, rpm, disc)
            depth = batch.critical_depths(frequencies=False, rel_tol=1e-3, guess_m=7.0 * batch.scale_m, rungs=2).depth_m * 1e3
            curves.append([float(d) if np.isfinite(d) else None for d in depth])
        out.append({"label": label, "pose_id": poses.pose_id[i], "rpm": rpm.tolist(), "depth_mm": curves[0], "depth_with_absorber_mm": curves[1], "field_mt": rows[i]["field_mt"], "cut_rpm": ctx.rpm})
    return out
