"""`posedyn sweep`: the workspace through the per-pose chain on Dask, with an HTML report."""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from pathlib import Path
from typing import Optional

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn, TimeRemainingColumn

from posedyn.errors import InputError
from posedyn.io.cut import read_cut
from service import html
from service.cli.common import console, resolve_cut
from service.sweep import SweepSpec, run_sweep, write_report
from service.sweep.spec import DEFAULT_CHUNK_SIZE


def sweep(
    model_dir: Optional[Path] = typer.Argument(None, help="Model directory (or give --twin)."),
    twin: Optional[Path] = typer.Option(None, "--twin", help="Robot twin file instead of a model (modes from the twin, no uncertainty)."),
    grid: Path = typer.Option(..., "--grid", help="Pose grid (TOML) or pose list / tool path (CSV with the pose columns)."),
    cut: Optional[Path] = typer.Option(None, "--cut", help="Cut file (TOML; default: MODEL_DIR/cut.toml); an \\[sle] section adds the surface-location-error map."),
    absorber: Optional[Path] = typer.Option(None, "--absorber", help="Absorber file (default: seed 004's design)."),
    actuator: Optional[Path] = typer.Option(None, "--actuator", help="Actuator file (default: seed 000's)."),
    out: Path = typer.Option(..., "--out", help="Output directory: chunks/, results.csv, results.parquet, report.html."),
    workers: int = typer.Option(2, "--workers", min=1, help="Local Dask workers (processes)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Address of a running Dask scheduler instead of a local cluster (the input files must be readable by its workers)."),
    resume: bool = typer.Option(False, "--resume", help="Keep the chunks already in --out and compute only the missing ones."),
    policy: str = typer.Option("match", "--policy", help="Absorber target: match (dominant chatter), sims (max-min Re G; slow) or depth (the largest critical depth; slow)."),
    steps: Optional[int] = typer.Option(None, "--steps", min=4, help="Expert override: semi-discretization steps per delay instead of the converged engine (error not estimated)."),
    chunk_size: int = typer.Option(DEFAULT_CHUNK_SIZE, "--chunk-size", min=1, help="Poses per chunk (the unit of work, of writing and of resuming)."),
    robust_samples: int = typer.Option(0, "--robust-samples", min=0, max=2000, help="> 0 (8 or more): the guaranteed depths (95 % lower bounds) over that many samples of each pose's modes, and the robust absorber setting; seconds per pose. Needs a model."),
    lobes: bool = typer.Option(True, "--lobes/--no-lobes", help="Stability lobes at three representative poses in the report."),
    lobe_speeds: int = typer.Option(40, "--lobe-speeds", min=2, max=2000, help="Speeds of each report lobe (0.5-1.5 x the cut's speed); each is a verified solve without and with the absorber."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary instead of the table."),
):
    """Sweep the workspace: modes, chatter, absorber field, controller gain and SLE at every pose, on Dask; writes a self-contained HTML report."""
    started = time.perf_counter()
    if (model_dir is None) == (twin is None):
        raise InputError("either MODEL_DIR or --twin TWIN.toml", column="--twin")
    cut = resolve_cut(cut, model_dir)
    for path in filter(None, (model_dir, twin, grid, cut, absorber, actuator)):
        if not path.exists():
            raise InputError("an existing file or directory", got="missing", file=str(path))
    spec = SweepSpec(
        poses=str(grid.resolve()),
        cut=str(cut.resolve()),
        model=str(model_dir.resolve()) if model_dir else None,
        twin=str(twin.resolve()) if twin else None,
        absorber=str(absorber.resolve()) if absorber else None,
        actuator=str(actuator.resolve()) if actuator else None,
        policy=policy,
        steps=steps if steps is not None else read_cut(cut)[2],
        chunk_size=chunk_size,
        robust_samples=robust_samples,
    )
    show = sys.stderr.isatty() and not as_json
    with Progress("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn(), console=console, disable=not show) as bar:
        task = bar.add_task("chunks", total=None)
        outcome = run_sweep(spec, out, workers=workers, scheduler=scheduler, resume=resume, progress=lambda done, total: bar.update(task, completed=done, total=total),
                            lobe_speeds=lobe_speeds if lobes else 0)
    lobe_curves = outcome.lobes
    provenance = _provenance(spec, outcome, outcome.grid_twin)
    provenance["software"] = html.software_versions()
    provenance["written"] = html.now_utc()
    write_report(out / "report.html", outcome.rows, lobe_curves, provenance, title=f"Pose sweep: {grid.name}")
    summary = {
        "poses": len(outcome.rows),
        "reachable": sum(1 for r in outcome.rows if r.get("reachable")),
        "chunks_computed": outcome.computed_chunks,
        "chunks_resumed": outcome.skipped_chunks,
        "seconds": round(outcome.seconds, 2),
        "wall_seconds": round(time.perf_counter() - started, 2),
        "results": str(out / "results.csv"),
        "report": str(out / "report.html"),
    }
    if as_json:
        print(json.dumps(summary, indent=2))
        return
    console.print(
        f"{summary['poses']} poses ({summary['reachable']} reachable), {outcome.computed_chunks} chunks computed, "
        f"{outcome.skipped_chunks} resumed, the chunks in {outcome.seconds:.1f} s ({summary['wall_seconds']:.1f} s in all: Dask's start, the lobes, the report)\nresults: {summary['results']}\nreport:  {summary['report']}"
    )


def _provenance(spec, outcome, grid_twin) -> dict:
    files = spec.input_files()
    if grid_twin:
        files["grid twin"] = grid_twin
    out = {"fingerprint": outcome.manifest["fingerprint"]}
    if spec.model:
        doc = json.loads(Path(spec.model, "model.json").read_text(encoding="utf-8"))
        out["model"] = {"directory": spec.model, "schema_version": doc.get("schema_version"), "method": doc.get("method"), "training_data_hash": doc.get("training_data_hash")}
    out["inputs"] = {role: f"{path} (sha256 {hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]})" for role, path in files.items()}
    cut, rpm, _ = read_cut(spec.cut)
    out["cut"] = {"rpm": rpm, "teeth": cut.teeth, "kt_mpa": cut.kt_pa / 1e6, "kn_mpa": cut.kn_pa / 1e6, "radial_immersion": cut.radial_immersion, "milling": cut.milling}
    out["settings"] = {"policy": spec.policy, "steps": spec.steps, "chunk_size": spec.chunk_size, "robust_samples": spec.robust_samples, "workers": outcome.workers}
    out["command"] = " ".join(["posedyn"] + sys.argv[1:]) if os.path.basename(sys.argv[0]).startswith("posedyn") else "(library call)"
    return out
