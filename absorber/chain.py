"""The per-pose chain, the one computation every caller runs for a pose (the `schedule` and
`chatter`-style commands, the sweep, the Zenoh service, the gap workflow's depth rows):

    modes -> critical depth and dominant chatter (the converged engine, batched over poses)
          -> absorber target by policy -> field (clamped, flagged) -> coil current
          -> critical depth with the absorber coupled to the tool tip
          -> absolute limits (zeroth order), the field interval covering the target's +-2 std
          -> the active-damping controller entry (DVF gain, virtual absorber; seed 000)
          -> with robust samples (`robust_entries`): the depths the pose's modal uncertainty
             guarantees (95 % lower bounds, seed 002 section 4), bare and with the absorber,
             the robust absorber setting and DVF gain

Policies:
- `match` (seed 004): target = dominant chatter frequency.
- `sims`: the target (within the absorber's range) that maximises the zeroth-order absolute
  stability limit of host plus absorber, the absorber's mass and field-dependent damping
  included (seed 002's max-min Re G for the real, coupled structure).
- `depth`: the target that maximises the critical depth of host plus absorber at the cut's speed
  (the converged engine; a grid of DEPTH_GRID targets around the chatter frequency, then a
  bounded refinement): neither `match` nor `sims` is that optimum for the engine in general.

Stability is `posedyn.stability.critical_points`, batched over the poses: the converged engine
by default (every result carries the accuracy it reached), the semi-discretization when the
config's `steps` overrides it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize_scalar

from absorber.active_damping import ControlConfig, controller_entry, robust_gain
from absorber.coil import Coil
from absorber.coupling import with_absorber
from absorber.mrf import FieldSetting, MRFAbsorber
from absorber.robust import Z95
from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError, check_choice
from posedyn.robot import GridPose, Robot, TwinParameters, direction_rows, pose_modes, pose_rotation, tool_pose
from posedyn.stability import Cut, StabilityResult, absolute_limit, critical_points, zoa
from posedyn.stability.critical import REL_TOL
from posedyn.table import ModalTable, PoseSet
from posedyn.uncertainty import ModalDistribution, distributions_from_table

POLICIES = ("match", "sims", "depth")


@dataclass(frozen=True)
class ScheduleConfig:
    """The cut and speed, the devices and the settings of the chain."""

    cut: Cut
    rpm: float
    absorber: MRFAbsorber = field(default_factory=MRFAbsorber)
    coil: Coil = field(default_factory=Coil)
    control: ControlConfig = field(default_factory=ControlConfig)
    policy: str = "match"
    steps: int | None = None  # expert override: semi-discretization steps instead of the converged engine
    directions: tuple[str, ...] = ("x", "y")
    absolute_limits: bool = True  # the zeroth-order absolute limits (0.4-0.8 s a structure; sweeps skip them)
    robust_samples: int = 0  # > 0: the guaranteed depth over that many samples of each pose's modes (`robust_entries`)
    robust_seed: int = 0

    def __post_init__(self):
        check_choice("policy", self.policy, POLICIES)
        if not (math.isfinite(self.rpm) and self.rpm > 0):
            raise InputError("a spindle speed > 0 rpm", got=self.rpm, column="rpm")
        if self.steps is not None and (not isinstance(self.steps, int) or self.steps < 4):
            raise InputError("an integer number of steps >= 4 (or none: the converged engine)", got=self.steps, column="steps")
        if not isinstance(self.robust_samples, int) or isinstance(self.robust_samples, bool) or not (self.robust_samples == 0 or 8 <= self.robust_samples <= 2000):
            raise InputError("robust samples 0 (off) or 8-2000", got=self.robust_samples, column="robust_samples")


@dataclass(frozen=True, eq=False)
class PoseModes:
    """One pose's modes: its tool-tip dynamics, its table rows (direction, mode, fn_hz, zeta,
    k_n_per_m, std_fn_hz) and its tool rotation (base frame)."""

    pose_id: str
    dyn: ToolTipDynamics
    rows: tuple
    rotation: np.ndarray
    distribution: ModalDistribution | None = None  # the modes' uncertainty (None: unknown)

    @property
    def lowest_xy(self) -> tuple:
        """The row of the lowest x or y mode."""
        return min((r for r in self.rows if r[0] in ("x", "y")), key=lambda r: r[2])


@dataclass(frozen=True)
class AbsorberEntry:
    policy: str
    target_hz: float
    field_t: float
    current_a: float  # NaN where the coil cannot give the field
    feasible: bool
    field_t_interval: tuple[float, float]


@dataclass(frozen=True)
class RobustEntry:
    """The depth a cell can count on at a pose (seed 002 section 4 with the pose's own
    uncertainty): over samples of its modes, the lower end of the 95 % interval of the critical
    depth, mean - 1.96 std floored at 0, bare and with the absorber; the absorber setting is the
    nominal one or the robust one, whichever guarantees more."""

    samples: int
    depth_p95_m: float
    depth_cv: float
    tuning: str  # "nominal" or "robust"
    absorber: AbsorberEntry  # the setting that gives depth_with_absorber_p95_m
    depth_with_absorber_p95_m: float
    nominal_with_absorber_p95_m: float  # with the nominal setting, for comparison
    converged: bool  # every sample's stability result converged
    controller: dict | None = None  # `absorber.active_damping.robust_gain`: the DVF gain that keeps its margin in 95 % of samples

    def to_json(self) -> dict:
        return {
            "samples": self.samples,
            "critical_depth_p95_mm": _mm(self.depth_p95_m),
            "critical_depth_cv_pct": 100 * self.depth_cv if math.isfinite(self.depth_cv) else None,
            "tuning": self.tuning,
            "absorber": _absorber_json(self.absorber),
            "critical_depth_with_absorber_p95_mm": _mm(self.depth_with_absorber_p95_m),
            "nominal_tuning_with_absorber_p95_mm": _mm(self.nominal_with_absorber_p95_m),
            "converged": self.converged,
            "controller": self.controller,
        }


@dataclass(frozen=True, eq=False)
class PoseSchedule:
    """The chain's result for one pose (SI units; `to_json` gives the schedule entry)."""

    pose: PoseModes
    critical_depth_m: float
    dominant_chatter_hz: float
    absorber: AbsorberEntry
    critical_depth_with_absorber_m: float
    stability: StabilityResult  # the bare structure's, with the accuracy it reached
    stability_with_absorber: StabilityResult
    absolute_limit_m: float  # the zeroth-order estimate capped by the critical depth (`absolute_limit`); NaN where the config skips them
    absolute_limit_with_absorber_m: float
    controller: dict | None  # None: no robot mode below 500 Hz in the actuator's direction
    robust: RobustEntry | None = None  # None: not asked, or the pose's uncertainty is unknown

    def to_json(self) -> dict:
        out = {
            "pose_id": self.pose.pose_id,
            "critical_depth_mm": _mm(self.critical_depth_m),
            "dominant_chatter_hz": self.dominant_chatter_hz,
            "absorber": _absorber_json(self.absorber),
            "critical_depth_with_absorber_mm": _mm(self.critical_depth_with_absorber_m),
            "absolute_limit_mm": _mm(self.absolute_limit_m),
            "absolute_limit_with_absorber_mm": _mm(self.absolute_limit_with_absorber_m),
            "stability": self.stability.accuracy_json(),
            "stability_with_absorber": self.stability_with_absorber.accuracy_json(),
            "modes": [{"direction": d, "mode": m, "fn_hz": fn, "zeta": z, "k_n_per_m": k} for d, m, fn, z, k, _ in self.pose.rows],
            "controller": self.controller,
        }
        if self.robust is not None:
            out["robust"] = self.robust.to_json()
        return out


