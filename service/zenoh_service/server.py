"""The Zenoh schedule service (`posedyn serve`).

Key expressions, all under `cells/{cell}/posedyn/`:

- `schedule` (queryable; selector parameter `timeout_ms`, the querier's budget):
  `{"pose": {...}, "cut": {...}}` -> the `posedyn
  schedule` entry plus `model_version`, `service_id`, `computed_at`, `stale_after_s`;
- `plan/{plan_id}` (queryable, or put): `{"poses": [...], "cut": {...}}` -> the
  plan (every entry), published whole at `schedules/{plan_id}` through an AdvancedPublisher with
  a cache (late AdvancedSubscribers with history get it) and entry by entry at
  `schedules/{plan_id}/{index}` (live); a plan that cannot be computed within the querier's
  budget is answered `{"state": "accepted", ...}` and goes on in the background; a query
  without payload returns the stored plan or `{"state": "pending", ...}`;
- `status` (queryable): model version, service id, limits, queue lengths and counters;
  liveliness token at `alive`.

Paths. Cached schedules are answered on the Zenoh callback thread from serialized replies (the
pose id spliced in: no state per pose id; a request repeated byte for byte is answered without
parsing). Computations run in worker processes (`workers`),
fed by dispatcher threads from two bounded lanes, single schedules before plan poses. A request
is refused `busy` with `retry_after_ms` at once when its lane is full or the expected wait is
longer than the querier's budget (`timeout_ms`, else `default_timeout_s`); a request whose budget
runs out while it waits or computes is answered `busy` just before its deadline (the computation
goes on and fills the cache: the retry is answered from it), and work nobody waits for any more
is dropped. Every handler answers `reply_err` `{"error", "message"}` for whatever it raises.

Bounds (ServiceSettings): payload bytes, poses per plan, cached entries, plans with a publisher,
plans computing, plan files on disk, lane lengths. State: plans are validated when loaded
(`state.PlanStore`); plans of another model are recomputed in the background, never republished
as current. Security: `session.secure_defaults` keeps the service's own keys writable by the
service alone; with a signing key every reply and publication carries an HMAC (`signing`).
"""

from __future__ import annotations

import heapq
import json
import math
import logging
import threading
import time
from collections import OrderedDict, deque
from dataclasses import dataclass, fields
from datetime import datetime, timezone
from pathlib import Path

import zenoh
from zenoh.ext import CacheConfig, declare_advanced_publisher

from service.zenoh_service import keys, workers
from service.zenoh_service.engine import canonical
from service.zenoh_service.protocol import RequestError, parse_plan_request, parse_schedule_request, parse_timeout, valid_cell, valid_plan_id
from service.zenoh_service.session import secure_defaults
from service.zenoh_service.signing import reply_signature, sample_signature
from service.zenoh_service.state import SCHEMA_VERSION, PlanStore
from service.zenoh_service.workers import EngineSpec, WorkerPool

log = logging.getLogger("posedyn.service")

#: Requests remembered byte for byte with their reply (<= 1 KiB each: at most ~14 MB): a cell
#: asking the same thing again is answered without parsing, as fast as a raw echo.
REPEATED_REQUESTS = 4096
#: Queries waiting for the same computation (the same pose, or the same plan), then `busy`.
WAITERS_PER_JOB = 64


@dataclass(frozen=True)
class ServiceSettings:
    """The service's limits, each bounding one resource (README: "Limits")."""

    cell: str
    max_payload_bytes: int = 65536  # a schedule request
    max_plan_payload_bytes: int = 1 << 20  # a plan request: 1,000 poses with 200-character ids fit
    queue_size: int = 32  # single schedules waiting for a worker
    workers: int = 1  # worker processes
    stale_after_s: float = 3600.0
    max_plan_poses: int = 1000
    cache_entries: int = 20_000  # about 2.5 KB each
    plans_in_memory: int = 16  # plans with a publisher and their document in memory
    pending_plans: int = 4  # plans being computed
    stored_plans: int = 256  # plan files kept in the state folder
    default_timeout_s: float = 10.0  # a querier's budget when its request does not say (Zenoh's default)

    def __post_init__(self):
        valid_cell(self.cell)
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name != "cell" and not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise RequestError("invalid_setting", f"{f.name}: expected a finite number > 0, got {value!r}")


