"""Critical depth and dominant chatter frequency of structures at a speed: the one entry point
every user-facing stability number goes through (`posedyn chatter`, the per-pose chain behind
`posedyn schedule`, the sweep, the service and the gap workflow).

By default the converged engine (`floquet`: the exact Floquet characteristic equation, with its
resolution chosen from the cut until the estimated relative error is below `REL_TOL`, and a
multiplier count below the reported depth that guarantees no lower boundary point was missed).
`steps` is the expert override: the semi-discretization with that many steps per delay, whose
error is not estimated (`converged` None) - at low speed with kHz modes it can be off by 2x.
"""

from __future__ import annotations

import dataclasses
import math
import multiprocessing
import threading
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from posedyn.dynamics import ToolTipDynamics
from posedyn.stability import floquet, surface, zoa
from posedyn.stability.batch import BatchStability
from posedyn.stability.cutting import Cut
from posedyn.stability.model import Discretization

#: Relative accuracy every default result reaches (or says it did not).
REL_TOL = 0.02
#: Relative bisection tolerance of the semi-discretization override.
SDM_REL_TOL = 2e-3


@dataclass(frozen=True)
class StabilityResult:
    """Critical depth (m; inf: never chatters), dominant chatter frequency (Hz; NaN when not
    asked or undefined) and the accuracy reached."""

    depth_m: float
    chatter_hz: float
    method: str  # "floquet" (converged engine) or "sdm" (override)
    converged: bool | None  # None: not estimated (the semi-discretization override)
    rel_error_estimate: float  # NaN where not estimated
    steps: int | None = None  # the override's steps per delay
    family: tuple = ()  # ((hz, relative tool-tip amplitude), ...), largest first
    free_flight_decay_efolds: float = math.nan  # `free_flight_decay` (NaN without a chatter frequency)
    no_growth_depth_m: float = math.nan  # `surface.no_growth_depth` where only the surface remembers the last pass (else NaN)

    @property
    def surface_memory(self) -> bool:
        """Whether the chattering mode's vibration dies out between cuts (`free_flight_decay` above
        SURFACE_MEMORY_EFOLDS): the depth is then an asymptotic boundary only."""
        return self.free_flight_decay_efolds > SURFACE_MEMORY_EFOLDS

    def accuracy_json(self) -> dict:
        out = {"method": self.method, "converged": self.converged,
               "rel_error_estimate": self.rel_error_estimate if math.isfinite(self.rel_error_estimate) else None,
               "free_flight_decay_efolds": self.free_flight_decay_efolds if math.isfinite(self.free_flight_decay_efolds) else None,
               "no_growth_depth_mm": self.no_growth_depth_m * 1e3 if math.isfinite(self.no_growth_depth_m) else None}
        if self.steps is not None:
            out["steps"] = self.steps
        return out


@dataclass(frozen=True)
class AbsoluteLimit:
    """The speed-independent limit reported beside critical depths: the zeroth-order estimate
    (Altintas-Budak, `zoa.absolute_limit_m`), capped by the critical depths computed at any
    speed. The absolute limit is the infimum of the critical depth over speeds, so no computed
    depth can be below it; the zeroth order (averaged directional factors) can be above it at
    low lobe numbers and in interrupted cuts (seen: 0.61 mm beside a converged 0.43 mm at
    600 rpm, a 10 Hz robot mode, 2 teeth). `source` says which one it is."""

    depth_m: float
    source: str  # "zoa" (the estimate) or "computed" (the lowest critical depth computed)


def absolute_limit(dyn: ToolTipDynamics, cut: Cut, depths_m) -> AbsoluteLimit:
    """`AbsoluteLimit` of a structure from its zeroth-order estimate and the critical depths (m)
    computed for it (at one speed or many; non-finite ones ignored)."""
    estimate = zoa.absolute_limit_m(dyn, cut)
    depths = np.asarray(depths_m, dtype=float).reshape(-1)
    depths = depths[np.isfinite(depths)]
    if len(depths) and depths.min() < estimate:
        return AbsoluteLimit(float(depths.min()), "computed")
    return AbsoluteLimit(estimate, "zoa")