def _mm(depth_m: float):
    return depth_m * 1e3 if math.isfinite(depth_m) else None


def _absorber_json(a: AbsorberEntry) -> dict:
    return {
        "policy": a.policy,
        "target_hz": a.target_hz,
        "field_mt": a.field_t * 1e3,
        "current_a": a.current_a if math.isfinite(a.current_a) else None,
        "feasible": a.feasible,
        "field_mt_interval": [b * 1e3 for b in a.field_t_interval],
    }


def table_pose_modes(table: ModalTable, distributions: list[ModalDistribution] | None = None) -> list[PoseModes]:
    """The PoseModes of every pose of a modal table (std_fn_hz 0 where the table has none), with
    each pose's distribution where given (a pose model's `predict_distributions`, or
    `posedyn.uncertainty.distributions_from_table`)."""
    distributions = distributions if distributions is not None else [None] * len(table.poses)
    std = table.std.get("std_fn_hz")
    out = []
    for p, pose_id in enumerate(table.poses.pose_id):
        rows = tuple(
            (str(table.direction[i]), int(table.mode[i]), float(table.fn_hz[i]), float(table.zeta[i]), float(table.k_n_per_m[i]),
             float(std[i]) if std is not None and np.isfinite(std[i]) else 0.0)
            for i in np.flatnonzero(table.pose_index == p)
        )
        out.append(PoseModes(pose_id, ToolTipDynamics.from_table(table, pose_id), rows, pose_rotation(table.poses, p), distributions[p]))
    return out