class ReplyCache:
    """Schedule entries by request key as serialized JSON split around the pose id, so that a
    reply for any pose id is two concatenations and nothing is kept per pose id (LRU, bounded)."""

    _MARK = "\u0000pose-id\u0000"

    def __init__(self, size: int):
        self.size = size
        self._items: OrderedDict[str, tuple[bytes, bytes]] = OrderedDict()
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._items)

    def put(self, key: str, entry: dict) -> None:
        head, tail = json.dumps(dict(entry, pose_id=self._MARK)).split(json.dumps(self._MARK))
        with self._lock:
            self._items[key] = (head.encode(), tail.encode())
            self._items.move_to_end(key)
            while len(self._items) > self.size:
                self._items.popitem(last=False)

    def has(self, key: str) -> bool:
        return key in self._items

    def reply(self, key: str, pose_id: str) -> bytes | None:
        with self._lock:
            parts = self._items.get(key)
            if parts is None:
                return None
            self._items.move_to_end(key)
        return parts[0] + json.dumps(pose_id).encode() + parts[1]


class Waiter:
    """A query waiting for a computation: answered exactly once, by the computation or, at its
    deadline, by `on_expire` (so that the querier gets an answer before its own timeout)."""

    def __init__(self, service: "ScheduleService", query, request: bytes | None, deadline: float, on_expire, pose_id: str | None = None):
        self.service, self.query, self.request, self.deadline = service, query, request, deadline
        self.on_expire, self.pose_id = on_expire, pose_id
        self._done = False
        self._lock = threading.Lock()

    @property
    def done(self) -> bool:
        return self._done

    def _claim(self) -> bool:
        with self._lock:
            if self._done:
                return False
            self._done = True
            return True

    def reply(self, payload: bytes) -> None:
        if self._claim():
            try:
                self.service._reply(self.query, self.request, payload)
            finally:
                self.query.drop()

    def error(self, exc: RequestError) -> None:
        if self._claim():
            try:
                self.service._reply_error(self.query, exc)
            finally:
                self.query.drop()

    def expire(self) -> None:
        if not self._done:
            result = self.on_expire()
            self.error(result) if isinstance(result, RequestError) else self.reply(result)


class Job:
    """One schedule computation and the queries waiting for it."""

    def __init__(self, key: str, pose: dict, cut: dict):
        self.key, self.pose, self.cut = key, pose, cut
        self.waiters: list[Waiter] = []


class PlanJob:
    """A plan being computed pose by pose (the poses already cached are skipped)."""

    def __init__(self, plan_id: str, poses: list[dict], cut: dict, times: list[float] | None = None):
        self.plan_id, self.poses, self.cut, self.times = plan_id, poses, cut, times
        self.keys = [canonical(p, cut) for p in poses]
        self.checked = False  # poses checked (workspace, reachability, cut) in a worker
        self.next = 0  # the next pose to look at
        self.outstanding = 0  # pieces of work running
        self.finishing = False
        self.failed: RequestError | None = None
        self.waiters: list[Waiter] = []  # the queries waiting for the whole plan
        self.doc: dict | None = None


