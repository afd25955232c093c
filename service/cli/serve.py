"""`posedyn serve` and `posedyn query`: the Zenoh schedule service and its command-line client."""

from __future__ import annotations

import json
import math
import logging
import re
import signal
import sys
import threading
from pathlib import Path
from typing import Optional

import typer

from posedyn.errors import InputError
from posedyn.io import read_pose_table
from posedyn.io.modal_csv import read_tool_path
from service.cli.common import console, resolve_cut
from service.zenoh_service.client import ScheduleClient, ServiceError
from service.zenoh_service.protocol import CELL_RULE, PLAN_ID_RULE, RequestError, parse_cut, parse_pose, valid_cell, valid_plan_id
from service.zenoh_service.server import ScheduleService, ServiceSettings
from service.zenoh_service.session import DEFAULT_LISTEN, zenoh_config
from service.zenoh_service.signing import read_key
from service.zenoh_service.workers import EngineSpec


def serve(
    model: Path = typer.Option(..., "--model", help="Model directory (posedyn train)."),
    cell: str = typer.Option(..., "--cell", help="Cell name: keys live under cells/CELL/posedyn/."),
    cut: Optional[Path] = typer.Option(None, "--cut", help="Default cut (TOML; default: MODEL_DIR/cut.toml); a request's cut fields override it."),
    listen: list[str] = typer.Option([], "--listen", help=f"Zenoh endpoint to listen on (repeatable), e.g. tls/0.0.0.0:7447 (default without --connect or --config: {DEFAULT_LISTEN}, this machine only)."),
    connect: list[str] = typer.Option([], "--connect", help="Zenoh endpoint to connect to (repeatable)."),
    mode: str = typer.Option("peer", "--mode", help="peer (embedded, default), client or router."),
    config: Optional[Path] = typer.Option(None, "--config", help="Zenoh config (JSON5): TLS, authentication, access control."),
    state_dir: Optional[Path] = typer.Option(None, "--state-dir", help="Where published plans are kept (republished after a restart)."),
    absorber: Optional[Path] = typer.Option(None, "--absorber", help="Absorber file (default: seed 004's design)."),
    actuator: Optional[Path] = typer.Option(None, "--actuator", help="Actuator file (default: seed 000's)."),
    twin: Optional[Path] = typer.Option(None, "--twin", help="Twin file for the reachability check when the model has none (default: the shipped KR R2700 twin)."),
    signing_key: Optional[Path] = typer.Option(None, "--signing-key", help="Key file (>= 32 bytes) shared with the cell: every reply and publication carries its HMAC."),
    max_payload_bytes: int = typer.Option(65536, "--max-payload-bytes", min=64, help="Largest schedule request."),
    max_plan_payload_bytes: int = typer.Option(1 << 20, "--max-plan-payload-bytes", min=64, help="Largest plan request."),
    queue_size: int = typer.Option(32, "--queue-size", min=1, help="Schedules waiting for a worker before 'busy'."),
    workers: int = typer.Option(1, "--workers", min=1, help="Worker processes (one core each)."),
    stale_after_s: float = typer.Option(3600.0, "--stale-after-s", help="How long a schedule is valid for the cell."),
    cache_entries: int = typer.Option(20_000, "--cache-entries", min=1, help="Schedules kept in memory (about 2.5 KB each)."),
    plans_in_memory: int = typer.Option(16, "--plans-in-memory", min=1, help="Plans held with a publisher for late joiners."),
    pending_plans: int = typer.Option(4, "--pending-plans", min=1, help="Plans computed at once before 'busy'."),
    stored_plans: int = typer.Option(256, "--stored-plans", min=1, help="Plan files kept in --state-dir."),
    reference_tool: Optional[Path] = typer.Option(None, "--reference-tool", help="The tool the model's campaign was measured with (tool file; with --target-tool)."),
    target_tool: Optional[Path] = typer.Option(None, "--target-tool", help="Serve schedules for this tool (its modes by receptance coupling, as `posedyn tool-change`)."),
    pivot_mm: float = typer.Option(150.0, "--pivot-mm", help="With --target-tool: where the holder side turns, behind the holder face."),
    robust_samples: int = typer.Option(0, "--robust-samples", min=0, max=2000, help="> 0: every entry also carries the guaranteed depth over that many samples of the pose's modes (`robust`; 8 or more; seconds per pose)."),
):
    """Serve per-pose schedules over Zenoh until SIGTERM or SIGINT."""
    if mode not in ("peer", "client", "router"):
        raise InputError("--mode peer, client or router", got=mode, column="--mode")
    cut = resolve_cut(cut, model)
    for path in filter(None, (model, cut, config, absorber, actuator, twin, signing_key, reference_tool, target_tool)):
        if not path.exists():
            raise InputError("an existing file or directory", got="missing", file=str(path))
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    limits = dict(max_payload_bytes=max_payload_bytes, max_plan_payload_bytes=max_plan_payload_bytes, queue_size=queue_size, workers=workers,
                  stale_after_s=stale_after_s, cache_entries=cache_entries, plans_in_memory=plans_in_memory, pending_plans=pending_plans, stored_plans=stored_plans)
    try:
        settings = ServiceSettings(cell, **limits)
    except RequestError as exc:  # named as the flag it came from
        if exc.code == "invalid_cell":
            raise InputError(f"a cell name of {CELL_RULE}", got=cell, column="--cell") from None
        name = exc.message.partition(":")[0]
        raise InputError("a finite number > 0", got=limits.get(name), column="--" + name.replace("_", "-")) from None
    key = read_key(signing_key) if signing_key else None
    if 0 < robust_samples < 8:
        raise InputError("--robust-samples 0 (off) or 8-2000", got=robust_samples, column="--robust-samples")
    if (reference_tool is None) != (target_tool is None):
        raise InputError("--reference-tool and --target-tool together", got="one of them", column="--target-tool")
    if target_tool is not None and not (math.isfinite(pivot_mm) and pivot_mm > 0):  # (the service started and refused every query)
        raise InputError("a pivot distance > 0 mm", got=pivot_mm, column="--pivot-mm")
    spec = EngineSpec(model, cut, absorber, actuator, twin, robust_samples, None if target_tool is None else (reference_tool, target_tool), pivot_mm)
    spec.build()  # every file checked here, with its name in the error, before any process starts
    if not listen and not connect and config is None:
        listen = [DEFAULT_LISTEN]
    try:
        conf = zenoh_config(config, mode, listen, connect)
    except Exception as exc:  # zenoh reports a bad config file or key as ZError / ValueError
        raise InputError("a valid Zenoh configuration", got=str(exc), file=str(config) if config else None) from None
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    service = ScheduleService(spec, settings, conf, state_dir, signing_key=key)
    try:
        service.start()
    except Exception as exc:  # noqa: BLE001 - e.g. a port in use, a TLS file missing, a state folder not writable
        raise InputError("a service that starts (Zenoh session, worker processes, state folder)", got=str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__,
                         file=str(config) if config else None) from None
    try:
        print(f"serving cells/{cell}/posedyn (model {service.model_version[:12]}, service id {service.service_id}) mode {mode} listen {list(listen)} connect {list(connect)}"
              f"{', signed' if key else ''}", flush=True)
        while not stop.wait(0.5):
            pass
    finally:
        service.close()
        print("stopped", flush=True)