def twin_pose_modes(robot: Robot, params: TwinParameters, poses: PoseSet, index=None) -> dict[int, PoseModes]:
    """{pose index: PoseModes} straight from the robot twin (its 3-D mode shapes, which a modal
    table's per-direction rows cannot hold) for the reachable poses among `index` (default all)."""
    data = robot.model.createData()
    count = params.robot_modes_per_direction
    out = {}
    for i in range(len(poses)) if index is None else index:
        pose = tool_pose(poses, i)
        try:
            _, modes = pose_modes(robot, GridPose(pose.label, pose), params, data=data)
        except InputError:
            continue
        rows = tuple((d, m, fn, z, k, 0.0) for d in ("x", "y", "z") for m, (fn, z, k) in enumerate(direction_rows(modes, d, count), 1))
        out[i] = PoseModes(poses.pose_id[i], modes.dynamics(), rows, pose.rotation)
    return out


def coupled(dyn: ToolTipDynamics, config: ScheduleConfig, field_t: float, response_hz: float | None = None) -> ToolTipDynamics:
    """Host plus the MRF absorber at a field (`absorber.coupling.with_absorber`), its damping
    the viscous equivalent of its loss at `response_hz` (`absorber_zeta`)."""
    a = config.absorber
    return with_absorber(dyn, a.mass_kg, a.stiffness_n_per_m(field_t), absorber_zeta(config, field_t, a.natural_frequency_hz(field_t), response_hz), config.directions)


def absorber_zeta(config: ScheduleConfig, field_t: float, absorber_hz: float, response_hz: float | None) -> float:
    """The absorber's damping ratio as a viscous dashpot, c = 2 zeta sqrt(k m). Its loss is
    hysteretic (loss factors, `MRFAbsorber.damping_ratio`: a force eta k x at every frequency),
    and a dashpot gives c w x, growing with frequency: equal at one frequency only. At the
    absorber's own frequency (the default) a dashpot credits a chatter mode far above it with
    (f_chatter / f_absorber) times the damping it gets (seen: an 8-63 Hz absorber raising a 5.4 kHz
    spindle mode's critical depth 5-12 fold). With the frequency the vibration to suppress has
    (`response_hz`, the chatter frequency) c = eta k / w there: zeta x f_absorber / f_response
    above the absorber's frequency; below it the resonance value (never more damping)."""
    zeta = config.absorber.damping_ratio(field_t)
    if response_hz is None or not math.isfinite(response_hz) or response_hz <= absorber_hz:
        return zeta
    return zeta * absorber_hz / response_hz


def sims_target_hz(dyn: ToolTipDynamics, config: ScheduleConfig, around_hz: float) -> float:
    """The absorber frequency that maximises the ZOA absolute limit of the coupled structure."""
    a = config.absorber
    lo, hi = a.range_hz
    lo, hi = max(lo, 0.5 * around_hz), min(hi, 2.0 * around_hz)
    if hi <= lo:
        return around_hz

    def limit(f):
        return zoa.absolute_limit_m(coupled(dyn, config, a.field_for_frequency(f).field_t, around_hz), config.cut)

    grid = np.linspace(lo, hi, 25)
    values = [limit(f) for f in grid]
    i = int(np.argmax(values))
    a_, b_ = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    best = minimize_scalar(lambda f: -limit(f), bounds=(a_, b_), method="bounded", options={"xatol": 1e-3})
    return float(best.x) if -best.fun > values[i] else float(grid[i])