def critical_points(structures: list[ToolTipDynamics], cut: Cut, rpm, steps: int | None = None, frequencies: bool = True, verify: bool = True,
                    continuation: bool = False) -> list[StabilityResult]:
    """The StabilityResult of each structure at its speed (`rpm` one value or one per
    structure); `steps` switches to the semi-discretization override. A structure the engine
    fails on numerically comes back not converged with an infinite error estimate and a NaN
    depth (unknown), never as an exception that takes the other structures down.
    `continuation`: structures with similar modes start from each other's boundary points
    (`floquet.critical_depths`; the same verified answers at about half the cost)."""
    structures = list(structures)
    rpm = np.broadcast_to(np.asarray(rpm, dtype=float), (len(structures),))
    if not structures:
        return []
    if steps is None:
        points = _floquet_points(structures, cut, rpm, verify, frequencies, continuation)
        results = [_converged_or_flagged(p, frequencies) for p in points]
    else:
        results = _sdm_points(structures, cut, rpm, steps, frequencies)
    return [_with_surface_memory(r, s, cut, float(n)) for r, s, n in zip(results, structures, rpm)]


def _floquet_points(structures, cut, rpm, verify, frequencies=True, continuation=False):
    """The engine's CriticalPoints, or None for a structure it could not solve (a numerical
    failure in one structure must not take the batch down: the batch is retried one by one)."""
    try:
        return floquet.critical_depths(structures, cut, rpm, rel_tol=REL_TOL, verify=verify, frequencies=frequencies, continuation=continuation)
    except (np.linalg.LinAlgError, FloatingPointError, ValueError, ZeroDivisionError):
        if len(structures) == 1:
            return [None]
        return [_floquet_points([s], cut, [r], verify, frequencies)[0] for s, r in zip(structures, rpm)]


#: `free_flight_decay` above this (e-folds: the vibration keeps under 1 % of its amplitude at the
#: next cut): the boundary is asymptotic only, and where every relevant mode decays so, the pass
#: map's premise (each pass starts from rest) holds to that 1 % (`surface`). It was 20 until a
#: new user's case at 11 e-folds (one 3 kHz mode, 4 teeth at 300 rpm): a surface perturbation
#: grew 52-fold at 8 mm under the 10.1 mm boundary with no word said (no-growth depth 3.71 mm).
SURFACE_MEMORY_EFOLDS = 5.0


def free_flight_decay(dyn: ToolTipDynamics, cut: Cut, rpm: float, chatter_hz: float) -> float:
    """zeta w T_free: the e-folds by which the structure's mode nearest the chatter frequency
    decays over the non-cutting stretch of a tooth period, T_free = (2 pi / N - engagement) /
    Omega (0 where the teeth always cut; NaN without a chatter frequency).

    Where it is large (SURFACE_MEMORY_EFOLDS), the tool's vibration is gone before the next
    cut and only the surface keeps the previous pass: the pass-to-pass map is far from normal.
    The critical depth (the linear delay equation's Floquet boundary) is still exact, but below
    it perturbations can grow for many passes before they decay. Measured with the tests'
    independent time-domain simulation (one 3 kHz mode a direction, zeta 0.02, one tooth, a/D
    0.1, up milling; boundary 132 / 117 / 92 mm at 300 / 1000 / 3000 rpm, confirmed at 1000 and
    3000 rpm: decaying at 110 and 90 mm, growing at 125 and 100 mm): at 300 rpm (68 e-folds) a
    perturbation grew 300-fold at 20 mm, 1e5 at 30 mm and 1e12 at 60 mm before it decayed; at
    3000 rpm (6.8) at most 34-fold at 90 mm, and the worst surface grows from one pass to the next
    from 15.7 mm (`surface.no_growth_depth`)."""
    if not math.isfinite(chatter_hz) or chatter_hz <= 0:
        return math.nan
    return float(_mode_decays(dyn, cut, rpm)[int(np.argmin(np.abs(dyn.fn_hz - chatter_hz)))])