def query(
    cell: str = typer.Option(..., "--cell"),
    connect: list[str] = typer.Option([], "--connect", help="Endpoint of the service or of a router (repeatable)."),
    pose_json: Optional[str] = typer.Option(None, "--pose-json", help='One pose, e.g. \'{"x_mm": 1400, "y_mm": 0, "z_mm": 800, "beta_deg": 0}\'.'),
    plan: Optional[Path] = typer.Option(None, "--plan", help="A tool path: CSV with the pose columns."),
    plan_id: Optional[str] = typer.Option(None, "--plan-id", help="Plan id (default: the CSV's file name)."),
    cut_json: Optional[str] = typer.Option(None, "--cut-json", help="Cut fields overriding the service's default cut."),
    config: Optional[Path] = typer.Option(None, "--config", help="Zenoh config (JSON5), e.g. TLS certificates."),
    service_id: Optional[str] = typer.Option(None, "--service-id", help="Accept replies from this Zenoh session only (printed by posedyn serve)."),
    signing_key: Optional[Path] = typer.Option(None, "--signing-key", help="The service's key file: accept signed replies only."),
    timeout_s: float = typer.Option(5.0, "--timeout-s"),
    as_json: bool = typer.Option(False, "--json"),
):
    """Ask the schedule service for a pose's schedule, or send it a tool path as a plan."""
    if (pose_json is None) == (plan is None):
        raise InputError("either --pose-json or --plan", column="--pose-json")
    _check_query_flags(cell, connect, plan_id or (plan.stem if plan is not None else None), timeout_s)
    cut = _json_option(cut_json, "--cut-json") if cut_json else None
    key = read_key(signing_key) if signing_key else None
    pose = rows = times = None  # the request read before connecting: a bad one is exit 2 without a wait
    if cut is not None:
        _checked(parse_cut, cut, "--cut-json")
    if pose_json is not None:
        pose = _json_option(pose_json, "--pose-json")
        _checked(parse_pose, pose, "--pose-json")
    else:
        lines = plan.read_text(encoding="utf-8", errors="replace").splitlines()
        if not lines:
            raise InputError("a CSV with the pose columns and one row per pose", got="an empty file", file=str(plan))
        if "time_s" in lines[0].split(","):
            path_poses, times = read_tool_path(plan)  # a timed path: the plan carries the coil's trajectory
            rows, times = path_poses.records(), times.tolist()
        else:
            rows = read_pose_table(plan).records()
    try:
        client = ScheduleClient(cell, connect=connect, config=config, timeout_s=timeout_s, service_id=service_id, signing_key=key).open()
    except Exception as exc:  # noqa: BLE001 - zenoh could not open (no route, TLS refused): no service answered, as a missing reply
        reason = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        reason = re.sub(r"\s+at \S+\.rs:\d+\.?$", "", reason)  # zenoh's own source location means nothing to a user
        print(f"error: no_session: could not reach {', '.join(connect) or 'a Zenoh peer'}: {reason}", file=sys.stderr)
        raise typer.Exit(3)
    try:
        if pose is not None:
            result = client.schedule(pose, cut)
        else:
            result = client.plan(plan_id or plan.stem, rows, cut, timeout_s=max(timeout_s, 2.0 * len(rows)), times_s=times)
    except ServiceError as exc:
        print(f"error: {exc.code}: {exc.message}", file=sys.stderr)
        raise typer.Exit(3)
    finally:
        client.close()
    if as_json:
        print(json.dumps(result, indent=2))
        return
    if result.get("state") in ("accepted", "pending"):
        console.print(f"plan {result['plan_id']}: {result['done']} of {result['total']} poses computed; the service goes on and publishes it at cells/{cell}/posedyn/schedules/{result['plan_id']} when done")
        return
    entries = result.get("entries", [result])
    for e in entries:
        a = e["absorber"]
        console.print(
            f"{e['pose_id']}: critical depth {_g(e['critical_depth_mm'])} mm, chatter {_g(e['dominant_chatter_hz'])} Hz -> "
            f"absorber {_g(a['field_mt'])} mT, {_g(a['current_a'])} A{'' if a['feasible'] else ' (outside its range)'}, "
            f"critical depth with it {_g(e['critical_depth_with_absorber_mm'])} mm; DVF gain {_g(e['controller']['dvf_gain_ns_per_m'])} N s/m"
        )
        r = e.get("robust")
        if r:
            ra = r["absorber"]
            console.print(
                f"  guaranteed (95 %, {r['samples']} samples): {_g(r['critical_depth_p95_mm'])} mm bare, {_g(r['critical_depth_with_absorber_p95_mm'])} mm with the "
                f"{r['tuning']} setting ({_g(ra['field_mt'])} mT, {_g(ra['current_a'])} A; nominal setting {_g(r['nominal_tuning_with_absorber_p95_mm'])} mm)"
            )