def absorber_setting(dyn: ToolTipDynamics, config: ScheduleConfig, chatter_hz: float) -> tuple[float, FieldSetting, float, bool]:
    """(target Hz, FieldSetting, coil current A or NaN, feasible): the policy's target, the
    field that tunes the absorber to it (clamped to its range) and whether the coil can give it."""
    if config.policy == "match":
        target = chatter_hz
    elif config.policy == "sims":
        target = sims_target_hz(dyn, config, chatter_hz)
    else:
        target = depth_target_hz(dyn, config, chatter_hz)
    return (target, *coil_setting(target, config))


#: The `depth` policy's first grid: targets from 0.7 to 1.3 times the chatter frequency.
DEPTH_GRID = 13


def coupled_depth_m(dyn: ToolTipDynamics, config: ScheduleConfig, targets_hz, fields_t=None, response_hz: float | None = None) -> np.ndarray:
    """Critical depth (m) at the config's cut and speed with the absorber at each frequency: by
    default tuned there by its field (and the damping that field gives); with `fields_t`, at that
    frequency with that field's damping (a trajectory's absorber, its temperature in the
    frequency); the damping as a dashpot at `response_hz` (`absorber_zeta`). The converged
    engine, or `steps`."""
    targets = np.atleast_1d(np.asarray(targets_hz, dtype=float))
    return absorber_depths_m([dyn] * len(targets), config, targets, fields_t, response_hz)


def absorber_depths_m(dyns: list[ToolTipDynamics], config: ScheduleConfig, targets_hz, fields_t=None, response_hz=None) -> np.ndarray:
    """`coupled_depth_m` with one host per target (a trajectory's points at several poses), all
    solved in one batch; `response_hz` one value or one per host."""
    a = config.absorber
    targets = np.atleast_1d(np.asarray(targets_hz, dtype=float))
    response = [None] * len(targets) if response_hz is None else np.broadcast_to(np.asarray(response_hz, dtype=float), targets.shape).tolist()
    if fields_t is None:
        structures = [coupled(d, config, a.field_for_frequency(float(f), clamp=True).field_t, r) for d, f, r in zip(dyns, targets, response)]
    else:
        structures = [with_absorber(d, a.mass_kg, a.mass_kg * (2 * math.pi * f) ** 2, absorber_zeta(config, float(b), float(f), r), config.directions)
                      for d, f, b, r in zip(dyns, targets, fields_t, response)]
    return np.array([r.depth_m for r in critical_points(structures, config.cut, config.rpm, config.steps, frequencies=False)])


def depth_target_hz(dyn: ToolTipDynamics, config: ScheduleConfig, around_hz: float) -> float:
    """The absorber frequency that maximises the critical depth (module docstring, `depth`)."""
    lo, hi = config.absorber.range_hz
    lo, hi = max(lo, 0.7 * around_hz), min(hi, 1.3 * around_hz)
    if hi <= lo:
        return float(np.clip(around_hz, *config.absorber.range_hz))
    grid = np.linspace(lo, hi, DEPTH_GRID)
    values = coupled_depth_m(dyn, config, grid, response_hz=around_hz)
    values = np.where(np.isfinite(values), values, -np.inf)
    i = int(np.argmax(values))
    a_, b_ = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    best = minimize_scalar(lambda f: -coupled_depth_m(dyn, config, [f], response_hz=around_hz)[0], bounds=(a_, b_), method="bounded", options={"xatol": 1e-3 * around_hz, "maxiter": 12})
    return float(best.x) if -best.fun > values[i] else float(grid[i])


def depth_weight(dyn: ToolTipDynamics, config: ScheduleConfig, target_hz: float, rel_step: float = 0.03, response_hz: float | None = None) -> float:
    """How much critical depth a mistuned absorber costs at a depth-optimal target: the relative
    curvature -(a(f (1 + d)) + a(f (1 - d)) - 2 a(f)) / (d^2 a(f)), so that a relative mistuning
    m loses about weight m^2 / 2 of the depth (0 where the depth does not fall either side)."""
    a = coupled_depth_m(dyn, config, [target_hz * (1 - rel_step), target_hz, target_hz * (1 + rel_step)], response_hz=response_hz)
    if not np.all(np.isfinite(a)) or a[1] <= 0:
        return 0.0
    return float(max(0.0, -(a[0] + a[2] - 2 * a[1]) / (rel_step**2 * a[1])))


