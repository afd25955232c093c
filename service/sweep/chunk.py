"""One chunk of a workspace sweep: every pose of the chunk through the per-pose chain
(`absorber.chain.schedule_poses`: modes -> critical depth and dominant chatter -> absorber
target, field, current -> critical depth with the absorber -> DVF gain and actuator force), plus
the surface location error when the cut asks for it.

A chunk is a pure function of the sweep's inputs and its poses (`compute_chunk`), so chunks can
run anywhere (a Dask worker) in any order, be written as they finish and be skipped on a
resumed run (`service.sweep.runner`). The modes come from a trained model (with their std) or
straight from the robot twin.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from absorber.chain import PoseModes, ScheduleConfig, coupled, schedule_poses, table_pose_modes, twin_pose_modes
from absorber.files import load_tuning_cache, read_absorber, read_actuator, save_tuning_cache
from absorber.tuning import known_tunings
from posedyn.io.cut import read_cut, read_sle_cut
from posedyn.io.model_dir import load_model, model_robot
from posedyn.io.twin_file import load_twin
from posedyn.posemodel import PoseModel
from posedyn.robot import Robot, TwinParameters, reachable_joints, with_joints
from posedyn.sle import SleCut, sle_m
from posedyn.stability import critical_lobes
from posedyn.table import PoseSet
from service.sweep.spec import RESULT_COLUMNS, SweepSpec


@dataclass(frozen=True, eq=False)
class SweepContext:
    """Everything a chunk needs, read once per process: the mode source (a model, or the twin's
    parameters), the robot for the reachability check, the chain's settings, the SLE cut."""

    spec: SweepSpec
    model: PoseModel | None
    robot: Robot  # decides which poses are reachable
    twin_params: TwinParameters | None
    schedule: ScheduleConfig
    sle_cut: tuple[SleCut, float] | None  # and the offset (m) the cut file adds to its SLE


@lru_cache(maxsize=4)
def context(spec_json: str, grid_twin: str | None = None) -> SweepContext:
    spec = SweepSpec(**json.loads(spec_json))
    load_tuning_cache()  # once per worker process: the virtual absorber's optima of earlier runs
    cut, rpm, _ = read_cut(spec.cut)
    control = read_actuator(Path(spec.actuator) if spec.actuator else None)
    schedule = ScheduleConfig(cut, rpm, read_absorber(spec.absorber), control=control, policy=spec.policy, steps=spec.steps, absolute_limits=False,
                              robust_samples=spec.robust_samples)
    model = robot = params = None
    if spec.model:
        model = load_model(spec.model)
        robot = model_robot(model, grid_twin)  # the model's twin, else the grid's, else the shipped one
    else:
        robot, params = load_twin(spec.twin)
    return SweepContext(spec, model, robot, params, schedule, read_sle_cut(spec.cut))


def pose_modes_of(ctx: SweepContext, poses: PoseSet, index: list[int]) -> dict[int, PoseModes]:
    """{pose index: PoseModes} of the reachable poses among `index`."""
    return _model_modes(ctx, poses, index) if ctx.model is not None else _twin_modes(ctx, poses, index)


def _twin_modes(ctx: SweepContext, poses: PoseSet, index: list[int]) -> dict[int, PoseModes]:
    return twin_pose_modes(ctx.robot, ctx.twin_params, poses, index)


def _model_modes(ctx: SweepContext, poses: PoseSet, index: list[int]) -> dict[int, PoseModes]:
    found = reachable_joints(ctx.robot, poses, index)
    reachable = sorted(found)
    if not reachable:
        return {}
    subset = with_joints(poses.subset(reachable), {k: found[i] for k, i in enumerate(reachable)})
    table = ctx.model.predict_table(subset)
    distributions = ctx.model.predict_distributions(subset, table) if ctx.schedule.robust_samples else None
    return dict(zip(reachable, table_pose_modes(table, distributions)))


def compute_chunk(spec_json: str, poses: PoseSet, grid_twin: str | None = None) -> list[dict]:
    """Result rows (dicts, `RESULT_COLUMNS` plus pose and mode columns) for a PoseSet."""
    ctx = context(spec_json, grid_twin)
    known = len(known_tunings())
    index = list(range(len(poses)))
    found = pose_modes_of(ctx, poses, index)
    rows = poses.records()
    for i in index:
        rows[i].update({c: None for c in RESULT_COLUMNS})
        rows[i]["reachable"] = i in found
        rows[i]["flags"] = "" if i in found else "unreachable"
    order = sorted(found)
    for i, result in zip(order, schedule_poses([found[i] for i in order], ctx.schedule)):
        rows[i].update(_result_columns(result))
        if ctx.sle_cut is not None:
            sle_cut, offset_m = ctx.sle_cut
            rows[i]["sle_um"] = float(sle_m(found[i].dyn, sle_cut, ctx.schedule.rpm, offset_m=offset_m)[0]) * 1e6
    if len(known_tunings()) > known:
        save_tuning_cache()
    return rows


