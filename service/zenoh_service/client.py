"""The cell side: a small client for the schedule service.

    with ScheduleClient("cell1", connect=["tcp/10.0.0.5:7447"]) as client:
        entry = client.schedule({"x_mm": 1400, "y_mm": 0, "z_mm": 800, "beta_deg": 0})
        plan = client.plan("job-42", poses)

Queries use target ALL_COMPLETE; zero replies is an error (an undeclared or unreachable
queryable can give an empty answer rather than a failure), and so is a reply_err, raised as
`ServiceError(code, message)`.
"""

from __future__ import annotations

import json
from pathlib import Path

import zenoh

from service.zenoh_service import keys
from service.zenoh_service.session import zenoh_config


class ServiceError(Exception):
    def __init__(self, code: str, message: str):
        super().__init__(f"{code}: {message}")
        self.code, self.message = code, message


class ScheduleClient:
    def __init__(self, cell: str, connect=(), config: Path | None = None, mode: str = "client", timeout_s: float = 5.0):
        self.cell, self.timeout_s = cell, timeout_s
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

    def schedule(self, pose: dict, cut: dict | None = None) -> dict:
        request = {"pose": pose} if cut is None else {"pose": pose, "cut": cut}
        return self.get(keys.SCHEDULE, request)

    def plan(self, plan_id: str, poses: list[dict], cut: dict | None = None, timeout_s: float | None = None) -> dict:
        request = {"poses": poses} if cut is None else {"poses": poses, "cut": cut}
        return self.get(keys.plan(plan_id), request, timeout_s)

    def stored_plan(self, plan_id: str) -> dict:
        return self.get(keys.plan(plan_id), None)

    def status(self) -> dict:
        return self.get(keys.STATUS, None)

    def get(self, suffix: str, request, timeout_s: float | None = None, raw: bytes | None = None) -> dict:
        """One query; the first reply's JSON, or ServiceError."""
        if self.session is None:
            self.open()
        payload = raw if raw is not None else (None if request is None else json.dumps(request, allow_nan=False).encode())
        replies = self.session.get(
            f"{self.prefix}/{suffix}", payload=payload, target=zenoh.QueryTarget.ALL_COMPLETE, timeout=timeout_s or self.timeout_s
        )
        for reply in replies:
            if reply.ok is not None:
                return json.loads(reply.ok.payload.to_bytes())
            try:
                err = json.loads(reply.err.payload.to_bytes())
                raise ServiceError(err.get("error", "error"), err.get("message", ""))
            except (ValueError, AttributeError):
                raise ServiceError("error", reply.err.payload.to_string()) from None
        raise ServiceError("no_reply", f"no reply on {self.prefix}/{suffix} within {timeout_s or self.timeout_s} s (is the service running and reachable?)")
