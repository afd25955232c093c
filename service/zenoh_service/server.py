"""The Zenoh schedule service (`posedyn serve`).

Key expressions, all under `cells/{cell}/posedyn/`:

- `schedule` (queryable): `{"pose": {...}, "cut": {...}}` -> the `posedyn schedule` entry plus
  `model_version`, `computed_at`, `stale_after_s`;
- `plan/{plan_id}` (queryable, or put): `{"poses": [...], "cut": {...}}` -> every entry
  published at `schedules/{plan_id}/{index}` and the whole plan at `schedules/{plan_id}`, through
  AdvancedPublishers with a cache (late AdvancedSubscribers with history get them); the reply is
  the plan; a query without payload returns a stored plan;
- `status` (queryable): model version, uptime and counters; liveliness token at `alive`.

Every handler catches everything and answers `reply_err` with `{"error": code, "message": ...}`.
Cached schedules are answered on the Zenoh callback thread; new computations go to worker
threads through a bounded queue, and a full queue is answered `busy` at once. Plans are written
atomically to `--state-dir` before they are published and republished at start-up.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import zenoh
from zenoh.ext import CacheConfig, declare_advanced_publisher

from posedyn.io.atomic import write_text_atomic
from posedyn.io.json_values import json_ready
from service.zenoh_service import keys
from service.zenoh_service.engine import ScheduleEngine, canonical
from service.zenoh_service.protocol import RequestError, parse_plan_request, parse_schedule_request, valid_plan_id

log = logging.getLogger("posedyn.service")


@dataclass(frozen=True)
class ServiceSettings:
    cell: str
    max_payload_bytes: int = 65536
    queue_size: int = 32
    workers: int = 1
    stale_after_s: float = 3600.0
    max_plan_poses: int = 1000
    cache_entries: int = 100_000
    plans_in_memory: int = 64

    def __post_init__(self):
        if not self.cell or not all(c.isalnum() or c in "-_" for c in self.cell):
            raise RequestError("invalid_cell", f"cell: expected letters, digits, - or _, got {self.cell!r}")


class ScheduleService:
    def __init__(self, scheduler: ScheduleEngine, settings: ServiceSettings, conf, state_dir: Path | None = None):
        self.scheduler, self.settings, self.conf = scheduler, settings, conf
        self.state_dir = Path(state_dir) if state_dir else None
        self.prefix = keys.prefix(settings.cell)
        self.started = time.monotonic()
        self.counts = {"queries": 0, "errors": 0, "cache_hits": 0, "computations": 0, "busy": 0, "plans_published": 0}
        self._count_lock = threading.Lock()
        self._cache: OrderedDict[str, dict] = OrderedDict()
        self._replies: dict[str, dict[str, bytes]] = {}  # serialized replies per schedule key and pose_id
        self._cache_lock = threading.Lock()
        self._jobs: queue.Queue = queue.Queue(maxsize=settings.queue_size)
        self._publishers: OrderedDict[str, list] = OrderedDict()
        self._publish_lock = threading.Lock()
        self._plans: dict[str, dict] = {}
        self.session = None
        self._declared = []
        self._threads = []

    # --- life cycle ------------------------------------------------------------------------

    def start(self) -> "ScheduleService":
        if self.state_dir is not None:
            (self.state_dir / "plans").mkdir(parents=True, exist_ok=True)
        self.conf.insert_json5("timestamping/enabled", "true")  # AdvancedPublisher's cache needs timestamps
        self.session = zenoh.open(self.conf)
        p = self.prefix
        self._declared = [
            self.session.declare_queryable(f"{p}/{keys.SCHEDULE}", self._guard(self._on_schedule), complete=True),
            self.session.declare_queryable(f"{p}/{keys.PLANS}", self._guard(self._on_plan_query), complete=True),
            self.session.declare_subscriber(f"{p}/{keys.PLANS}", self._on_plan_put),
            self.session.declare_queryable(f"{p}/{keys.STATUS}", self._guard(self._on_status), complete=True),
            self.session.liveliness().declare_token(f"{p}/{keys.ALIVE}"),
        ]
        for _ in range(self.settings.workers):
            thread = threading.Thread(target=self._work, name="posedyn-worker", daemon=True)
            thread.start()
            self._threads.append(thread)
        self._republish()
        return self

    def close(self) -> None:
        for _ in self._threads:
            try:
                self._jobs.put_nowait(None)
            except queue.Full:
                pass
        for entity in self._declared:
            try:
                entity.undeclare()
            except Exception:  # noqa: BLE001 - closing anyway
                pass
        with self._publish_lock:
            for publishers in self._publishers.values():
                for pub in publishers:
                    try:
                        pub.undeclare()
                    except Exception:  # noqa: BLE001
                        pass
            self._publishers.clear()
        if self.session is not None:
            self.session.close()
            self.session = None

    # --- handlers ----------------------------------------------------------------------------

    def _guard(self, handler):
        """Run a query handler; whatever it raises becomes a JSON reply_err, never a dead service
        or a querier left waiting."""

        def run(query):
            self._count("queries")
            deferred = False
            try:
                deferred = bool(handler(query))
            except RequestError as exc:
                self._reply_error(query, exc)
            except Exception as exc:  # noqa: BLE001 - a service never dies of a bad message
                log.exception("query on %s failed", query.key_expr)
                self._reply_error(query, RequestError("internal", f"{type(exc).__name__}: {exc}"))
            finally:
                if not deferred:  # finalize now: the querier stops waiting (a worker drops the others)
                    query.drop()

        return run

    def _on_schedule(self, query) -> None:
        pose, cut = parse_schedule_request(_payload(query), self.settings.max_payload_bytes)
        key = canonical(pose, cut)
        cached = self._cached_reply(key, pose["pose_id"])
        if cached is not None:
            self._count("cache_hits")
            query.reply(query.key_expr, cached)
            return
        self._submit(query, lambda: self._reply_entry(query, key, pose, cut))
        return True

    def _on_plan_query(self, query) -> None:
        plan_id = valid_plan_id(str(query.key_expr).rsplit("/", 1)[-1])
        request = parse_plan_request(_payload(query), self.settings.max_payload_bytes, self.settings.max_plan_poses)
        if request is None:
            plan = self._stored_plan(plan_id)
            if plan is None:
                raise RequestError("unknown_plan", f"plan {plan_id!r}: no such plan (send its poses to compute it)")
            query.reply(query.key_expr, json.dumps(plan).encode())
            return
        poses, cut = request
        self._submit(query, lambda: self._reply_plan(query, plan_id, poses, cut))
        return True

    def _on_plan_put(self, sample) -> None:
        try:
            self._count("queries")
            plan_id = valid_plan_id(str(sample.key_expr).rsplit("/", 1)[-1])
            request = parse_plan_request(sample.payload.to_bytes(), self.settings.max_payload_bytes, self.settings.max_plan_poses)
            if request is None:
                raise RequestError("missing_payload", "a plan put needs its poses")
            self._jobs.put_nowait(lambda: self.compute_plan(plan_id, *request))
        except queue.Full:
            self._count("busy")
            log.warning("plan put on %s dropped: busy", sample.key_expr)
        except Exception as exc:  # noqa: BLE001
            self._count("errors")
            log.warning("plan put on %s refused: %s", sample.key_expr, exc)

    def _on_status(self, query) -> None:
        query.reply(query.key_expr, json.dumps(self.status()).encode())

    def status(self) -> dict:
        with self._count_lock:
            counts = dict(self.counts)
        return {
            "cell": self.settings.cell,
            "model_version": self.scheduler.model_version,
            "uptime_s": round(time.monotonic() - self.started, 3),
            "queue": self._jobs.qsize(),
            "cached_schedules": len(self._cache),
            "plans": len(self._plans),
            **counts,
        }

    # --- work ------------------------------------------------------------------------------------

    def _submit(self, query, job) -> None:
        try:
            self._jobs.put_nowait((query, job))
        except queue.Full:
            self._count("busy")
            raise RequestError("busy", f"the service is computing {self.settings.queue_size} requests; retry later") from None

    def _work(self) -> None:
        while True:
            item = self._jobs.get()
            if item is None:
                return
            query, job = item if isinstance(item, tuple) else (None, item)
            try:
                job()
            except RequestError as exc:
                if query is not None:
                    self._reply_error(query, exc)
            except Exception as exc:  # noqa: BLE001
                log.exception("job failed")
                if query is not None:
                    self._reply_error(query, RequestError("internal", f"{type(exc).__name__}: {exc}"))
            finally:
                if query is not None:
                    query.drop()

    def schedule(self, key: str, pose: dict, cut: dict) -> dict:
        """The reply document for one pose (from the cache or computed now)."""
        with self._cache_lock:
            entry = self._cache.get(key)
        if entry is None:
            self._count("computations")
            entry = json_ready(self.scheduler.entry(pose, cut))
            entry.update(model_version=self.scheduler.model_version, computed_at=_now(), stale_after_s=self.settings.stale_after_s)
            with self._cache_lock:
                self._cache[key] = entry
                while len(self._cache) > self.settings.cache_entries:
                    old, _ = self._cache.popitem(last=False)
                    self._replies.pop(old, None)
        return dict(entry, pose_id=pose["pose_id"])

    def _reply_entry(self, query, key, pose, cut) -> None:
        doc = self.schedule(key, pose, cut)
        payload = json.dumps(doc).encode()
        with self._cache_lock:
            self._replies.setdefault(key, {})[pose["pose_id"]] = payload
        query.reply(query.key_expr, payload)

    def _cached_reply(self, key: str, pose_id: str) -> bytes | None:
        with self._cache_lock:
            payload = self._replies.get(key, {}).get(pose_id)
            if payload is not None or key not in self._cache:
                return payload
            payload = json.dumps(dict(self._cache[key], pose_id=pose_id)).encode()
            self._replies.setdefault(key, {})[pose_id] = payload
            return payload

    def compute_plan(self, plan_id: str, poses: list[dict], cut: dict) -> dict:
        entries = [self.schedule(canonical(p, cut), p, cut) for p in poses]
        plan = {"plan_id": plan_id, "model_version": self.scheduler.model_version, "published_at": _now(), "cut": cut, "entries": entries}
        if self.state_dir is not None:
            write_text_atomic(self.state_dir / "plans" / f"{plan_id}.json", json.dumps(plan) + "\n")
        self._publish(plan)
        return plan

    def _reply_plan(self, query, plan_id, poses, cut) -> None:
        plan = self.compute_plan(plan_id, poses, cut)
        query.reply(query.key_expr, json.dumps(plan).encode())

    def _publish(self, plan: dict) -> None:
        plan_id = plan["plan_id"]
        base = f"{self.prefix}/{keys.schedules(plan_id)}"
        with self._publish_lock:
            old = self._publishers.pop(plan_id, [])
            for pub in old:
                pub.undeclare()
            key_exprs = [base] + [f"{base}/{i}" for i in range(len(plan["entries"]))]
            pubs = [declare_advanced_publisher(self.session, k, cache=CacheConfig(max_samples=1), publisher_detection=True) for k in key_exprs]
            pubs[0].put(json.dumps(plan).encode())
            for pub, entry in zip(pubs[1:], plan["entries"]):
                pub.put(json.dumps(entry).encode())
            self._publishers[plan_id] = pubs
            self._plans[plan_id] = plan
            while len(self._publishers) > self.settings.plans_in_memory:
                gone, gone_pubs = self._publishers.popitem(last=False)
                for pub in gone_pubs:
                    pub.undeclare()
                self._plans.pop(gone, None)
        self._count("plans_published")

    def _stored_plan(self, plan_id: str) -> dict | None:
        if plan_id in self._plans:
            return self._plans[plan_id]
        if self.state_dir is not None:
            path = self.state_dir / "plans" / f"{plan_id}.json"
            if path.exists():
                return json.loads(path.read_text(encoding="utf-8"))
        return None

    def _republish(self) -> None:
        """Publish again, newest last, the plans a previous run persisted."""
        if self.state_dir is None:
            return
        files = sorted((self.state_dir / "plans").glob("*.json"), key=lambda f: f.stat().st_mtime)[-self.settings.plans_in_memory :]
        for path in files:
            try:
                self._publish(json.loads(path.read_text(encoding="utf-8")))
            except (OSError, ValueError, KeyError) as exc:
                log.warning("stored plan %s not republished: %s", path, exc)

    # --- helpers ---------------------------------------------------------------------------------

    def _reply_error(self, query, exc: RequestError) -> None:
        self._count("errors")
        try:
            query.reply_err(exc.to_json())
        except Exception:  # noqa: BLE001 - the querier may be gone
            log.warning("could not deliver error %s", exc.code)

    def _count(self, name: str) -> None:
        with self._count_lock:
            self.counts[name] += 1


def _payload(query) -> bytes | None:
    payload = query.payload
    return None if payload is None else payload.to_bytes()


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")