def coil_setting(target_hz: float, config: ScheduleConfig) -> tuple[FieldSetting, float, bool]:
    """(FieldSetting, coil current A or NaN, feasible) that tune the absorber to a target."""
    setting = config.absorber.field_for_frequency(target_hz, clamp=True)
    try:
        current = config.coil.current_for_field(setting.field_t)
        return setting, current, bool(setting.feasible and current <= config.coil.max_current_a)
    except InputError:
        return setting, float("nan"), False


def schedule_poses(poses: list[PoseModes], config: ScheduleConfig) -> list[PoseSchedule]:
    """The chain for every pose (see the module docstring). The stability engine continues
    between poses with similar modes (`critical_points(continuation=True)`: the same verified
    answers as pose by pose, at about half the cost)."""
    if not poses:
        return []
    bare = critical_points([p.dyn for p in poses], config.cut, config.rpm, config.steps, continuation=True)
    entries, structures = [], []
    for pose, result in zip(poses, bare):
        depth, chatter_hz = result.depth_m, result.chatter_hz
        if not math.isfinite(chatter_hz):
            chatter_hz = float(pose.dyn.fn_hz[np.argmin(pose.dyn.fn_hz)])
        target, setting, current, feasible = absorber_setting(pose.dyn, config, chatter_hz)
        fn_std = pose.lowest_xy[5]
        spread = 2.0 * fn_std * target / max(chatter_hz, 1e-12)
        interval = (
            config.absorber.field_for_frequency(max(target - spread, 1e-6), clamp=True).field_t,
            config.absorber.field_for_frequency(target + spread, clamp=True).field_t,
        )
        entries.append((depth, chatter_hz, AbsorberEntry(config.policy, target, setting.field_t, current, feasible, interval)))
        structures.append(coupled(pose.dyn, config, setting.field_t, chatter_hz))
    with_absorber = critical_points(structures, config.cut, config.rpm, config.steps, frequencies=False, continuation=True)
    robust = robust_entries(poses, [e[1] for e in entries], [e[2] for e in entries], bare, with_absorber, config) if config.robust_samples else [None] * len(poses)
    out = []
    for pose, (depth, chatter_hz, absorber), structure, result, result_with, guaranteed in zip(poses, entries, structures, bare, with_absorber, robust):
        out.append(PoseSchedule(
            pose=pose,
            critical_depth_m=depth,
            dominant_chatter_hz=chatter_hz,
            absorber=absorber,
            critical_depth_with_absorber_m=result_with.depth_m,
            stability=result,
            stability_with_absorber=result_with,
            absolute_limit_m=absolute_limit(pose.dyn, config.cut, depth).depth_m if config.absolute_limits else math.nan,
            absolute_limit_with_absorber_m=absolute_limit(structure, config.cut, result_with.depth_m).depth_m if config.absolute_limits else math.nan,
            controller=controller_entry(pose.pose_id, pose.rows, pose.rotation, config.control),
            robust=guaranteed,
        ))
    return out


#: Absorber targets tried by the robust search: this many across the band target x exp(+-2.5 s)
#: (s: the ln-std of the chatter mode's frequency); below s = 0.1 % the pose is taken as certain.
ROBUST_CANDIDATES = 9
CERTAIN_REL_STD = 1e-3


def lower95(depths_m: np.ndarray) -> tuple[float, float]:
    """(mean - 1.96 std floored at 0, std / mean) of sampled depths (seed 002's 95 % interval);
    inf if every sample never chatters, NaN if fewer than half have a finite depth."""
    depths_m = np.asarray(depths_m, dtype=float)
    finite = depths_m[np.isfinite(depths_m)]
    if np.all(np.isposinf(depths_m)):
        return math.inf, 0.0
    if len(finite) < max(2, len(depths_m) / 2):
        return math.nan, math.nan
    mean, std = float(finite.mean()), float(finite.std(ddof=1))
    return max(mean - Z95 * std, 0.0), std / mean


