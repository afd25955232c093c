"""The service's state on disk: one JSON file per published plan in `STATE_DIR/plans/`.

Every file is validated against the plan schema and the serving model's version when it is
read. A file that does not validate is moved to `STATE_DIR/rejected/` with the reason logged
(never republished, never half-loaded); a valid plan computed with another model is returned
apart (`stale`) so that the service recomputes it from its poses, never republishing it as
current. Writes are atomic and durable (fsync of the file and of its folder); at most
`max_files` plans are kept, the oldest removed first.
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from posedyn.io.atomic import sync_folder, write_text_atomic
from service.zenoh_service.protocol import RequestError, parse_cut, parse_pose, parse_times, valid_plan_id

log = logging.getLogger("posedyn.service")

SCHEMA_VERSION = 1
PLAN_KEYS = {"schema_version", "plan_id", "model_version", "published_at", "cut", "poses", "entries"}


def plan_problem(doc, plan_id: str) -> str | None:
    """Why `doc` is not a valid stored plan named `plan_id` (None when it is)."""
    if not isinstance(doc, dict):
        return f"expected a JSON object, got {type(doc).__name__}"
    missing = sorted(PLAN_KEYS - set(doc))
    if missing:
        return f"missing field(s) {missing}"
    if doc["schema_version"] != SCHEMA_VERSION:
        return f"schema_version: expected {SCHEMA_VERSION}, got {doc['schema_version']!r}"
    if doc["plan_id"] != plan_id:
        return f"plan_id: expected {plan_id!r} (the file's name), got {str(doc['plan_id'])[:60]!r}"
    if not isinstance(doc["model_version"], str) or not isinstance(doc["published_at"], str):
        return "model_version and published_at: expected strings"
    try:
        parse_cut(doc["cut"])
        poses = doc["poses"]
        if not isinstance(poses, list) or not poses:
            return "poses: expected a non-empty list"
        for i, pose in enumerate(poses):
            parse_pose(pose, f"poses[{i}]")
    except RequestError as exc:
        return exc.message
    entries = doc["entries"]
    if not isinstance(entries, list) or len(entries) != len(poses):
        return f"entries: expected a list of {len(poses)} entries, one per pose"
    for i, (entry, pose) in enumerate(zip(entries, poses)):
        if not isinstance(entry, dict) or entry.get("pose_id") != pose["pose_id"] or "critical_depth_mm" not in entry:
            return f"entries[{i}]: expected the schedule entry of pose {pose['pose_id']!r}"
    if "times_s" in doc or "trajectory" in doc:
        try:
            parse_times(doc.get("times_s"), len(poses), "times_s")
        except RequestError as exc:
            return exc.message
        trajectory = doc.get("trajectory")
        if not isinstance(trajectory, dict) or not isinstance(trajectory.get("current_a"), list) or len(trajectory["current_a"]) != len(poses):
            return f"trajectory: expected the coil's trajectory at the {len(poses)} times"
    return None


@dataclass
class PlanStore:
    state_dir: Path
    max_files: int = 256

    @property
    def folder(self) -> Path:
        return self.state_dir / "plans"

    def open(self) -> "PlanStore":
        for name in ("plans", "rejected"):
            (self.state_dir / name).mkdir(parents=True, exist_ok=True)
        for tmp in self.folder.glob(".*.tmp"):  # a write cut short by a crash: never renamed into place
            tmp.unlink(missing_ok=True)
        return self

    def write(self, plan: dict) -> None:
        write_text_atomic(self.folder / f"{plan['plan_id']}.json", json.dumps(plan) + "\n")
        files = self._files()
        for old in files[: max(0, len(files) - self.max_files)]:
            old.unlink(missing_ok=True)
        if len(files) > self.max_files:
            sync_folder(self.folder)

    def read(self, plan_id: str, model_version: str) -> tuple[dict | None, bool]:
        """(the plan, whether it was computed with another model); (None, False) when there is
        no valid file."""
        path = self.folder / f"{plan_id}.json"
        if not path.exists():
            return None, False
        plan = self._load(path)
        if plan is None:
            return None, False
        return plan, plan["model_version"] != model_version

    def load_all(self, model_version: str) -> tuple[list[dict], list[dict]]:
        """(current plans, plans of another model), oldest first; invalid files moved aside."""
        current, stale = [], []
        for path in self._files():
            plan = self._load(path)
            if plan is not None:
                (current if plan["model_version"] == model_version else stale).append(plan)
        return current, stale

    def _files(self) -> list[Path]:
        files = [f for f in self.folder.glob("*.json") if not f.name.startswith(".")]
        return sorted(files, key=lambda f: (f.stat().st_mtime, f.name))

    def _load(self, path: Path) -> dict | None:
        try:
            plan_id = valid_plan_id(path.stem)
            doc = json.loads(path.read_text(encoding="utf-8"))
            problem = plan_problem(doc, plan_id)
        except RequestError as exc:
            problem = exc.message
        except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
            problem = f"{type(exc).__name__}: {exc}"
        if problem is None:
            return doc
        self.reject(path, problem)
        return None

    def reject(self, path: Path, reason: str) -> None:
        stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S%fZ")
        target = self.state_dir / "rejected" / f"{path.name}.{stamp}"
        try:
            os.replace(path, target)
            sync_folder(path.parent)
            log.warning("stored plan %s moved to %s: %s", path, target, reason)
        except OSError as exc:
            log.warning("stored plan %s is invalid (%s) and could not be moved aside: %s", path, reason, exc)
