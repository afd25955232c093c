"""`posedyn plan`: the coil's voltage and current along a timed tool path (absorber.field_plan)."""

from __future__ import annotations

import csv
import io
import sys
from pathlib import Path
from typing import Optional

import numpy as np
import typer

from absorber.chain import ScheduleConfig, absorber_depths_m, depth_weight, schedule_poses, table_pose_modes
from absorber.field_plan import FieldPlanner, simulate, step_schedule
from absorber.files import read_absorber, read_drive
from posedyn.io.atomic import write_text_atomic
from posedyn.io.cut import read_cut
from posedyn.io.modal_csv import read_tool_path
from posedyn.errors import InputError
from service.cli.absorber import Policy
from service.cli.common import console, output_folder, print_json, resolve_cut
from service.cli.inputs import modal_table_for, twin_modes_at

COLUMNS = ("time_s", "pose_id", "target_hz", "voltage_v", "current_a", "field_mt", "fluid_field_mt", "temperature_c", "frequency_hz", "step_frequency_hz", "step_current_a")


def plan(
    model_dir: Optional[Path] = typer.Argument(None, help="Model directory (or give --modes or --twin)."),
    modes: Optional[Path] = typer.Option(None, "--modes", help="Modal table with the path's poses instead of a model."),
    twin: Optional[Path] = typer.Option(None, "--twin", help="Robot twin file: its modes at the path's poses (3-D mode shapes) instead of a model."),
    path: Path = typer.Option(..., "--path", help="Timed tool path: the pose columns and time_s (s, increasing), one row per point."),
    cut: Optional[Path] = typer.Option(None, "--cut", help="Cut file (default: MODEL_DIR/cut.toml)."),
    absorber: Optional[Path] = typer.Option(None, "--absorber", help="Absorber file (default: seed 004's design)."),
    policy: Policy = typer.Option(Policy.match, "--policy"),
    out: Path = typer.Option(..., "--out", help="Folder: trajectory.csv and trajectory.png."),
    as_json: bool = typer.Option(False, "--json"),
):
    """Plan the coil's voltage along a tool path so the absorber stays on each point's target (CasADi, IPOPT)."""
    poses, time_s = read_tool_path(path)
    output_folder(out, "--out")
    if len(time_s) < 2:
        raise InputError("a path of at least two points", got=len(time_s), file=str(path), column="time_s")
    the_cut, rpm, steps = read_cut(resolve_cut(cut, model_dir))
    config = ScheduleConfig(the_cut, rpm, read_absorber(absorber), policy=policy.value, steps=steps, absolute_limits=False)
    columns = np.column_stack(list(poses.numeric_columns().values()))
    unique, back = np.unique(columns, axis=0, return_inverse=True)  # a path dwells: each distinct pose once
    first = [int(np.flatnonzero(back.ravel() == u)[0]) for u in range(len(unique))]
    entries = schedule_poses(_path_modes(model_dir, modes, twin, poses.subset(first), path), config)
    weights = [_weight(e, config) for e in entries]
    back = back.ravel()
    target = np.array([entries[u].absorber.target_hz for u in back])
    weight = np.array([weights[u] for u in back])
    coil, drive = config.coil, read_drive(absorber)
    result = FieldPlanner(len(time_s) - 1, config.absorber, coil, drive).solve(time_s, target, weight)
    if result.solver["status"] != "solved":  # IPOPT's last iterate: no plan to write or compare (a 0 to 1e9 s path was 95 % off in re-simulation)
        print(f"error: the coil planner did not converge ({result.solver['status']} after {result.solver['iterations']} iterations) on {path}'s "
              f"times ({time_s[0]:g} to {time_s[-1]:g} s): nothing written", file=sys.stderr)
        raise typer.Exit(1)
    check = simulate(coil, drive, config.absorber, time_s, result.voltage_v)
    baseline = step_schedule(coil, drive, config.absorber, time_s, target)
    lo, hi = config.absorber.range_hz
    reachable = np.clip(target, lo, hi)
    planned_depth = _depths(entries, back, result.frequency_hz, result.fluid_field_t, config)
    step_depth = _depths(entries, back, baseline[4], baseline[1], config)
    summary = {
        "points": len(time_s),
        "solver": result.solver,
        "plan": {"max_mistune_pct": float(100 * np.max(np.abs(result.frequency_hz[1:] / reachable[1:] - 1))),
                 "max_voltage_v": float(np.max(np.abs(result.voltage_v))), "max_temperature_c": float(result.temperature_c.max())},
        "step_schedule": {"max_mistune_pct": float(100 * np.max(np.abs(baseline[4][1:] / reachable[1:] - 1))), "asked_voltage_v": float(baseline[5])},
        "min_critical_depth_mm": {"plan": float(1e3 * planned_depth[1:].min()), "step_schedule": float(1e3 * step_depth[1:].min())},
        "resimulation_max_rel_error": float(np.max(np.abs(check[3] - result.current_a)) / max(np.max(np.abs(check[3])), 1e-12)),
        "outside_absorber_range": int(np.sum((target < lo) | (target > hi))),
        "trajectory": str(out / "trajectory.csv"),
    }
    out.mkdir(parents=True, exist_ok=True)
    rows = zip(time_s, poses.pose_id, target, np.r_[result.voltage_v, np.nan], result.current_a, 1e3 * result.field_t, 1e3 * result.fluid_field_t,
               result.temperature_c, result.frequency_hz, baseline[4], baseline[3])
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(COLUMNS)
    writer.writerows([c if isinstance(c, str) else ("" if not np.isfinite(c) else repr(float(c))) for c in row] for row in rows)
    write_text_atomic(out / "trajectory.csv", buffer.getvalue())
    _plot(out / "trajectory.png", time_s, target, result, baseline)
    if as_json:
        print_json(summary)
        return
    plan_, step, depth = summary["plan"], summary["step_schedule"], summary["min_critical_depth_mm"]
    console.print(f"{summary['points']} points, solver {summary['solver']['status']} ({summary['solver']['iterations']} iterations); "
                  f"re-simulation within {100 * summary['resimulation_max_rel_error']:.2g} %")
    console.print(f"plan:          mistuned by {plan_['max_mistune_pct']:.3g} % at most, {plan_['max_voltage_v']:.3g} V, {plan_['max_temperature_c']:.3g} C; "
                  f"lowest critical depth {depth['plan']:.4g} mm")
    console.print(f"step schedule: mistuned by {step['max_mistune_pct']:.3g} % at most, asks {step['asked_voltage_v']:.3g} V; lowest critical depth {depth['step_schedule']:.4g} mm")
    if summary["outside_absorber_range"]:
        console.print(f"{summary['outside_absorber_range']} points target a frequency outside the absorber's range (clamped)")
    console.print(f"trajectory: {summary['trajectory']} (and .png)")