def robust_entries(poses: list[PoseModes], chatter_hz: list[float], nominal: list[AbsorberEntry], bare: list[StabilityResult],
                   with_absorber: list[StabilityResult], config: ScheduleConfig) -> list[RobustEntry | None]:
    """The guaranteed depth of every pose with a distribution (None for the others), given the
    chain's nominal entries and verified results.

    n = config.robust_samples Latin-hypercube samples of the pose's modes, the same for every
    setting (common random numbers), each through the converged engine (`_sample_depths`): bare,
    and with the absorber at the nominal field. The robust target is screened with the
    zeroth-order depth at the speed (cheap; `zoa.depth_at_speed` on the absorber band) over
    ROBUST_CANDIDATES targets across the chatter mode's uncertainty, on a second set of samples;
    the best candidate is then judged by the engine on the first set and kept only if it
    guarantees more than the nominal setting there."""
    n, seed = config.robust_samples, config.robust_seed
    todo = [i for i, p in enumerate(poses) if p.distribution is not None]
    samples = {i: poses[i].distribution.sample_dynamics(n, seed) for i in todo}
    bare_check = _needs_verification([poses[i].dyn for i in todo], [bare[i] for i in todo], config)
    coupled_check = _needs_verification([coupled(poses[i].dyn, config, nominal[i].field_t, chatter_hz[i]) for i in todo], [with_absorber[i] for i in todo], config)
    bare_depths = _sample_depths([samples[i] for i in todo], bare_check, config)
    nominal_coupled = _sample_depths([[coupled(d, config, nominal[i].field_t, chatter_hz[i]) for d in samples[i]] for i in todo], coupled_check, config)
    # screened on other samples than those it is judged on: the choice is not fitted to its judges
    candidates = {i: _robust_candidate(poses[i], poses[i].distribution.sample_dynamics(n, seed + 1), chatter_hz[i], nominal[i], config) for i in todo}
    judged = [k for k, i in enumerate(todo) if candidates[i] is not None]
    robust_coupled = _sample_depths([[coupled(d, config, candidates[todo[k]].field_t, chatter_hz[todo[k]]) for d in samples[todo[k]]] for k in judged], coupled_check[judged], config)
    out: list[RobustEntry | None] = [None] * len(poses)
    for k, i in enumerate(todo):
        depth_p95, cv = lower95(bare_depths[0][k])
        nominal_p95, _ = lower95(nominal_coupled[0][k])
        ok = bool(bare_depths[1][k].all() and nominal_coupled[1][k].all())
        tuning, entry, best = "nominal", nominal[i], nominal_p95
        if k in judged:
            j = judged.index(k)
            robust_p95, _ = lower95(robust_coupled[0][j])
            if robust_p95 > nominal_p95:
                tuning, entry, best, ok = "robust", candidates[i], robust_p95, ok and bool(robust_coupled[1][j].all())
        out[i] = RobustEntry(n, depth_p95, cv, tuning, entry, best, nominal_p95, ok, _robust_controller(poses[i], n, seed, config))
    return out


#: Samples are solved without the engine's verification (2x its cost bare, 13x with the absorber
#: coupled) where the pose's nominal structure, solved so, gives its verified depth within the
#: engine's accuracy (the same branch: a missed one lies further off).
VERIFY_AGREEMENT = REL_TOL


def _needs_verification(structures: list[ToolTipDynamics], verified: list[StabilityResult], config: ScheduleConfig) -> np.ndarray:
    """Per structure: whether its samples need the verified engine. Without the verification the
    engine finds the boundary from its seeds only, which can miss the lowest lobe; where the
    nominal structure's verified answer came from beyond the seeds, its samples' will too."""
    if config.steps is not None or not structures:
        return np.zeros(len(structures), bool)
    quick = critical_points(structures, config.cut, config.rpm, frequencies=False, verify=False)
    return np.array([not (q.converged and v.converged and math.isfinite(q.depth_m) and abs(q.depth_m / v.depth_m - 1.0) <= VERIFY_AGREEMENT)
                     if math.isfinite(v.depth_m) else not math.isinf(q.depth_m) for q, v in zip(quick, verified)])