def _result_columns(result) -> dict:
    pose, a, c = result.pose, result.absorber, result.controller
    row = {}
    for d, m, fn, zeta, k, std in pose.rows:
        row.update({f"fn_{d}{m}_hz": fn, f"std_fn_{d}{m}_hz": std, f"zeta_{d}{m}": zeta, f"k_{d}{m}_n_per_m": k})
    lowest = pose.lowest_xy
    flags = []
    if not a.feasible:
        flags.append("outside_absorber_range")
    if c is None or not (c["dvf_gain_ns_per_m"] > 0 and c["virtual_absorber"]["force_ok"]):
        flags.append("force_limit")
    if result.stability.converged is False or result.stability_with_absorber.converged is False:
        flags.append("stability_not_converged")
    if result.stability.surface_memory:  # the depth is an asymptotic boundary only (`free_flight_decay`)
        flags.append("surface_memory")
    errors = [r.rel_error_estimate for r in (result.stability, result.stability_with_absorber) if math.isfinite(r.rel_error_estimate)]
    row.update(
        lowest_fn_hz=lowest[2],
        lowest_fn_std_hz=lowest[5],
        critical_depth_mm=_mm(result.critical_depth_m),
        no_growth_depth_mm=_mm(result.stability.no_growth_depth_m),  # (where only the surface remembers the last pass)
        dominant_chatter_hz=result.dominant_chatter_hz,
        target_hz=a.target_hz,
        field_mt=a.field_t * 1e3,
        current_a=a.current_a if math.isfinite(a.current_a) else None,
        absorber_feasible=a.feasible,
        critical_depth_with_absorber_mm=_mm(result.critical_depth_with_absorber_m),
        actuator_direction=c["direction"] if c else None,
        dvf_gain_ns_per_m=c["dvf_gain_ns_per_m"] if c else None,
        gain_margin_db=c["gain_margin_db"] if c and math.isfinite(c["gain_margin_db"]) else None,
        controller_force_n=c["max_force_n"] if c else None,
        dynamic_stiffness_gain_pct=c["dynamic_stiffness_gain_pct"] if c else None,
        **_robust_columns(result.robust),
        stability_method=result.stability.method,
        stability_rel_error=max(errors) if errors else None,
        flags=";".join(flags),
    )
    return row


def _robust_columns(robust) -> dict:
    if robust is None:
        return {}
    return {
        "critical_depth_p95_mm": _mm(robust.depth_p95_m),
        "critical_depth_cv_pct": 100 * robust.depth_cv if math.isfinite(robust.depth_cv) else None,
        "robust_tuning": robust.tuning,
        "robust_target_hz": robust.absorber.target_hz,
        "robust_field_mt": robust.absorber.field_t * 1e3,
        "critical_depth_with_absorber_p95_mm": _mm(robust.depth_with_absorber_p95_m),
        "robust_dvf_gain_ns_per_m": robust.controller["dvf_gain_ns_per_m"] if robust.controller else None,
    }


def _mm(depth_m: float):
    return depth_m * 1e3 if math.isfinite(depth_m) else None


# --- lobes at representative poses -------------------------------------------------------------


def representative_lobes(spec_json: str, poses: PoseSet, rows: list[dict], grid_twin: str | None = None, speeds: int = 40, mapper=None) -> list[dict]:
    """Stability lobes (`posedyn.stability.critical_lobes`, the sweep's engine) from 0.5 to 1.5 times the
    cut's speed, without and with the absorber at its scheduled field, at the poses with the
    smallest, the median and the largest critical depth. `mapper(fn, jobs)` -> [fn(job), ...]
    computes the curves (default here, one after the other; the sweep runs them on its cluster)."""
    ctx = context(spec_json, grid_twin)
    ranked = sorted((r["critical_depth_mm"], i) for i, r in enumerate(rows) if r.get("critical_depth_mm") is not None and r.get("field_mt") is not None)
    if not ranked:
        return []
    picks = {"softest": ranked[0][1], "median": ranked[len(ranked) // 2][1], "stiffest": ranked[-1][1]}
    found = pose_modes_of(ctx, poses, sorted(set(picks.values())))
    rpm = np.linspace(0.5, 1.5, speeds) * ctx.schedule.rpm
    chosen, jobs = [], []
    for label, i in picks.items():
        if i not in found or any(poses.pose_id[i] == poses.pose_id[k] for _, k in chosen):
            continue
        chosen.append((label, i))
        field_t = rows[i]["field_mt"] * 1e-3
        chatter_hz = rows[i].get("dominant_chatter_hz")
        jobs += [(dyn, ctx.schedule.cut, rpm, ctx.schedule.steps) for dyn in (found[i].dyn, coupled(found[i].dyn, ctx.schedule, field_t, chatter_hz))]
    curves = (mapper or (lambda fn, items: [fn(x) for x in items]))(lobe_depths_mm, jobs)
    return [{"label": label, "pose_id": poses.pose_id[i], "rpm": rpm.tolist(), "depth_mm": curves[2 * q], "depth_with_absorber_mm": curves[2 * q + 1],
             "field_mt": rows[i]["field_mt"], "cut_rpm": ctx.schedule.rpm} for q, (label, i) in enumerate(chosen)]


def lobe_depths_mm(job) -> list:
    """One lobe curve, (structure, cut, rpm, steps) -> critical depths in mm (None: never chatters)."""
    dyn, cut, rpm, steps = job
    return [r.depth_m * 1e3 if math.isfinite(r.depth_m) else None for r in critical_lobes(dyn, cut, rpm, steps)]