def _mode_decays(dyn: ToolTipDynamics, cut: Cut, rpm: float) -> np.ndarray:
    """zeta w T_free of every mode (`free_flight_decay`)."""
    start, exit_ = cut.engagement_rad
    free_rad = max(0.0, 2.0 * math.pi / cut.teeth - (exit_ - start))
    return dyn.zeta * 2.0 * math.pi * dyn.fn_hz * free_rad / (2.0 * math.pi * rpm / 60.0)


def modes_carrying_over(dyn: ToolTipDynamics, cut: Cut, rpm: float) -> np.ndarray:
    """Frequencies (Hz) of the relevant modes (`floquet.relevant_modes`) that decay by at most
    SURFACE_MEMORY_EFOLDS between cuts: they carry vibration from one pass into the next (a robot
    mode at 10-20 Hz always does), which the pass map (`surface`) leaves out."""
    keep = floquet.relevant_modes(dyn)
    return dyn.fn_hz[keep][_mode_decays(dyn, cut, rpm)[keep] <= SURFACE_MEMORY_EFOLDS]


def _with_surface_memory(result: StabilityResult, dyn: ToolTipDynamics, cut: Cut, rpm: float) -> StabilityResult:
    """`result` with its chattering mode's `free_flight_decay` and, where only the surface
    remembers the last pass, its no-growth depth (`_with_no_growth_depth`): every result of
    `critical_points` and `critical_lobes` goes through this."""
    result = dataclasses.replace(result, free_flight_decay_efolds=free_flight_decay(dyn, cut, rpm, result.chatter_hz))
    return _with_no_growth_depth(result, dyn, cut, rpm)


def _with_no_growth_depth(result: StabilityResult, dyn: ToolTipDynamics, cut: Cut, rpm: float) -> StabilityResult:
    """`result` with the depth below which no surface perturbation grows from one pass to the
    next (`surface.no_growth_depth`), where the chattering mode and every other relevant one
    (`floquet.relevant_modes`) decay by more than SURFACE_MEMORY_EFOLDS between cuts (the pass
    map's premise: each pass starts from rest; a robot mode that keeps vibrating between cuts
    carries state it leaves out) and the depth is resolved to REL_TOL; else unchanged (NaN)."""
    if not result.surface_memory or len(modes_carrying_over(dyn, cut, rpm)):
        return result
    try:
        limit = surface.no_growth_depth(dyn, cut, rpm, result.depth_m)
    except (RuntimeError, np.linalg.LinAlgError, ValueError, FloatingPointError):  # (ARPACK's no convergence is a RuntimeError): no depth, not a failed result
        return result
    if not limit.rel_error_estimate <= REL_TOL:
        return result
    return dataclasses.replace(result, no_growth_depth_m=limit.depth_m)


def _converged_or_flagged(point, frequencies: bool) -> StabilityResult:
    if point is None:
        return StabilityResult(math.nan, math.nan, "floquet", False, math.inf)  # unknown, not "never chatters"
    converged = bool(point.converged) and point.verified is not False  # a failed check is not a converged answer
    return StabilityResult(point.depth_m, point.chatter_hz if frequencies else math.nan, "floquet", converged,
                           _estimate(point.rel_error_estimate, point.verified), family=tuple(point.family))


def _estimate(rel_error_estimate: float, verified) -> float:
    """The error estimate a result reports: the resolution's, or inf where the multiplier count
    found a lower branch it could not place (the estimate is then of another boundary point)."""
    return math.inf if verified is False else float(rel_error_estimate)