def _sample_depths(groups: list[list[ToolTipDynamics]], verify: np.ndarray, config: ScheduleConfig) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """(critical depths m, converged flags) of each group of sampled structures, verified where
    `verify` says, and any unverified sample that did not converge re-solved verified."""
    flat = [(g, s) for g, group in enumerate(groups) for s in range(len(group))]
    results: list[StabilityResult | None] = [None] * len(flat)
    for check in (False, True):
        idx = [q for q, (g, _) in enumerate(flat) if (check or not verify[g]) and (results[q] is None or results[q].converged is False)]
        if idx:
            solved = critical_points([groups[flat[q][0]][flat[q][1]] for q in idx], config.cut, config.rpm, config.steps, frequencies=False, verify=check,
                                     continuation=check)
            for q, r in zip(idx, solved):
                results[q] = r
    depths = [np.array([results[q].depth_m for q, (g, _) in enumerate(flat) if g == k]) for k in range(len(groups))]
    converged = [np.array([results[q].converged is not False for q, (g, _) in enumerate(flat) if g == k]) for k in range(len(groups))]
    return depths, converged


def _robust_controller(pose: PoseModes, n: int, seed: int, config: ScheduleConfig) -> dict | None:
    """The robust DVF gain over the same samples as the depths (None where the pose has no
    controller entry)."""
    nominal = controller_entry(pose.pose_id, pose.rows, pose.rotation, config.control)
    if nominal is None:
        return None
    table = pose.distribution.table
    sampled = [list(zip(table.direction, table.mode, *values.T)) for values in pose.distribution.sample_values(n, seed)]
    return robust_gain(sampled, pose.rotation, config.control, nominal["dvf_gain_ns_per_m"])


def _robust_candidate(pose: PoseModes, samples: list[ToolTipDynamics], chatter_hz: float, nominal: AbsorberEntry, config: ScheduleConfig) -> AbsorberEntry | None:
    """The absorber setting whose zeroth-order 95 % lower bound over the samples is largest,
    among targets across the chatter mode's uncertainty; None where the nominal one is best or
    the mode's frequency is certain."""
    dist = pose.distribution
    fn = dist.table.fn_hz
    row = int(np.argmin(np.abs(np.log(fn / chatter_hz))))
    s = float(dist.log_std[row, 0])
    if s < CERTAIN_REL_STD:
        return None
    lo, hi = config.absorber.range_hz
    targets = np.unique(np.clip(nominal.target_hz * np.exp(np.linspace(-2.5 * s, 2.5 * s, ROBUST_CANDIDATES)), lo, hi))
    band = np.geomspace(0.5 * min(targets.min(), chatter_hz), 2.0 * max(targets.max(), chatter_hz), 800) * 2.0 * math.pi

    def guaranteed(target: float) -> float:
        field_t = config.absorber.field_for_frequency(target, clamp=True).field_t
        depths = [zoa.depth_at_speed(zoa.branches(coupled(d, config, field_t, chatter_hz), config.cut, band), config.cut.teeth, config.rpm) for d in samples]
        return lower95(np.array(depths, dtype=float))[0]

    base = guaranteed(nominal.target_hz)
    scores = [guaranteed(t) for t in targets]
    best = int(np.nanargmax(scores)) if np.isfinite(scores).any() else None
    if best is None or not scores[best] > base * 1.001:
        return None
    target = float(targets[best])
    setting, current, feasible = coil_setting(target, config)
    lo, hi = nominal.field_t_interval  # the target's +-2 std, widened to hold the robust field
    return AbsorberEntry("robust", target, setting.field_t, current, feasible, (min(lo, setting.field_t), max(hi, setting.field_t)))


def schedule_entries(table: ModalTable, config: ScheduleConfig, distributions: list[ModalDistribution] | None = None) -> list[dict]:
    """The `posedyn schedule` entry (JSON-ready) of every pose of a modal table; with robust
    samples, the poses' distributions are the given ones (a pose model's) or the table's std
    columns'."""
    if config.robust_samples and distributions is None:
        distributions = distributions_from_table(table)
    return [s.to_json() for s in schedule_poses(table_pose_modes(table, distributions), config)]
