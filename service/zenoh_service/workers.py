"""The service's computations, in worker processes.

Each worker process loads its own `ScheduleEngine` (model, cut, absorber, actuator, twin) once
and computes schedule entries. The service's own process only parses requests, answers from its
cache and talks Zenoh: a computation holds no lock or interpreter the cached path needs, so
cached answers never wait behind one. A worker that dies (killed, out of memory) fails the
requests it was computing with `internal` and the pool is started again.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path

from absorber.files import load_tuning_cache, read_absorber, read_actuator, read_drive, save_tuning_cache
from absorber.tuning import known_tunings
from posedyn.io.json_values import json_ready
from posedyn.io.cut import read_cut
from posedyn.io.model_dir import load_model
from posedyn.io.tool_file import read_tool
from posedyn.io.twin_file import load_twin
from service.heap import keep_freed_memory
from service.zenoh_service.engine import ScheduleEngine, model_version
from service.zenoh_service.protocol import RequestError


@dataclass(frozen=True)
class EngineSpec:
    """What a worker process needs to build its engine (files only: nothing heavy crosses)."""

    model_dir: Path
    cut: Path
    absorber: Path | None = None
    actuator: Path | None = None
    twin: Path | None = None
    robust_samples: int = 0
    tools: tuple[Path, Path] | None = None  # (reference, target) tool files: schedules for the target tool
    pivot_mm: float = 150.0

    def check(self) -> None:
        """Every settings file read here, in the service's own process: a bad one stops the
        service at its start with the file's error (in the workers alone it was every query's
        `internal` error, the service up)."""
        read_cut(self.cut)
        read_absorber(self.absorber)
        read_drive(self.absorber)
        read_actuator(self.actuator)
        if self.twin is not None:
            load_twin(self.twin)
        for tool in self.tools or ():
            read_tool(tool)

    def build(self) -> ScheduleEngine:
        return ScheduleEngine(self.model_dir, self.cut, self.absorber, self.actuator, self.twin, self.robust_samples, self.tools, self.pivot_mm)

    def model_version(self) -> str:
        return model_version(load_model(self.model_dir).training_hash_, self.robust_samples, self.tools, self.pivot_mm, (self.cut, self.absorber, self.actuator, self.twin))


_engine: ScheduleEngine | None = None


def _start_worker(spec: EngineSpec) -> None:
    from threadpoolctl import threadpool_limits  # noqa: PLC0415 - in the worker only

    threadpool_limits(1)  # one core per worker: BLAS threads would compete with the service's process
    keep_freed_memory()  # a spawned worker starts with glibc's thresholds (service.heap)
    global _engine
    _engine = spec.build()
    load_tuning_cache()  # the virtual absorber's optima of earlier runs: seconds each otherwise


def _pid() -> int:
    return os.getpid()


def entry(pose: dict, cut: dict) -> dict:
    """The schedule entry of one pose (in a worker process)."""
    known = len(known_tunings())
    out = json_ready(_engine.entry(pose, cut))
    if len(known_tunings()) > known:
        save_tuning_cache()
    return out


def trajectory(targets_hz: list[float], times_s: list[float]) -> dict:
    """The coil's planned trajectory through a plan's targets (in a worker process)."""
    return json_ready(_engine.trajectory(targets_hz, times_s))


def check_poses(poses: list[dict], cut: dict) -> None:
    """Workspace, reachability and cut overrides of a plan's poses, before any of them is computed."""
    for i, pose in enumerate(poses):
        try:
            _engine.pose_set(pose)
        except RequestError as exc:
            raise RequestError(exc.code, f"poses[{i}]: {exc.message}") from None
    _engine.config(cut)


class WorkerPool:
    """`workers` processes, each with its engine; `call` runs a function of this module in one."""

    def __init__(self, spec: EngineSpec, workers: int):
        self.spec, self.workers = spec, workers
        self._executor: ProcessPoolExecutor | None = None
        self._lock = threading.Lock()

    def start(self) -> "WorkerPool":
        """Start the processes and wait until every engine is loaded (raises if one cannot be)."""
        with self._lock:
            self._executor = self._new_executor()
            executor = self._executor
        try:
            for future in [executor.submit(_pid) for _ in range(self.workers)]:
                future.result()
        except BrokenProcessPool:
            raise RuntimeError("a worker process could not load the model (see its error above)") from None
        return self

    def call(self, function, *args):
        with self._lock:
            executor = self._executor
        if executor is None:
            raise RequestError("shutting_down", "the service is stopping")
        try:
            return executor.submit(function, *args).result()
        except BrokenProcessPool:
            self._restart(executor)
            raise RequestError("internal", "a worker process died during the computation (it was restarted); retry") from None

    def pids(self) -> list[int]:
        with self._lock:
            executor = self._executor
        return sorted(getattr(executor, "_processes", None) or {})

    def close(self) -> None:
        with self._lock:
            executor, self._executor = self._executor, None
        if executor is not None:
            processes = list((getattr(executor, "_processes", None) or {}).values())
            executor.shutdown(wait=False, cancel_futures=True)
            for process in processes:  # a computation may take seconds: stop it rather than wait
                process.kill()
            for process in processes:
                process.join(5)

    def _restart(self, broken: ProcessPoolExecutor) -> None:
        with self._lock:
            if self._executor is not broken:  # another thread restarted it already
                return
            self._executor = self._new_executor()
        broken.shutdown(wait=False, cancel_futures=True)

    def _new_executor(self) -> ProcessPoolExecutor:
        # spawn: the service's process runs Zenoh's threads, which a fork would copy half-way
        return ProcessPoolExecutor(self.workers, mp_context=multiprocessing.get_context("spawn"), initializer=_start_worker, initargs=(self.spec,))
