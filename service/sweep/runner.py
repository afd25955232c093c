"""Running a sweep on Dask: chunks computed on workers, written atomically by the driver as they
finish (`DIR/chunks/chunk_NNNNN.csv`), skipped on `--resume`, merged into `DIR/results.csv`
(and `DIR/results.parquet` when pyarrow is installed).

`DIR/sweep.json` records the inputs' fingerprint (settings plus the bytes of every input file):
a resumed run refuses a directory whose chunks came from other inputs, and a fresh run refuses
a directory that already holds chunks, so results never mix.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

from posedyn.errors import InputError
from posedyn.io.atomic import write_text_atomic
from posedyn.table import PoseSet
from service.heap import keep_freed_memory
from service.sweep.chunk import compute_chunk, context, representative_lobes
from service.sweep.spec import RESULT_COLUMNS, SweepSpec, read_sweep_poses
import hashlib

POSE_COLUMNS = ("pose_id", "x_mm", "y_mm", "z_mm", "beta_deg", "a_deg", "b_deg", "c_deg")


@dataclass(frozen=True)
class SweepOutcome:
    rows: list
    columns: list
    computed_chunks: int
    skipped_chunks: int
    seconds: float
    workers: int
    manifest: dict
    poses: object  # the PoseSet swept
    grid_twin: str | None
    lobes: list = dataclasses.field(default_factory=list)  # `representative_lobes` when asked for


def run_sweep(spec: SweepSpec, out: Path, workers: int | None = None, scheduler: str | None = None, resume: bool = False, progress=None,
              lobe_speeds: int = 0) -> SweepOutcome:
    """Compute every pending chunk, then merge. `progress(done, total)` is called as chunks land.
    `lobe_speeds` > 0: also the report's `representative_lobes` at that many speeds, one curve a
    task on the same cluster (not counted in `seconds`)."""
    start = time.perf_counter()
    poses, grid_twin = read_sweep_poses(spec.poses)
    chunks = [list(range(i, min(i + spec.chunk_size, len(poses)))) for i in range(0, len(poses), spec.chunk_size)]
    out = Path(out)
    chunk_dir = out / "chunks"
    manifest = {
        "kind": "posedyn_sweep",
        "schema_version": 1,
        "fingerprint": spec.fingerprint() + (":" + _sha(grid_twin) if grid_twin else ""),
        "spec": json.loads(spec.to_json()),
        "grid_twin": grid_twin,
        "poses": len(poses),
        "chunks": len(chunks),
    }
    context(spec.to_json(), grid_twin)  # every input file read before anything is written (a bad one left sweep.json and chunks/)
    _prepare(out, manifest, resume)
    done = {i for i in range(len(chunks)) if _chunk_path(chunk_dir, i).exists()}
    pending = [i for i in range(len(chunks)) if i not in done]
    if progress:
        progress(len(done), len(chunks))
    used_workers = 0
    with _dask(workers, scheduler) if pending or lobe_speeds > 0 else contextlib.nullcontext() as client:
        if client is not None:
            used_workers = _worker_count(client, workers)
        if pending:
            _compute(client, spec, poses, grid_twin, chunks, pending, chunk_dir, progress, len(done), len(chunks))
        rows = []
        for i in range(len(chunks)):
            rows += _read_chunk(_chunk_path(chunk_dir, i))
        columns = result_columns(rows)
        write_text_atomic(out / "results.csv", rows_to_csv(rows, columns))
        _write_parquet(out / "results.parquet", rows, columns)
        seconds = time.perf_counter() - start
        lobes = []
        if lobe_speeds > 0:
            lobes = representative_lobes(spec.to_json(), poses, rows, grid_twin, lobe_speeds, mapper=lambda fn, jobs: client.gather(client.map(fn, jobs, pure=False)))
    return SweepOutcome(rows, columns, len(pending), len(done), seconds, used_workers, manifest, poses, grid_twin, lobes)


@contextlib.contextmanager
def _dask(workers: int | None, scheduler: str | None):
    """A Dask client: of the scheduler at `scheduler`, or of a local cluster of `workers` (2)
    single-threaded worker processes, closed on exit."""
    from distributed import Client, LocalCluster  # heavy (about 1 s): only when there is work

    import dask  # heavy: only when there is work

    from distributed.diagnostics.plugin import WorkerPlugin  # as above

    class SweepWorker(WorkerPlugin):  # every worker, local or a scheduler's, joining now or later
        def setup(self, worker):
            keep_freed_memory()
            # Dask's statistical profiler samples every thread's stack every 10 ms under the GIL;
            # nothing here reads its profiles, so it is stopped. Measured 2026-12-06, alternately:
            # 80 poses on a one-worker cluster 101 against 114 ms a pose (8 runs each), but
            # 1,250 poses on two workers 64.1 against 64.8 s (2 runs each): within the noise.
            for name in ("profile", "profile-cycle"):
                callback = getattr(worker, "periodic_callbacks", {}).pop(name, None)
                if callback is not None:
                    callback.stop()

    logging.getLogger("distributed").setLevel(logging.ERROR)
    # Dask's default worker environment sets MALLOC_TRIM_THRESHOLD_=64 KiB, which also turns off
    # glibc's dynamic mmap threshold: every large temporary array is then mmap'd and unmapped and
    # the batched stability work runs 1.9x slower (a chunk in one process: 202 ms a pose against
    # 107). Every worker, local or a scheduler's, joining now or later, keeps its heap instead
    # (`service.heap`, a worker plugin); a local one also has one arena for the task thread and
    # the event loop.
    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    environ.update(MALLOC_ARENA_MAX=1)
    dask.config.set({"distributed.nanny.pre-spawn-environ": environ})
    if scheduler:
        client, cluster = Client(scheduler), None
    else:
        cluster = LocalCluster(n_workers=workers or 2, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=logging.ERROR)
        client = Client(cluster)
    try:
        client.register_plugin(SweepWorker(), name="posedyn-sweep-worker")
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _worker_count(client, workers: int | None) -> int:
    return len(client.scheduler_info().get("workers", {})) or (workers or 2)


def _prepare(out: Path, manifest: dict, resume: bool) -> None:
    path = out / "sweep.json"
    chunk_dir = out / "chunks"
    has_chunks = chunk_dir.exists() and any(chunk_dir.glob("chunk_*.csv"))
    if path.exists() and has_chunks:
        try:
            old = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise InputError("a readable sweep.json", got=str(exc), file=str(path)) from None
        if not resume:
            raise InputError("an empty output directory (this one holds a sweep: pass --resume to finish it, or choose another --out)", got=str(out), file=str(path))
        if old.get("fingerprint") != manifest["fingerprint"]:
            raise InputError("the same inputs as the sweep being resumed (settings or input files changed)", got="a different fingerprint", file=str(path), column="fingerprint")
    elif has_chunks:
        raise InputError("a sweep.json beside the chunks", got="missing", file=str(path))
    chunk_dir.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, json.dumps(manifest, indent=2) + "\n")


def _compute(client, spec, poses, grid_twin, chunks, pending, chunk_dir, progress, done_count, total) -> None:
    from distributed import as_completed  # heavy: only when chunks are computed

    spec_json = spec.to_json()
    futures = {client.submit(_chunk_rows, spec_json, _subset(poses, chunks[i]), grid_twin, pure=False): i for i in pending}
    finished = done_count
    for future in as_completed(futures):
        i = futures[future]
        rows = future.result()
        write_text_atomic(_chunk_path(chunk_dir, i), rows_to_csv(rows, result_columns(rows)))
        finished += 1
        if progress:
            progress(finished, total)


def _chunk_rows(spec_json: str, poses, grid_twin):
    return [{k: _plain(v) for k, v in row.items()} for row in compute_chunk(spec_json, poses, grid_twin)]


def _subset(poses, index):
    return PoseSet(
        pose_id=tuple(poses.pose_id[i] for i in index),
        position_mm=poses.position_mm[index],
        orientation=poses.orientation,
        orientation_deg=poses.orientation_deg[index],
        joints_deg=None if poses.joints_deg is None else poses.joints_deg[index],
    )


def _chunk_path(chunk_dir: Path, i: int) -> Path:
    return chunk_dir / f"chunk_{i:05d}.csv"


# --- CSV and Parquet -------------------------------------------------------------------------


def result_columns(rows: list[dict]) -> list[str]:
    """Pose columns, the result columns, then per-mode columns by direction, mode and quantity."""
    seen = []
    for row in rows:
        for key in row:
            if key not in seen:
                seen.append(key)
    pose = [c for c in POSE_COLUMNS if c in seen]
    modes = sorted((c for c in seen if c not in pose and c not in RESULT_COLUMNS), key=_mode_key)
    return pose + list(RESULT_COLUMNS) + modes


def _mode_key(column: str):
    for prefix in ("std_fn_", "fn_", "zeta_", "k_"):
        if column.startswith(prefix):
            tag = column[len(prefix) :].split("_")[0]
            return (tag[0], int(tag[1:]) if tag[1:].isdigit() else 0, ("fn_", "std_fn_", "zeta_", "k_").index(prefix))
    return ("~", 0, column)


def rows_to_csv(rows: list[dict], columns: list[str]) -> str:
    """CSV text; floats as repr (round-trips exactly), None as an empty field."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_cell(row.get(c)) for c in columns])
    return buffer.getvalue()


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ""
    return str(value)


def _read_chunk(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as f:
        return [{k: _parse(k, v) for k, v in row.items()} for row in csv.DictReader(f)]


def _parse(column: str, text: str):
    if text == "":
        return None
    if column in ("pose_id", "flags", "actuator_direction", "stability_method", "robust_tuning"):
        return text
    if text in ("true", "false"):
        return text == "true"
    return float(text)


def _plain(value):
    """numpy scalars to Python numbers (CSV and the Dask transport see plain types)."""
    if hasattr(value, "item"):
        return value.item()
    return value


def _write_parquet(path: Path, rows: list[dict], columns: list[str]) -> None:
    try:
        import pyarrow as pa  # optional (test extra): Parquet only when installed
        import pyarrow.parquet as pq  # optional (test extra): Parquet only when installed
    except ImportError:
        return
    table = pa.table({c: [row.get(c) for row in rows] for c in columns})
    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(table, tmp)
    tmp.replace(path)


def _sha(path: str) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
