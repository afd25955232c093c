"""The `posedyn` command: the library's commands (`posedyn.cli`) plus the ones that sit on top of
every package (`sweep`). The entry point lives here so that imports run one way only:
posedyn <- absorber <- service."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Optional

import typer
from rich.markup import escape

from posedyn.cli import app
from posedyn.cli.common import console
from posedyn.errors import InputError


@app.command("sweep")
def sweep(
    model_dir: Optional[Path] = typer.Argument(None, help="Model directory (or give --twin)."),
    twin: Optional[Path] = typer.Option(None, "--twin", help="Robot twin file instead of a model (modes from the twin, no uncertainty)."),
    grid: Path = typer.Option(..., "--grid", help="Pose grid (TOML) or pose list / tool path (CSV with the pose columns)."),
    cut: Path = typer.Option(..., "--cut", help="Cut file (TOML); an [sle] section adds the surface-location-error map."),
    absorber: Optional[Path] = typer.Option(None, "--absorber", help="Absorber file (default: seed 004's design)."),
    actuator: Optional[Path] = typer.Option(None, "--actuator", help="Actuator file (default: seed 000's)."),
    out: Path = typer.Option(..., "--out", help="Output directory: chunks/, results.csv, results.parquet, report.html."),
    workers: int = typer.Option(2, "--workers", min=1, help="Local Dask workers (processes)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Address of a running Dask scheduler instead of a local cluster (the input files must be readable by its workers)."),
    resume: bool = typer.Option(False, "--resume", help="Keep the chunks already in --out and compute only the missing ones."),
    policy: str = typer.Option("match", "--policy", help="Absorber target: match (dominant chatter) or sims (max-min Re G; slow)."),
    steps: int = typer.Option(20, "--steps", min=4, help="Semi-discretization steps per delay (20: within about 1 % of 40)."),
    chunk_size: int = typer.Option(250, "--chunk-size", min=1, help="Poses per chunk (the unit of work, of writing and of resuming)."),
    lobes: bool = typer.Option(True, "--lobes/--no-lobes", help="Stability lobes at three representative poses in the report."),
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary instead of the table."),
):
    """Sweep the workspace: modes, chatter, absorber field, controller gain and SLE at every pose, on Dask; writes a self-contained HTML report."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn, TimeRemainingColumn

    from service.report import now_utc, software_versions, write_report
    from service.sweep import SweepSpec, representative_lobes
    from service.sweep_run import run_sweep

    if (model_dir is None) == (twin is None):
        raise InputError("either MODEL_DIR or --twin TWIN.toml", column="--twin")
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
        steps=steps,
        chunk_size=chunk_size,
    )
    show = sys.stderr.isatty() and not as_json
    with Progress("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn(), console=console, disable=not show) as bar:
        task = bar.add_task("chunks", total=None)
        outcome = run_sweep(spec, out, workers=workers, scheduler=scheduler, resume=resume, progress=lambda done, total: bar.update(task, completed=done, total=total))
    lobe_curves = representative_lobes(spec.to_json(), outcome.poses, outcome.rows, outcome.grid_twin) if lobes else []
    provenance = _provenance(spec, outcome, outcome.grid_twin)
    provenance["software"] = software_versions()
    provenance["written"] = now_utc()
    write_report(out / "report.html", outcome.rows, lobe_curves, provenance, title=f"Pose sweep: {grid.name}")
    summary = {
        "poses": len(outcome.rows),
        "reachable": sum(1 for r in outcome.rows if r.get("reachable")),
        "chunks_computed": outcome.computed_chunks,
        "chunks_resumed": outcome.skipped_chunks,
        "seconds": round(outcome.seconds, 2),
        "results": str(out / "results.csv"),
        "report": str(out / "report.html"),
    }
    if as_json:
        print(json.dumps(summary, indent=2))
        return
    console.print(
        f"{summary['poses']} poses ({summary['reachable']} reachable), {outcome.computed_chunks} chunks computed, "
        f"{outcome.skipped_chunks} resumed, {outcome.seconds:.1f} s\nresults: {summary['results']}\nreport:  {summary['report']}"
    )


@app.command("serve")
def serve(
    model: Path = typer.Option(..., "--model", help="Model directory (posedyn train)."),
    cell: str = typer.Option(..., "--cell", help="Cell name: keys live under cells/CELL/posedyn/."),
    cut: Path = typer.Option(..., "--cut", help="Default cut (TOML); a request's cut fields override it."),
    listen: list[str] = typer.Option([], "--listen", help="Zenoh endpoint to listen on (repeatable), e.g. tcp/0.0.0.0:7447."),
    connect: list[str] = typer.Option([], "--connect", help="Zenoh endpoint to connect to (repeatable)."),
    mode: str = typer.Option("peer", "--mode", help="peer (embedded, default), client or router."),
    config: Optional[Path] = typer.Option(None, "--config", help="Zenoh config (JSON5): TLS, authentication, access control."),
    state_dir: Optional[Path] = typer.Option(None, "--state-dir", help="Where published plans are kept (republished after a restart)."),
    absorber: Optional[Path] = typer.Option(None, "--absorber", help="Absorber file (default: seed 004's design)."),
    actuator: Optional[Path] = typer.Option(None, "--actuator", help="Actuator file (default: seed 000's)."),
    twin: Optional[Path] = typer.Option(None, "--twin", help="Twin file for the reachability check when the model has none."),
    max_payload_bytes: int = typer.Option(65536, "--max-payload-bytes", min=64),
    queue_size: int = typer.Option(32, "--queue-size", min=1, help="Requests waiting for a computation before 'busy'."),
    workers: int = typer.Option(1, "--workers", min=1, help="Computation threads."),
    stale_after_s: float = typer.Option(3600.0, "--stale-after-s", help="How long a schedule is valid for the cell."),
):
    """Serve per-pose schedules over Zenoh until SIGTERM or SIGINT."""
    import logging
    import signal
    import threading

    from service.requests import RequestError
    from service.scheduler import Scheduler
    from service.server import ScheduleService, ServiceSettings, zenoh_config

    if mode not in ("peer", "client", "router"):
        raise InputError("--mode peer, client or router", got=mode, column="--mode")
    for path in filter(None, (model, cut, config, absorber, actuator, twin)):
        if not path.exists():
            raise InputError("an existing file or directory", got="missing", file=str(path))
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        settings = ServiceSettings(cell, max_payload_bytes, queue_size, workers, stale_after_s)
    except RequestError as exc:
        raise InputError("a cell name of letters, digits, - or _", got=cell, column="--cell") from exc
    scheduler = Scheduler(model, cut, absorber, actuator, twin)
    try:
        conf = zenoh_config(config, mode, listen, connect)
    except Exception as exc:  # zenoh reports a bad config file or key as ZError / ValueError
        raise InputError("a valid Zenoh configuration", got=str(exc), file=str(config) if config else None) from None
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    service = ScheduleService(scheduler, settings, conf, state_dir)
    try:
        service.start()
    except Exception as exc:  # noqa: BLE001 - e.g. a port in use or a TLS file missing
        raise InputError("a Zenoh session that opens", got=str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__, file=str(config) if config else None) from None
    try:
        print(f"serving cells/{cell}/posedyn (model {scheduler.model_version[:12]}) mode {mode} listen {list(listen)} connect {list(connect)}", flush=True)
        while not stop.wait(0.5):
            pass
    finally:
        service.close()
        print("stopped", flush=True)


@app.command("query")
def query(
    cell: str = typer.Option(..., "--cell"),
    connect: list[str] = typer.Option([], "--connect", help="Endpoint of the service or of a router (repeatable)."),
    pose_json: Optional[str] = typer.Option(None, "--pose-json", help='One pose, e.g. \'{"x_mm": 1400, "y_mm": 0, "z_mm": 800, "beta_deg": 0}\'.'),
    plan: Optional[Path] = typer.Option(None, "--plan", help="A tool path: CSV with the pose columns."),
    plan_id: Optional[str] = typer.Option(None, "--plan-id", help="Plan id (default: the CSV's file name)."),
    cut_json: Optional[str] = typer.Option(None, "--cut-json", help="Cut fields overriding the service's default cut."),
    config: Optional[Path] = typer.Option(None, "--config", help="Zenoh config (JSON5), e.g. TLS certificates."),
    timeout_s: float = typer.Option(5.0, "--timeout-s"),
    as_json: bool = typer.Option(False, "--json"),
):
    """Ask the schedule service for a pose's schedule, or send it a tool path as a plan."""
    from service.client import ScheduleClient, ServiceError

    if (pose_json is None) == (plan is None):
        raise InputError("either --pose-json or --plan", column="--pose-json")
    cut = _json_option(cut_json, "--cut-json") if cut_json else None
    try:
        client = ScheduleClient(cell, connect=connect, config=config, timeout_s=timeout_s).open()
    except Exception as exc:  # noqa: BLE001 - zenoh could not open (no route, TLS refused)
        raise InputError("a Zenoh session that connects", got=str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__, column="--connect") from None
    try:
        if pose_json is not None:
            result = client.schedule(_json_option(pose_json, "--pose-json"), cut)
        else:
            from posedyn.io import read_pose_table

            poses = read_pose_table(plan)
            rows = []
            for i, pose_id in enumerate(poses.pose_id):
                row = {"pose_id": pose_id, **dict(zip(("x_mm", "y_mm", "z_mm"), map(float, poses.position_mm[i])))}
                names = ("beta_deg",) if poses.orientation == "beta" else ("a_deg", "b_deg", "c_deg")
                row.update(zip(names, map(float, poses.orientation_deg[i])))
                rows.append(row)
            result = client.plan(plan_id or plan.stem, rows, cut, timeout_s=max(timeout_s, 2.0 * len(rows)))
    except ServiceError as exc:
        print(f"error: {exc.code}: {exc.message}", file=sys.stderr)
        raise typer.Exit(3)
    finally:
        client.close()
    if as_json:
        print(json.dumps(result, indent=2))
        return
    entries = result.get("entries", [result])
    for e in entries:
        a = e["absorber"]
        console.print(
            f"{e['pose_id']}: critical depth {_g(e['critical_depth_mm'])} mm, chatter {_g(e['dominant_chatter_hz'])} Hz -> "
            f"absorber {_g(a['field_mt'])} mT, {_g(a['current_a'])} A{'' if a['feasible'] else ' (outside its range)'}, "
            f"critical depth with it {_g(e['critical_depth_with_absorber_mm'])} mm; DVF gain {_g(e['controller']['dvf_gain_ns_per_m'])} N s/m"
        )


def _g(value) -> str:
    return "-" if value is None else f"{value:.4g}"


DEFAULT_TWIN = Path(__file__).resolve().parents[1] / "datasets/robots/kr_r2700_twin.toml"


@app.command("gap")
def gap(
    measured: Path = typer.Option(..., "--measured", help="Measurement campaign (CSV; README 'Measurement campaigns')."),
    model: Optional[Path] = typer.Option(None, "--model", help="Model directory: its predictions are the baseline."),
    twin: bool = typer.Option(False, "--twin", help="The robot twin is the baseline (--twin-file to choose one)."),
    twin_file: Path = typer.Option(DEFAULT_TWIN, "--twin-file"),
    cut: Optional[Path] = typer.Option(None, "--cut", help="Cut for critical_depth_mm rows (default: seed 004's)."),
    absorber: Optional[Path] = typer.Option(None, "--absorber", help="Absorber for absorber_* rows (default: seed 004's)."),
    out: Path = typer.Option(..., "--out", help="Output directory: report.html, gap.json."),
    as_json: bool = typer.Option(False, "--json"),
):
    """Find where the model and the measurements disagree, name the missing effect, add it, show the gap shrink."""
    from posedyn.gap import analyse
    from posedyn.io.atomic import write_text_atomic
    from posedyn.io.measurements import read_measurements
    from service.gap_data import Baseline
    from service.gap_report import render

    if (model is None) == (not twin):
        raise InputError("either --model MODEL_DIR or --twin", column="--model")
    m = read_measurements(measured)
    baseline = Baseline(twin_file=None if model else twin_file, model_dir=model, cut_file=cut, absorber_file=absorber)
    y, m = baseline.predict(m)
    result = analyse(m, y)
    doc = result.to_json()
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out / "gap.json", json.dumps(doc, indent=2) + "\n")
    write_text_atomic(out / "report.html", render(m, y, result, f"Simulation vs measurement: {measured.name}"))
    if as_json:
        print(json.dumps(doc, indent=2))
        return
    console.print(f"RMS normalised residual {result.rmse_before:.3g} -> {result.rmse_after:.3g} (noise 1); chi-square p {result.noise_p_before:.2g} -> {result.noise_p_after:.2g}")
    for e in doc["effects"]:
        pars = ", ".join(f"{k} = {v:.4g} +- {e['parameter_std'][k]:.2g}" for k, v in e["parameters"].items())
        console.print(escape(f"named: {e['name']} ({pars}): {e['description']} [{e['source']}]"))
    for a in doc["ambiguous"]:
        console.print(f"undecided between {' and '.join(a['candidates'])}: {a['separating_measurement']}")
    if not result.explained:
        console.print("no named effect explains the rest; the residual depends on: " + (", ".join(f"{c['variable']} ({c['quantity']})" for c in doc["residual_correlates"]) or "nothing measured"))
    console.print(f"report: {out / 'report.html'}")


