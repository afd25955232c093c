"""The cell side: a small client for the schedule service.

    with ScheduleClient("cell1", connect=["tcp/10.0.0.5:7447"]) as client:
        entry = client.schedule({"x_mm": 1400, "y_mm": 0, "z_mm": 800, "beta_deg": 0})
        plan = client.plan("job-42", poses)

Queries use target ALL_COMPLETE, no consolidation (every reply is seen), and send the time left
as the selector's `timeout_ms` parameter so that the service answers `busy` rather than let the
query time out; `busy` is retried with backoff (at least the
service's `retry_after_ms`) while the deadline allows. Replies are checked before they are used:
with `service_id` only that Zenoh session's replies count, with `signing_key` only replies whose
HMAC verifies, and in any case replies from more than one source are refused
(`conflicting_replies`: a rogue queryable) as is a document whose `service_id` is not its
sender's. Zero replies is an error (`no_reply`: nothing answered, or access control dropped the
query, which Zenoh does silently); an error reply is raised as `ServiceError(code, message)`.
"""

from __future__ import annotations

import json
import random
import time
from pathlib import Path

import zenoh

from service.zenoh_service import keys
from service.zenoh_service.session import zenoh_config
from service.zenoh_service.signing import reply_signature, sample_signature, valid


class ServiceError(Exception):
    def __init__(self, code: str, message: str, retry_after_ms: int | None = None):
        super().__init__(f"{code}: {message}")
        self.code, self.message, self.retry_after_ms = code, message, retry_after_ms


class ScheduleClient:
    def __init__(self, cell: str, connect=(), config: Path | None = None, mode: str = "client", timeout_s: float = 5.0,
                 service_id: str | None = None, signing_key: bytes | None = None):
        self.cell, self.timeout_s = cell, timeout_s
        self.service_id, self.signing_key = service_id, signing_key
        self.prefix = keys.prefix(cell)
        self.conf = zenoh_config(config, mode=mode, connect=connect)
        self.session = None

    def __enter__(self) -> "ScheduleClient":
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    def open(self) -> "ScheduleClient":
        self.session = zenoh.open(self.conf)
        return self

    def close(self) -> None:
        if self.session is not None:
            self.session.close()
            self.session = None

    def schedule(self, pose: dict, cut: dict | None = None, timeout_s: float | None = None) -> dict:
        request = {"pose": pose} if cut is None else {"pose": pose, "cut": cut}
        return self.get(keys.SCHEDULE, request, timeout_s)

    def plan(self, plan_id: str, poses: list[dict], cut: dict | None = None, timeout_s: float | None = None, wait: bool = True,
             times_s: list[float] | None = None) -> dict:
        """The computed plan (with `times_s`, the poses' times, also the coil's trajectory); with
        `wait`, a plan the service accepted for the background is polled until it is done or the
        timeout has passed (then its progress is returned, `{"state": "pending", "done", "total", ...}`)."""
        deadline = time.monotonic() + (timeout_s or self.timeout_s)
        request = {"poses": poses} if cut is None else {"poses": poses, "cut": cut}
        if times_s is not None:
            request["times_s"] = list(times_s)
        doc = self.get(keys.plan(plan_id), request, timeout_s)
        while wait and doc.get("state") in ("accepted", "pending"):
            left = deadline - time.monotonic()
            pause = min(doc.get("retry_after_ms", 500) / 1000.0, 5.0)
            if left <= pause:
                break
            time.sleep(pause)
            doc = self.get(keys.plan(plan_id), None, deadline - time.monotonic())
        return doc

    def stored_plan(self, plan_id: str) -> dict:
        return self.get(keys.plan(plan_id), None)

    def status(self) -> dict:
        return self.get(keys.STATUS, None)

    def get(self, suffix: str, request, timeout_s: float | None = None, raw: bytes | None = None) -> dict:
        """One request: the reply's JSON or ServiceError; `busy` is retried until the deadline."""
        if self.session is None:
            self.open()
        deadline = time.monotonic() + (timeout_s or self.timeout_s)
        backoff = 0.05
        while True:
            left = deadline - time.monotonic()
            payload = raw if raw is not None else (None if request is None else json.dumps(request, allow_nan=False).encode())
            try:
                return self._once(f"{self.prefix}/{suffix}", payload, max(left, 0.01))
            except ServiceError as exc:
                if exc.code != "busy":
                    raise
                pause = max(backoff, (exc.retry_after_ms or 0) / 1000.0) * random.uniform(1.0, 1.3)
                if time.monotonic() + pause >= deadline - 0.05:
                    raise
                time.sleep(pause)
                backoff = min(2 * backoff, 2.0)

    def _once(self, key_expr: str, payload: bytes | None, timeout_s: float) -> dict:
        selector = f"{key_expr}?timeout_ms={max(1, int(1000 * timeout_s))}"  # the service answers within it
        replies = self.session.get(selector, payload=payload, target=zenoh.QueryTarget.ALL_COMPLETE, consolidation=zenoh.ConsolidationMode.NONE, timeout=timeout_s)
        good, errors, refused = [], [], []
        for reply in replies:
            replier = str(reply.replier_id.zid) if reply.replier_id is not None else None
            if self.service_id is not None and replier != self.service_id:
                refused.append(f"a reply from {replier}, not the service {self.service_id}")
                continue
            if reply.ok is None:
                errors.append((replier, reply.err.payload.to_bytes()))
                continue
            body = reply.ok.payload.to_bytes()
            if self.signing_key is not None:
                attachment = reply.ok.attachment
                signature = attachment.to_bytes() if attachment is not None else None
                if not valid(signature, reply_signature(self.signing_key, key_expr, payload, body)):
                    refused.append(f"a reply from {replier} without a valid signature")
                    continue
            good.append((replier, body))
        sources = {r for r, _ in good} | ({r for r, _ in errors} if not good else set())
        if len(sources) > 1:
            raise ServiceError("conflicting_replies", f"{len(sources)} sessions answered {key_expr} ({sorted(map(str, sources))}): a rogue queryable may be answering; "
                               "pin the service's id (service_id, `posedyn query --service-id`) or use a signing key")
        if good:
            replier, body = good[0]
            doc = json.loads(body)
            claimed = doc.get("service_id") if isinstance(doc, dict) else None
            if claimed and replier and claimed != replier:
                raise ServiceError("forged_reply", f"the reply says it comes from {claimed} but was sent by {replier}")
            return doc
        if errors:
            try:
                err = json.loads(errors[0][1])
                raise ServiceError(err.get("error", "error"), err.get("message", ""), err.get("retry_after_ms"))
            except (ValueError, AttributeError):
                raise ServiceError("error", errors[0][1].decode(errors="replace")) from None
        if refused:
            raise ServiceError("refused_replies", "; ".join(refused[:3]))
        raise ServiceError("no_reply", f"no reply on {key_expr} within {timeout_s:.3g} s (is the service running and reachable, and does its access control let this session query?)")

    def verify_sample(self, sample) -> bool:
        """Whether a sample published on `schedules/**` carries the service's signature (True
        when the client has no signing key: nothing to check)."""
        if self.signing_key is None:
            return True
        attachment = sample.attachment
        signature = attachment.to_bytes() if attachment is not None else None
        return valid(signature, sample_signature(self.signing_key, str(sample.key_expr), sample.payload.to_bytes()))
