"""The service's key expressions, defined once for the server, the client and the docs.

Everything lives under `cells/{cell}/posedyn/`: `schedule` (queryable), `plan/{plan_id}`
(queryable and put), `schedules/{plan_id}` and `schedules/{plan_id}/{index}` (published),
`status` (queryable), `alive` (liveliness token)."""

from __future__ import annotations


def prefix(cell: str) -> str:
    return f"cells/{cell}/posedyn"


SCHEDULE = "schedule"
STATUS = "status"
ALIVE = "alive"
PLANS = "plan/*"


def plan(plan_id: str) -> str:
    return f"plan/{plan_id}"


def schedules(plan_id: str) -> str:
    return f"schedules/{plan_id}"