def _g(value) -> str:
    return "-" if value is None else f"{value:.4g}"


def _checked(parse, value, flag: str) -> None:
    """The service's own check of a request part (`protocol.parse_pose`, `parse_cut`), before
    connecting: what it would refuse is exit 2 here, named by the flag."""
    try:
        parse(value)
    except RequestError as exc:
        raise InputError("a request the service accepts", got=f"{exc.code}: {exc.message}", column=flag) from None


def _check_query_flags(cell: str, connect: list[str], plan_id: Optional[str], timeout_s: float) -> None:
    """The flags `query` can judge before it connects (each was a wait and an exit 3, or Zenoh's
    debug text): the cell and plan id as the service accepts them, endpoints as PROTOCOL/ADDRESS,
    a timeout > 0."""
    for flag, value, check, rule in (("--cell", cell, valid_cell, CELL_RULE), ("--plan-id", plan_id, valid_plan_id, PLAN_ID_RULE)):
        if value is not None:
            try:
                check(value)
            except RequestError:
                raise InputError(rule, got=value, column=flag) from None
    for endpoint in connect:
        protocol, slash, address = endpoint.partition("/")
        if not (slash and address and protocol and all(c.isalnum() or c == "-" for c in protocol)):
            raise InputError("an endpoint PROTOCOL/ADDRESS, e.g. tcp/127.0.0.1:7447", got=endpoint, column="--connect")
    if not (math.isfinite(timeout_s) and timeout_s > 0):
        raise InputError("a timeout > 0 s", got=timeout_s, column="--timeout-s")


def _json_option(text: str, option: str) -> dict:
    """The JSON object an option holds (NaN and Infinity are not JSON: the request could not be sent)."""

    def refuse(constant):
        raise ValueError(f"{constant} is not a JSON number")

    try:
        value = json.loads(text, parse_constant=refuse)
    except ValueError as exc:
        raise InputError("a JSON object", got=str(exc), column=option) from None
    if not isinstance(value, dict):
        raise InputError("a JSON object", got=text, column=option)
    return value