@app.command("gap-campaign")
def gap_campaign(
    out: Optional[Path] = typer.Option(None, "--out", help="Measurement campaign to write (CSV)."),
    hide: list[str] = typer.Option([], "--hide", help="An effect to hide, NAME:parameter=value (repeatable); see `posedyn gap-campaign --list`."),
    seed: int = typer.Option(0, "--seed"),
    poses: int = typer.Option(10, "--poses", min=2),
    twin_file: Path = typer.Option(DEFAULT_TWIN, "--twin-file"),
    list_effects: bool = typer.Option(False, "--list", help="List the library's effects and exit."),
):
    """A synthetic measurement campaign from the twin with named effects hidden in it (for trying and testing `posedyn gap`)."""
    from posedyn.gap import LIBRARY
    from posedyn.io.atomic import write_text_atomic
    from posedyn.io.measurements import format_measurements
    from service.gap_data import Baseline, generate_measurements

    if list_effects:
        for e in LIBRARY.values():
            console.print(escape(f"{e.name}: {', '.join(p.name for p in e.parameters)}; acts on {', '.join(e.quantities)} through {', '.join(e.depends_on)}: {e.description} [{e.source}]"))
        return
    if out is None:
        raise InputError("--out FILE.csv", column="--out")
    hidden = {}
    for text in hide:
        name, _, rest = text.partition(":")
        if name not in LIBRARY:
            raise InputError("an effect among " + ", ".join(LIBRARY), got=name, column="--hide")
        params = {}
        for item in filter(None, rest.split(",")):
            key, sep, value = item.partition("=")
            try:
                params[key.strip()] = float(value)
            except ValueError:
                raise InputError("NAME:parameter=number", got=text, column="--hide") from None
        expected = [p.name for p in LIBRARY[name].parameters]
        if sorted(params) != sorted(expected):
            raise InputError(f"the parameters {expected} for {name}", got=sorted(params), column="--hide")
        hidden[name] = params
    m = generate_measurements(Baseline(twin_file=twin_file), hidden, seed=seed, poses=poses)
    write_text_atomic(out, format_measurements(m, [c for c in m.conditions if not c.startswith("model_")]))
    console.print(f"wrote {len(m)} measurements to {out}" + (f" with {', '.join(hidden)} hidden" if hidden else ""))


def _json_option(text: str, option: str):
    try:
        return json.loads(text)
    except ValueError as exc:
        raise InputError("JSON", got=str(exc), column=option) from None


def _provenance(spec, outcome, grid_twin) -> dict:
    import hashlib

    from posedyn.io.cut import read_cut

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
    out["settings"] = {"policy": spec.policy, "steps": spec.steps, "chunk_size": spec.chunk_size, "workers": outcome.workers}
    out["command"] = " ".join(["posedyn"] + sys.argv[1:]) if os.path.basename(sys.argv[0]).startswith("posedyn") else "(library call)"
    return out


def main(argv: Optional[list[str]] = None) -> None:
    from posedyn.cli import main as posedyn_main

    posedyn_main(argv)