class ScheduleService:
    def __init__(self, spec: EngineSpec, settings: ServiceSettings, conf, state_dir: Path | None = None, signing_key: bytes | None = None):
        self.spec, self.settings, self.conf = spec, settings, conf
        self.store = PlanStore(Path(state_dir), settings.stored_plans) if state_dir else None
        self.signing_key = signing_key
        self.prefix = keys.prefix(settings.cell)
        self.started = time.monotonic()
        self.counts = dict.fromkeys(("queries", "errors", "cache_hits", "computations", "busy", "expired", "dropped", "plans_published", "plans_accepted"), 0)
        self._count_lock = threading.Lock()
        self.cache = ReplyCache(settings.cache_entries)
        self._repeated: dict[bytes, tuple[bytes, bytes | None]] = {}  # request bytes -> (reply, signature), FIFO-bounded
        self.pool = WorkerPool(spec, settings.workers)
        self.model_version = ""
        self.service_id = ""
        self._cond = threading.Condition()
        self._lane: deque[Job] = deque()
        self._plan_lane: deque[PlanJob] = deque()
        self._inflight: dict[str, Job] = {}
        self._pending: dict[str, PlanJob] = {}
        self._running = 0
        self._durations: deque[float] = deque(maxlen=32)  # the last computations' seconds
        self._plans: OrderedDict[str, tuple[dict, object]] = OrderedDict()  # plan_id -> (plan, publisher)
        self._publish_lock = threading.Lock()
        self._deadlines: list = []
        self._deadline_cond = threading.Condition()
        self._closing = False
        self.session = None
        self._declared: list = []
        self._threads: list[threading.Thread] = []

    # --- life cycle ------------------------------------------------------------------------

    def start(self) -> "ScheduleService":
        """Load everything or nothing: on any failure the service is closed and the error raised."""
        try:
            self.spec.check()
            self.model_version = self.spec.model_version()
            current, stale = self.store.open().load_all(self.model_version) if self.store else ([], [])
            self.pool.start()
            self.session = zenoh.open(secure_defaults(self.conf, self.prefix))
            self.service_id = str(self.session.info.zid())
            p = self.prefix
            self._declared = [
                self.session.declare_queryable(f"{p}/{keys.SCHEDULE}", self._guard(self._on_schedule), complete=True),
                self.session.declare_queryable(f"{p}/{keys.PLANS}", self._guard(self._on_plan_query), complete=True),
                self.session.declare_subscriber(f"{p}/{keys.PLANS}", self._on_plan_put),
                self.session.declare_queryable(f"{p}/{keys.STATUS}", self._guard(self._on_status), complete=True),
            ]
            self._spawn(self._watch_deadlines, "posedyn-deadlines")
            for _ in range(self.settings.workers):
                self._spawn(self._dispatch, "posedyn-dispatch")
            for plan in current[-self.settings.plans_in_memory :]:
                self._publish(plan)
            for plan in stale:
                self._recompute_stale(plan)
            self._declared.append(self.session.liveliness().declare_token(f"{p}/{keys.ALIVE}"))  # alive once ready
        except BaseException:
            self.close()
            raise
        return self

    def close(self) -> None:
        with self._cond:
            self._closing = True
            waiting = [w for job in self._inflight.values() for w in job.waiters] + [w for pj in self._pending.values() for w in pj.waiters]
            self._lane.clear()
            self._plan_lane.clear()
            self._cond.notify_all()
        with self._deadline_cond:
            self._deadline_cond.notify_all()
        for waiter in waiting:
            waiter.error(RequestError("shutting_down", "the service is stopping; retry when it is back"))
        for entity in self._declared:
            try:
                entity.undeclare()
            except Exception:  # noqa: BLE001 - closing anyway
                pass
        self._declared = []
        with self._publish_lock:
            for _, publisher in self._plans.values():
                try:
                    publisher.undeclare()
                except Exception:  # noqa: BLE001
                    pass
            self._plans.clear()
        self.pool.close()
        if self.session is not None:
            self.session.close()
            self.session = None

    def _spawn(self, target, name: str) -> None:
        thread = threading.Thread(target=target, name=name, daemon=True)
        thread.start()
        self._threads.append(thread)

    # --- handlers (Zenoh callback threads: parse, answer from the cache, or queue) --------------

    def _guard(self, handler):
        """Run a query handler; whatever it raises becomes a JSON reply_err, never a dead service
        or a querier left waiting. A handler returning True has handed the query to a Waiter."""

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
                if not deferred:
                    query.drop()

        return run

    def _on_schedule(self, query) -> bool:
        request = _payload(query)
        repeated = self._repeated.get(request) if request is not None else None
        if repeated is not None:  # the very request answered before: no parsing, no signing
            self._count("cache_hits")
            query.reply(query.key_expr, repeated[0], attachment=repeated[1])
            return False
        pose, cut = parse_schedule_request(request, self.settings.max_payload_bytes)
        budget_s = parse_timeout(query.parameters.get("timeout_ms"))
        key = canonical(pose, cut)
        cached = self.cache.reply(key, pose["pose_id"])
        if cached is not None:
            self._count("cache_hits")
            attachment = self._reply(query, request, cached)
            if len(request) <= 1024:
                with self._count_lock:
                    self._repeated[request] = (cached, attachment)
                    while len(self._repeated) > REPEATED_REQUESTS:
                        self._repeated.pop(next(iter(self._repeated)), None)
            return False
        now = time.monotonic()
        deadline = self._deadline(now, budget_s)
        waiter = Waiter(self, query, request, deadline, lambda: self._busy("was not computed within the request's timeout; the computation goes on and its result is kept: retry"), pose["pose_id"])
        with self._cond:
            job = self._inflight.get(key)
            if job is None:
                if len(self._lane) >= self.settings.queue_size:
                    raise self._busy(f"{len(self._lane)} computations are waiting (the limit)")
                wait = self._expected_wait(len(self._lane))
                if now + wait > deadline:
                    raise self._busy(f"the expected wait ({wait:.1f} s) is longer than the request's timeout", wait)
                job = Job(key, pose, cut)
                self._inflight[key] = job
                self._lane.append(job)
                self._cond.notify()
            elif len(job.waiters) >= WAITERS_PER_JOB:
                raise self._busy(f"{len(job.waiters)} queries wait for this pose already (the limit)")
            job.waiters.append(waiter)
        self._watch(waiter)
        return True

    def _on_plan_query(self, query) -> bool:
        plan_id = valid_plan_id(str(query.key_expr).rsplit("/", 1)[-1])
        request_bytes = _payload(query)
        request = parse_plan_request(request_bytes, self.settings.max_plan_payload_bytes, self.settings.max_plan_poses)
        if request is None:
            self._reply(query, request_bytes, json.dumps(self.stored_plan(plan_id)).encode())
            return False
        poses, cut, times = request
        budget_s = parse_timeout(query.parameters.get("timeout_ms"))
        now = time.monotonic()
        with self._cond:
            same = self._pending.get(plan_id)
            if same is not None and (same.poses != poses or same.cut != cut or same.times != times):
                raise self._busy(f"plan {plan_id!r} is being computed with other poses", self._expected_wait(0, self._uncached(same)))
        plan = same or self._accept_plan(plan_id, poses, cut, times)  # the same plan asked again: wait for it
        waiter = Waiter(self, query, request_bytes, self._deadline(now, budget_s), lambda: json.dumps(self._plan_progress(plan, "accepted")).encode())
        with self._cond:
            finished = plan.finishing
            waits = not finished and len(plan.waiters) < WAITERS_PER_JOB and now + self._expected_wait(len(self._lane), self._uncached(plan)) <= waiter.deadline
            if waits:
                plan.waiters.append(waiter)
        if waits:
            self._watch(waiter)
        elif not finished:
            waiter.expire()  # longer than this query can wait: "accepted" now, computed in the background
        elif plan.failed is not None:
            waiter.error(plan.failed)
        else:
            waiter.reply(json.dumps(plan.doc).encode())
        return True

    def _on_plan_put(self, sample) -> None:
        try:
            self._count("queries")
            plan_id = valid_plan_id(str(sample.key_expr).rsplit("/", 1)[-1])
            request = parse_plan_request(sample.payload.to_bytes(), self.settings.max_plan_payload_bytes, self.settings.max_plan_poses)
            if request is None:
                raise RequestError("missing_payload", "a plan put needs its poses")
            self._accept_plan(plan_id, *request)
        except RequestError as exc:
            self._count("errors")
            log.warning("plan put on %s refused: %s: %s", sample.key_expr, exc.code, exc.message)
        except Exception:  # noqa: BLE001 - a service never dies of a bad message
            self._count("errors")
            log.exception("plan put on %s failed", sample.key_expr)

    def _on_status(self, query) -> bool:
        self._reply(query, _payload(query), json.dumps(self.status()).encode())
        return False

    def status(self) -> dict:
        with self._count_lock:
            counts = dict(self.counts)
        with self._cond:
            lanes = {"queue": len(self._lane), "plans_pending": len(self._pending), "computing": self._running}
        return {
            "cell": self.settings.cell,
            "model_version": self.model_version,
            "service_id": self.service_id,
            "uptime_s": round(time.monotonic() - self.started, 3),
            "seconds_per_pose": round(self._seconds_per_pose, 4),  # median of the last 32
            "cached_schedules": len(self.cache),
            "plans": len(self._plans),
            "limits": {f.name: getattr(self.settings, f.name) for f in fields(self.settings) if f.name != "cell"},
            "signed": self.signing_key is not None,
            **lanes,
            **counts,
        }

    # --- plans -----------------------------------------------------------------------------------

    def _accept_plan(self, plan_id: str, poses: list[dict], cut: dict, times: list[float] | None = None) -> PlanJob:
        with self._cond:
            if self._closing:
                raise RequestError("shutting_down", "the service is stopping")
            if plan_id in self._pending:
                raise self._busy(f"plan {plan_id!r} is being computed", self._expected_wait(0, self._uncached(self._pending[plan_id])))
            if len(self._pending) >= self.settings.pending_plans:
                ahead = min(self._uncached(p) for p in self._pending.values())  # a slot frees when the first is done
                raise self._busy(f"{len(self._pending)} plans are being computed (the limit)", self._expected_wait(len(self._lane), ahead))
            plan = PlanJob(plan_id, poses, cut, times)
            self._pending[plan_id] = plan
            self._plan_lane.append(plan)
            self._cond.notify()
        self._count("plans_accepted")
        return plan

    def _uncached(self, plan: PlanJob) -> int:
        return sum(not self.cache.has(k) for k in plan.keys)

    def _plan_progress(self, plan: PlanJob, state: str) -> dict:
        with self._cond:
            left = self._uncached(plan)
            done = len(plan.keys) - left
            wait = self._expected_wait(len(self._lane), left)
        return {"plan_id": plan.plan_id, "state": state, "done": done, "total": len(plan.keys), "retry_after_ms": int(1000 * min(max(wait, 0.2), 30.0)),
                "model_version": self.model_version, "service_id": self.service_id}

    def stored_plan(self, plan_id: str) -> dict:
        """The plan, or its progress while it is computed; `unknown_plan` / `stale_plan` else."""
        with self._cond:
            pending = self._pending.get(plan_id)
        if pending is not None:
            return self._plan_progress(pending, "pending")
        with self._publish_lock:
            held = self._plans.get(plan_id)
        if held is not None:
            return held[0]
        if self.store is not None:
            plan, stale = self.store.read(plan_id, self.model_version)
            if plan is not None and not stale:
                return dict(plan, service_id=self.service_id)  # served by this session now
            if plan is not None:
                raise RequestError("stale_plan", f"plan {plan_id!r} was computed with model {plan['model_version'][:12]}, not the serving {self.model_version[:12]}; send its poses again")
        raise RequestError("unknown_plan", f"plan {plan_id!r}: no such plan (send its poses to compute it)")

    def _recompute_stale(self, plan: dict) -> None:
        try:
            self._accept_plan(plan["plan_id"], plan["poses"], plan["cut"], plan.get("times_s"))
            log.warning("stored plan %s was computed with model %s: recomputing it with %s", plan["plan_id"], plan["model_version"][:12], self.model_version[:12])
        except RequestError as exc:
            log.warning("stored plan %s of model %s is not republished (%s); it is recomputed when its poses are sent again", plan["plan_id"], plan["model_version"][:12], exc.message)

    def _finish_plan(self, plan: PlanJob) -> None:
        """Store, publish and answer a plan whose poses are all computed (or fail it)."""
        if plan.failed is None:
            try:
                entries = [json.loads(self.cache.reply(k, p["pose_id"]) or b"null") for k, p in zip(plan.keys, plan.poses)]
                if any(e is None for e in entries):
                    raise RequestError("busy", "part of the plan left the cache before the plan was complete; send it again (or raise cache_entries)")
                plan.doc = {"schema_version": SCHEMA_VERSION, "plan_id": plan.plan_id, "model_version": self.model_version, "service_id": self.service_id,
                            "published_at": _now(), "cut": plan.cut, "poses": plan.poses, "entries": entries}
                if plan.times is not None:  # the coil's trajectory through the poses, planned in a worker
                    plan.doc["times_s"] = plan.times
                    plan.doc["trajectory"] = self.pool.call(workers.trajectory, [e["absorber"]["target_hz"] for e in entries], plan.times)
                if self.store is not None:
                    self.store.write(plan.doc)
                self._publish(plan.doc)
            except RequestError as exc:
                plan.failed = exc
            except Exception as exc:  # noqa: BLE001
                log.exception("plan %s could not be stored or published", plan.plan_id)
                plan.failed = RequestError("internal", f"{type(exc).__name__}: {exc}")
        with self._cond:
            self._pending.pop(plan.plan_id, None)
            waiters = list(plan.waiters)
        if plan.failed is not None:
            log.warning("plan %s failed: %s: %s", plan.plan_id, plan.failed.code, plan.failed.message)
        reply = None if plan.failed is not None else json.dumps(plan.doc).encode()
        for waiter in waiters:
            waiter.error(plan.failed) if reply is None else waiter.reply(reply)

    def _publish(self, plan: dict) -> None:
        """The whole plan on one AdvancedPublisher (cached for late joiners), entries live; at most
        `plans_in_memory` publishers, the oldest undeclared first."""
        plan = dict(plan, service_id=self.service_id)  # a stored plan is republished by this session
        plan_id = plan["plan_id"]
        base = f"{self.prefix}/{keys.schedules(plan_id)}"
        whole = json.dumps(plan).encode()
        with self._publish_lock:
            held = self._plans.pop(plan_id, None)
            if held is not None:
                held[1].undeclare()
            publisher = declare_advanced_publisher(self.session, base, cache=CacheConfig(max_samples=1), publisher_detection=True)
            publisher.put(whole, attachment=self._sample_signature(base, whole))
            for i, entry in enumerate(plan["entries"]):
                key, payload = f"{base}/{i}", json.dumps(entry).encode()
                self.session.put(key, payload, attachment=self._sample_signature(key, payload))
            self._plans[plan_id] = (plan, publisher)
            while len(self._plans) > self.settings.plans_in_memory:
                _, (_, gone) = self._plans.popitem(last=False)
                gone.undeclare()
        self._count("plans_published")

    # --- dispatch (threads of this process; the work itself runs in the worker processes) -------

    def _dispatch(self) -> None:
        while True:
            with self._cond:
                while not self._closing and not self._lane and not self._plan_lane:
                    self._cond.wait()
                if self._closing:
                    return
                task = ("schedule", self._lane.popleft()) if self._lane else self._plan_step()
                self._running += 1
            kind = task[0]
            try:
                if kind == "schedule":
                    self._run_job(task[1])
                elif kind == "check":
                    self._run_check(task[1])
                elif kind == "pose":
                    self._run_plan_pose(task[1], task[2])
            finally:
                with self._cond:
                    self._running -= 1
                    if kind in ("check", "pose"):
                        task[1].outstanding -= 1
                    finish = kind != "schedule" and self._plan_complete(task[1])
                if finish:
                    self._finish_plan(task[1])

    def _plan_step(self) -> tuple:
        """The next piece of work of the first plan in the lane (holding the lock)."""
        plan = self._plan_lane[0]
        if not plan.checked:
            self._plan_lane.popleft()  # back in the lane once its poses are checked
            plan.outstanding += 1
            return ("check", plan)
        while plan.next < len(plan.keys) and self.cache.has(plan.keys[plan.next]):
            plan.next += 1
        if plan.next >= len(plan.keys) or plan.failed is not None:
            self._plan_lane.popleft()
            return ("idle", plan)
        plan.next += 1
        plan.outstanding += 1
        return ("pose", plan, plan.next - 1)

    def _plan_complete(self, plan: PlanJob) -> bool:
        """Whether the caller finishes the plan now (holding the lock; true once per plan)."""
        if plan.finishing or plan.outstanding or plan in self._plan_lane:
            return False
        if plan.failed is None and not (plan.checked and plan.next >= len(plan.keys)):
            return False
        plan.finishing = True
        return True

    def _run_check(self, plan: PlanJob) -> None:
        try:
            self.pool.call(workers.check_poses, plan.poses, plan.cut)
        except RequestError as exc:
            plan.failed = exc
        with self._cond:
            plan.checked = True
            if plan.failed is None and not self._closing:
                self._plan_lane.appendleft(plan)
                self._cond.notify()

    def _run_plan_pose(self, plan: PlanJob, index: int) -> None:
        if plan.failed is not None or self.cache.has(plan.keys[index]):
            return
        try:
            self._compute(plan.keys[index], plan.poses[index], plan.cut)
        except RequestError as exc:
            plan.failed = RequestError(exc.code, f"poses[{index}]: {exc.message}")
            with self._cond:
                if plan in self._plan_lane:
                    self._plan_lane.remove(plan)

    def _run_job(self, job: Job) -> None:
        with self._cond:
            if all(w.done for w in job.waiters):  # everybody gave up before a worker was free
                self._inflight.pop(job.key, None)
                self._count("dropped")
                return
        error = None
        if not self.cache.has(job.key):
            try:
                self._compute(job.key, job.pose, job.cut)
            except RequestError as exc:
                error = exc
            except Exception as exc:  # noqa: BLE001
                log.exception("computation failed")
                error = RequestError("internal", f"{type(exc).__name__}: {exc}")
        with self._cond:
            self._inflight.pop(job.key, None)
            waiting = list(job.waiters)
        for waiter in waiting:
            payload = None if error is not None else self.cache.reply(job.key, waiter.pose_id)
            if payload is not None:
                waiter.reply(payload)
            else:
                waiter.error(error or self._busy("the entry left the cache at once (cache_entries is too small)"))

    def _compute(self, key: str, pose: dict, cut: dict) -> None:
        start = time.monotonic()
        self._count("computations")
        entry = self.pool.call(workers.entry, pose, cut)
        with self._cond:
            self._durations.append(time.monotonic() - start)
        entry.update(model_version=self.model_version, service_id=self.service_id, computed_at=_now(), stale_after_s=self.settings.stale_after_s)
        self.cache.put(key, entry)

    # --- deadlines ------------------------------------------------------------------------------

    def _deadline(self, now: float, budget_s: float | None) -> float:
        """When to answer at the latest: the querier's budget less a margin for the reply's trip."""
        budget = budget_s if budget_s is not None else self.settings.default_timeout_s
        return now + max(budget - max(0.05, 0.1 * budget), 0.5 * budget)

    @property
    def _seconds_per_pose(self) -> float:
        """The median of the last computations: the first pose of a new damping value takes
        seconds (the virtual absorber's tuning), the rest a fraction of one."""
        with self._cond:  # re-entrant
            durations = sorted(self._durations)
        return durations[len(durations) // 2] if durations else 1.0

    def _expected_wait(self, ahead: int, poses: int = 1) -> float:
        """Seconds until `poses` computations queued behind `ahead` others are done."""
        return (ahead + self._running + poses) * self._seconds_per_pose / self.settings.workers

    def _busy(self, why: str, wait: float | None = None) -> RequestError:
        self._count("busy")
        retry = min(max(wait if wait is not None else self._seconds_per_pose, 0.05), 30.0)
        return RequestError("busy", f"busy: {why}", retry_after_ms=int(1000 * retry))

    def _watch(self, waiter: Waiter) -> None:
        with self._deadline_cond:
            heapq.heappush(self._deadlines, (waiter.deadline, id(waiter), waiter))
            self._deadline_cond.notify()

    def _watch_deadlines(self) -> None:
        """Answer every waiter whose deadline has come (its `on_expire`)."""
        while True:
            with self._deadline_cond:
                if self._closing:
                    return
                now, due = time.monotonic(), None
                while self._deadlines:
                    deadline, _, waiter = self._deadlines[0]
                    if waiter.done or deadline <= now:
                        heapq.heappop(self._deadlines)
                        if not waiter.done:
                            due = waiter
                            break
                        continue
                    break
                if due is None:
                    self._deadline_cond.wait(self._deadlines[0][0] - now if self._deadlines else None)
                    continue
            self._count("expired")
            try:
                due.expire()
            except Exception:  # noqa: BLE001 - the querier may be gone
                log.exception("answering an expired request failed")

    # --- replies ----------------------------------------------------------------------------------

    def _reply(self, query, request: bytes | None, payload: bytes) -> bytes | None:
        """Reply (signed when the service has a key); returns the signature."""
        attachment = reply_signature(self.signing_key, str(query.key_expr), request, payload) if self.signing_key else None
        query.reply(query.key_expr, payload, attachment=attachment)
        return attachment

    def _reply_error(self, query, exc: RequestError) -> None:
        self._count("errors")
        try:
            query.reply_err(exc.to_json())  # unsigned: Zenoh 1.10's reply_err carries no attachment
        except Exception:  # noqa: BLE001 - the querier may be gone
            log.warning("could not deliver error %s", exc.code)

    def _sample_signature(self, key_expr: str, payload: bytes) -> bytes | None:
        return sample_signature(self.signing_key, key_expr, payload) if self.signing_key else None

    def _count(self, name: str) -> None:
        with self._count_lock:
            self.counts[name] += 1


def _payload(query) -> bytes | None:
    payload = query.payload
    return None if payload is None else payload.to_bytes()


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")