def _path_modes(model_dir, modes, twin, poses, path) -> list:
    """The PoseModes of the path's distinct poses from one source: a model, a modal table or the
    twin (every pose must be reachable)."""
    if sum(x is not None for x in (model_dir, modes, twin)) != 1:
        raise InputError("one mode source: MODEL_DIR, --modes MODAL.csv or --twin TWIN.toml", got="none" if model_dir is None and modes is None else "more than one", column="--twin")
    if twin is None:
        return table_pose_modes(modal_table_for(model_dir, modes, poses))
    return twin_modes_at(twin, poses, path)


def _depths(entries, pose_of_point, frequency_hz, fluid_field_t, config: ScheduleConfig) -> np.ndarray:
    """Critical depth (m) at every point with the absorber as a trajectory has it there; one
    solve per distinct pose and frequency (to 0.01 Hz), all in one batch."""
    keys = [(int(p), round(float(f), 2)) for p, f in zip(pose_of_point, frequency_hz)]
    found = {}
    for key, f, b in zip(keys, frequency_hz, fluid_field_t):
        found.setdefault(key, (f, b))
    depths = absorber_depths_m([entries[p].pose.dyn for p, _ in found], config, [f for f, _ in found.values()], [b for _, b in found.values()],
                               [entries[p].dominant_chatter_hz for p, _ in found])
    out = dict(zip(found, depths))
    return np.array([out[k] for k in keys])


def _weight(entry, config: ScheduleConfig) -> float:
    """The plan's weight of a pose: with the `depth` policy, how much depth mistuning costs there
    (`absorber.chain.depth_weight`, normalised below) discounted where the target itself is
    uncertain, 1 / (1 + (s_f / (zeta_a f))^2) with s_f the predicted std of the chatter mode's
    frequency and zeta_a f the absorber's half bandwidth; other policies: 1."""
    if config.policy != "depth":
        return 1.0
    a = entry.absorber
    curvature = depth_weight(entry.pose.dyn, config, a.target_hz, response_hz=entry.dominant_chatter_hz)
    spread = entry.pose.lowest_xy[5] / (config.absorber.damping_ratio(a.field_t) * a.target_hz)
    return 1e-3 + curvature / (1.0 + spread**2)


def _plot(path: Path, time_s, target, result, baseline) -> None:
    import matplotlib  # heavy (about 0.3 s): only when a figure is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # heavy (about 0.3 s): only when a figure is drawn

    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    axes[0].step(time_s, target, where="post", color="k", lw=0.8, label="target")
    axes[0].plot(time_s, result.frequency_hz, label="planned")
    axes[0].plot(time_s, baseline[4], "--", label="step schedule")
    axes[0].set_ylabel("absorber Hz")
    axes[0].legend()
    axes[1].step(time_s[:-1], result.voltage_v, where="post", label="voltage V")
    axes[1].plot(time_s, result.current_a * 10, label="current A x 10")
    axes[1].legend()
    axes[2].plot(time_s, result.temperature_c)
    axes[2].set_ylabel("temperature C")
    axes[2].set_xlabel("time s")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