def _sdm_points(structures, cut, rpm, steps, frequencies) -> list[StabilityResult]:
    out: list[StabilityResult] = [None] * len(structures)
    groups: dict[int, list[int]] = {}
    for i, dyn in enumerate(structures):
        groups.setdefault(dyn.n_modes, []).append(i)
    for members in groups.values():
        batch = BatchStability([structures[i] for i in members], cut, rpm[members], Discretization(steps))
        result = batch.critical_depths(frequencies=frequencies, rel_tol=SDM_REL_TOL, guess_m=7.0 * batch.scale_m, rungs=2)
        for j, i in enumerate(members):
            out[i] = StabilityResult(float(result.depth_m[j]), float(result.dominant_chatter_hz[j]), "sdm", None, math.nan, steps, tuple(result.family[j]))
    return out


#: Fewest speeds a lobe diagram gives each process (below this one process does them all).
SPEEDS_PER_WORKER = 16


def critical_lobes(dyn: ToolTipDynamics, cut: Cut, rpm, steps: int | None = None, workers: int = 1) -> list[StabilityResult]:
    """The StabilityResult of one structure at many speeds (stability lobes): the converged
    engine's batched `floquet.lobes` by default, verified per speed by the multiplier count (a
    speed whose count fails is flagged not converged), the semi-discretization with `steps`.

    `workers` > 1 shares the engine's speeds among that many processes (this one and forked
    children; every k-th speed to one, so each gets low and high speeds alike). The speeds are
    solved independently, so the answers are the same as in one process (each process with one
    BLAS thread); where the platform
    cannot fork, this is a daemon process or runs other threads, or there are fewer than SPEEDS_PER_WORKER speeds a
    process, one does them all; a child that dies has its share computed here."""
    rpm = np.atleast_1d(np.asarray(rpm, dtype=float))
    if steps is not None:
        return critical_points([dyn] * len(rpm), cut, rpm, steps, frequencies=False)
    workers = max(1, min(int(workers), len(rpm) // SPEEDS_PER_WORKER))
    if workers > 1 and _can_fork():
        # one BLAS thread a process (the children inherit it): two processes with a BLAS pool
        # each on two cores took 7.9 s for the issue-17 lobes, one process 6.1 s, this 3.1 s
        with threadpool_limits(1, user_api="blas"), ProcessPoolExecutor(workers - 1, mp_context=multiprocessing.get_context("fork")) as pool:
            shares = [pool.submit(_lobe_points, dyn, cut, rpm[k::workers]) for k in range(1, workers)]
            points: list = [None] * len(rpm)
            points[0::workers] = _lobe_points(dyn, cut, rpm[0::workers])
            for k, share in enumerate(shares, start=1):
                try:
                    points[k::workers] = share.result()
                except BrokenProcessPool:  # a child that died (killed, out of memory): its share here
                    points[k::workers] = _lobe_points(dyn, cut, rpm[k::workers])
        return points
    return _lobe_points(dyn, cut, rpm)


def _can_fork() -> bool:
    """Fork only where it is safe and allowed: the platform has it, this process is no daemon
    (which may not have children) and runs one thread (a lock another thread holds would stay
    held in the child forever)."""
    return "fork" in multiprocessing.get_all_start_methods() and not multiprocessing.current_process().daemon and threading.active_count() == 1


def _lobe_points(dyn: ToolTipDynamics, cut: Cut, rpm: np.ndarray) -> list[StabilityResult]:
    lobes = floquet.lobes(dyn, cut, rpm, rel_tol=REL_TOL, verify=True)
    return [
        _with_surface_memory(StabilityResult(float(d), float(f), "floquet", bool(c and v), _estimate(e, bool(v))), dyn, cut, float(n))
        for d, f, c, v, e, n in zip(lobes.depth_m, lobes.chatter_hz, lobes.converged, lobes.verified, lobes.rel_error_estimate, rpm)
    ]
