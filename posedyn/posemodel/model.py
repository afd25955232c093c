"""Pose -> modal-parameter regression (seed 004 section 2.1, seed 003 section 4.4).

`PoseModel` follows scikit-learn's estimator contract: the constructor stores parameters,
`fit(table)` learns (attributes ending in `_`) and returns self, `predict(poses)` answers.

Targets are named `<direction><mode>.<param>` (`x1.fn_hz`, `y2.k_n_per_m`, `x1.zeta`), one per
(direction, mode) present at every training pose and per parameter. All three parameters are
positive and modelled as ln(value); a GP's normal prediction N(mu, s^2) in log space maps back
to the log-normal mean exp(mu + s^2 / 2) and std mean * sqrt(exp(s^2) - 1).

Methods:
- `stgp`: one GP per target (anisotropic RBF + white noise), targets standardised, seeded
  restarts of the marginal-likelihood optimisation (`posedyn.posemodel`).
- `mtgp`: intrinsic coregionalization (seed 003 eq. 28) over groups of at most `max_tasks`
  targets. Groups are formed from the data: targets are joined greedily in order of the
  absolute correlation of their standardised training values (>= `min_correlation`), never
  beyond `max_tasks` per group (seed 003 keeps m <= 3 for training time); the same mode seen
  in two directions, or fn and k of one mode, end up together when the data say they move
  together. Targets correlated with nothing stay single-task.
- `physics`: the twin (`posedyn.robot.twin`) predicts every target at every pose; its six joint
  stiffness scale factors are fitted first (least squares on ln fn and ln k of the robot
  modes), then single-task GPs learn the residual ln(measured) - ln(twin). Without the pose
  information the twin needs (a pose it cannot reach), the model falls back to `stgp` and
  says so in `physics_`.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.stats

from posedyn.errors import InputError, check_choice
from posedyn.io import format_modal_table
from posedyn.posemodel._gp import Predictor, fit_gps, loo_residuals
from posedyn.robot import direction_rows, tool_pose
from posedyn.robot.twin import modes_at, pose_inertia
from posedyn.table import DIRECTIONS, JOINT_COLUMNS, MODAL_PARAMS, ORIENTATION_COLUMNS, ModalTable, PoseSet, coupled_y_stiffness
from posedyn.uncertainty import ModalDistribution

METHODS = ("stgp", "mtgp", "physics")
PARAMS = MODAL_PARAMS
CROSS = ("k_xy_n_per_m", "k_yx_n_per_m")  # signed: learned as compliance 1 / k in linear space


def target_name(direction: str, mode: int, param: str) -> str:
    return f"{direction}{mode}.{param}"


def parse_target(name: str) -> tuple[str, int, str]:
    head, param = name.split(".")
    return head[0], int(head[1:]), param


def training_hash(table: ModalTable) -> str:
    """sha256 of the table's canonical CSV text (what the model was trained on)."""
    return hashlib.sha256(format_modal_table(table).encode("utf-8")).hexdigest()


def table_targets(table: ModalTable) -> tuple[list[str], np.ndarray]:
    """Target names and the (poses x targets) matrix of values, for the (direction, mode) pairs
    present at every pose."""
    n = len(table.poses)
    keys = None
    for p in range(n):
        rows = table.pose_index == p
        present = set(zip(table.direction[rows].tolist(), table.mode[rows].tolist()))
        keys = present if keys is None else keys & present
    keys = sorted(keys or (), key=lambda k: (DIRECTIONS.index(k[0]), k[1]))
    if not keys:
        raise InputError("at least one (direction, mode) measured at every pose", got="none in common", column="mode")
    names, columns = [], []
    lookup = {(int(table.pose_index[i]), table.direction[i], int(table.mode[i])): i for i in range(len(table))}
    for d, m in keys:
        for param in PARAMS:
            names.append(target_name(d, m, param))
            column = getattr(table, param)
            columns.append([column[lookup[(p, d, m)]] for p in range(n)])
        for param in CROSS:
            if param in table.cross:
                values = np.array([table.cross[param][lookup[(p, d, m)]] for p in range(n)])
                if np.all(np.isfinite(values)):
                    names.append(target_name(d, m, param))
                    columns.append(values)
    return names, np.array(columns).T


def to_model_space(names: list[str], Y: np.ndarray) -> np.ndarray:
    """ln(value) for the positive parameters, compliance 1 / k for the signed cross stiffnesses."""
    cross = np.array([parse_target(t)[2] in CROSS for t in names], dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(cross[None, :], 1.0 / Y, np.log(np.abs(Y)))


def _least_margin(column: str) -> float:
    """The least widening of the workspace beyond the training poses: 15 deg or 50 mm."""
    return 15.0 if column.endswith("_deg") else 50.0


def select_features(poses: PoseSet, requested: list[str] | None) -> list[str]:
    """The pose columns to learn from: as requested, or every position/orientation column that
    varies over the training poses."""
    columns = poses.numeric_columns()
    if requested:
        missing = [c for c in requested if c not in columns]
        if missing:
            raise InputError("feature columns present in the table: " + ", ".join(columns), got=missing, column="--features")
        twice = sorted({c for c in requested if requested.count(c) > 1})
        if twice:
            raise InputError("each feature once", got=twice, column="--features")
        constant = [c for c in requested if np.ptp(columns[c]) == 0]
        if constant:  # the model cannot learn from it, and the workspace would be that one value (widened)
            raise InputError("features that vary over the training poses", got=f"{constant[0]} = {columns[constant[0]][0]:g} at every pose", column="--features")
        return list(requested)
    chosen = [c for c, v in columns.items() if c not in JOINT_COLUMNS and np.ptp(v) > 0]
    if not chosen:
        raise InputError("poses that differ in position or orientation (all training poses are the same)", column="pose_id")
    return chosen


def feature_matrix(poses: PoseSet, features: list[str]) -> np.ndarray:
    columns = poses.numeric_columns()
    missing = [c for c in features if c not in columns]
    if missing:
        raise InputError("the model's feature columns in the poses", got=missing, column=missing[0])
    return np.column_stack([columns[c] for c in features])


def group_targets(Z: np.ndarray, max_tasks: int, min_correlation: float) -> list[list[int]]:
    """Greedy correlation clustering of target columns into groups of <= max_tasks."""
    T = Z.shape[1]
    with np.errstate(invalid="ignore", divide="ignore"):
        C = np.corrcoef(Z, rowvar=False) if T > 1 else np.ones((1, 1))
    C = np.nan_to_num(np.atleast_2d(C))
    group = list(range(T))
    members = {t: [t] for t in range(T)}
    pairs = sorted(((abs(C[a, b]), a, b) for a in range(T) for b in range(a + 1, T)), reverse=True)
    for strength, a, b in pairs:
        if strength < min_correlation:
            break
        ga, gb = group[a], group[b]
        if ga == gb or len(members[ga]) + len(members[gb]) > max_tasks:
            continue
        if min(abs(C[i, j]) for i in members[ga] for j in members[gb]) < min_correlation:
            continue
        members[ga] += members.pop(gb)
        for t in members[ga]:
            group[t] = ga
    return [sorted(m) for _, m in sorted(members.items())]


@dataclass(frozen=True)
class PhysicsPrior:
    """The twin used as the prior mean: its parameters (after the fitted stiffness scales) and
    the robot it runs on."""

    robot: object
    params: object
    scales: np.ndarray
    robot_modes: int
    mode_map: dict | None = None  # {"x2": twin row, ...} (`match_twin_modes`); None: mode m is row m

    def log_values(self, poses: PoseSet, targets: list[str]) -> np.ndarray:
        """ln of the twin's prediction of each target at each pose (NaN where it has none)."""
        q = pose_joints(self.robot, poses)
        return _twin_log_values(self.robot, self.params.scaled(self.scales), q, targets, self.robot_modes, mode_map=self.mode_map)


def pose_joints(robot, poses: PoseSet) -> np.ndarray:
    """Joint angles (rad) of each pose: the table's joint columns, else inverse kinematics."""
    if poses.joints_deg is not None:
        return np.radians(poses.joints_deg)
    data = robot.model.createData()
    q = []
    for i in range(len(poses)):
        try:
            q.append(robot.inverse(tool_pose(poses, i), data))
        except InputError as exc:  # which pose: the caller adds the file
            raise exc.located(row=i + 1, column=f"pose {poses.pose_id[i]}") from None
    return np.array(q)


def _twin_log_values(robot, params, q: np.ndarray, targets: list[str], robot_modes: int, inertias=None, mode_map: dict | None = None) -> np.ndarray:
    """`inertias`: the `pose_inertia` of every q with these params' masses (a fit of the joint
    stiffnesses computes them once; computed here otherwise). `mode_map`: the twin row (1-based,
    `direction_rows` order) of each table mode, "x2" -> 5 (absent: no prior); None: mode m is row m."""
    if inertias is None:
        data = robot.model.createData()
        inertias = [pose_inertia(robot, qi, params, data) for qi in q]
    out = np.full((len(q), len(targets)), np.nan)
    parsed = [parse_target(t) for t in targets]
    rows_of = [m if mode_map is None else mode_map.get(mode_key(d, m)) for d, m, _ in parsed]
    for i in range(len(q)):
        modes = modes_at(inertias[i], params)
        rows = {d: direction_rows(modes, d, robot_modes) for d in DIRECTIONS}
        for j, (d, m, param) in enumerate(parsed):
            r = rows_of[j]
            if r is not None and r <= len(rows[d]) and param in PARAMS:
                out[i, j] = np.log(rows[d][r - 1][PARAMS.index(param)])
    return out


#: Which of the twin's modes is a table mode: per direction, the one-to-one pairing of table
#: modes and twin rows (robot modes, then spindle modes) that minimises the sum of
#: |ln fn ratio| + |ln k ratio| / 2 (medians over the training poses, before the stiffness fit;
#: k ~ fn^2), kept where fn is within MODE_MATCH_FN and k within MODE_MATCH_K; other modes get
#: no prior. By number alone, a table of one robot mode and the spindle per direction had the
#: spindle (1450 Hz) paired with the twin's second robot mode (17 Hz), and predicted 1e84 N/m; by
#: frequency alone, its 17 Hz x mode (3e6 N/m) with the twin's 17 Hz mode that hardly moves the
#: tool in x (1.6e8 N/m, up to 1e38), where the 12.5 Hz one (2.5e6 N/m) is the one it sees.
MODE_MATCH_FN = 2.0
MODE_MATCH_K = 10.0


def mode_key(direction: str, mode: int) -> str:
    """A table mode as `mode_map` names it: "x2"."""
    return f"{direction}{mode}"


def match_twin_modes(measured: dict, twin: dict) -> dict:
    """{"x2": twin row (1-based), ...} for the table modes {("x", 2): (median fn, median k)} and
    the twin's rows {"x": [(median fn, median k) of row 1, 2, ...]} (see MODE_MATCH_FN)."""
    out = {}
    for d in DIRECTIONS:
        keys = sorted(m for dd, m in measured if dd == d)
        rows = np.array(twin.get(d, []), dtype=float).reshape(-1, 2)
        if not keys or not len(rows):
            continue
        table = np.array([measured[(d, m)] for m in keys], dtype=float)
        with np.errstate(all="ignore"):
            dfn = np.abs(np.log(table[:, None, 0] / rows[None, :, 0]))
            dk = np.abs(np.log(table[:, None, 1] / rows[None, :, 1]))
        cost = np.where(np.isfinite(dfn + dk), dfn + 0.5 * dk, 1e6)
        for i, r in zip(*scipy.optimize.linear_sum_assignment(cost)):
            if dfn[i, r] <= np.log(MODE_MATCH_FN) and dk[i, r] <= np.log(MODE_MATCH_K):
                out[mode_key(d, keys[i])] = int(r) + 1
    return out


class PoseModel:
    """Pose -> tool-tip modal parameters with uncertainty (see the module docstring)."""

    def __init__(
        self,
        method: str = "stgp",
        features: list[str] | None = None,
        n_restarts: int = 1,
        random_state: int = 0,
        max_tasks: int = 3,
        min_correlation: float = 0.5,
        twin=None,
        workers: int | None = None,
    ):
        self.method = method
        self.workers = workers
        self.features = features
        self.n_restarts = n_restarts
        self.random_state = random_state
        self.max_tasks = max_tasks
        self.min_correlation = min_correlation
        self.twin = twin  # (Robot, TwinParameters) for method "physics"

    def _validate(self):
        check_choice("method", self.method, METHODS)
        if self.method == "physics" and self.twin is None:
            raise InputError("a twin (robot, parameters) for the physics method", column="twin")
        if not 1 <= self.max_tasks <= 6:
            raise InputError("max_tasks between 1 and 6", got=self.max_tasks, column="max_tasks")

    def fit(self, table: ModalTable) -> "PoseModel":
        self._validate()
        poses = table.poses
        if len(poses) < 2:
            raise InputError("at least two training poses", got=len(poses), column="pose_id")
        self.features_ = select_features(poses, self.features)
        self.fixed_pose_ = {c: float(v[0]) for c, v in poses.numeric_columns().items()
                            if c not in JOINT_COLUMNS and c not in self.features_ and np.ptp(v) == 0}
        X = feature_matrix(poses, self.features_)
        self.x_mean_ = X.mean(axis=0)
        self.x_scale_ = np.where(X.std(axis=0) > 0, X.std(axis=0), 1.0)
        self.targets_, Y = table_targets(table)
        self.cross_ = np.array([parse_target(t)[2] in CROSS for t in self.targets_], dtype=bool)
        logY = to_model_space(self.targets_, Y)
        self.physics_ = None
        prior = np.zeros_like(logY)
        if self.method == "physics":
            prior, self.physics_ = self._fit_prior(poses, logY)
        residual = logY - prior
        self.y_mean_ = residual.mean(axis=0)
        spread = residual.std(axis=0)
        self.y_scale_ = np.where(spread > 0, spread, 1.0)
        Z = (residual - self.y_mean_) / self.y_scale_
        if self.method == "mtgp":
            self.groups_ = group_targets(Z, self.max_tasks, self.min_correlation)
        else:
            self.groups_ = [[t] for t in range(len(self.targets_))]
        self.X_train_ = (X - self.x_mean_) / self.x_scale_
        self.Z_train_ = Z
        self.gps_ = fit_gps(self.X_train_, [Z[:, g] for g in self.groups_], restarts=self.n_restarts, seed=self.random_state, workers=self.workers)
        self.n_poses_ = len(poses)
        self.training_hash_ = training_hash(table)
        return self

    def _fit_prior(self, poses: PoseSet, logY: np.ndarray):
        robot, params = self.twin
        count = params.robot_modes_per_direction
        try:
            q = pose_joints(robot, poses)
        except InputError as exc:
            return np.zeros_like(logY), {"used": False, "reason": str(exc)}
        data = robot.model.createData()
        inertias = [pose_inertia(robot, qi, params, data) for qi in q]  # the scales change the stiffnesses only
        mode_map = match_twin_modes(*self._median_modes(logY, robot, params, inertias, count))
        fit_cols = [j for j, t in enumerate(self.targets_) if parse_target(t)[2] in ("fn_hz", "k_n_per_m")]

        def residual(log_scale):
            twin = _twin_log_values(robot, params.scaled(np.exp(log_scale)), q, [self.targets_[j] for j in fit_cols], count, inertias, mode_map)
            r = logY[:, fit_cols] - twin
            return np.nan_to_num(r[:, np.isfinite(twin).all(axis=0)]).ravel()

        # soft L1 on the ln residuals, quadratic up to 10 %: a mode the twin orders differently, or
        # the stiffness of a mode that hardly shows in a direction, gives ln residuals of 1-3 that
        # plain least squares lets pull a weakly seen joint to its bound in hundreds of evaluations
        # (an as-built robot, 60 poses: 600 evaluations, not converged, joint 6 x 1.5 against x 0.82
        # true; soft L1: 23 evaluations, every scale nearer the truth; seed 003's campaign: the same
        # scales to 2e-3)
        result = scipy.optimize.least_squares(residual, np.zeros(6), bounds=(np.log(1 / 3), np.log(3)), diff_step=1e-4, x_scale=0.1,
                                              loss="soft_l1", f_scale=0.1)
        scales = np.exp(result.x)
        prior_model = PhysicsPrior(robot, params, scales, count, mode_map)
        prior = _twin_log_values(robot, params.scaled(scales), q, self.targets_, count, inertias, mode_map)
        has = np.isfinite(prior).all(axis=0) & ~self.cross_
        with np.errstate(invalid="ignore"):  # a target keeps the prior where it explains the data: no more spread with it than without
            has &= np.std(np.where(has, logY - prior, 0.0), axis=0) <= np.std(logY, axis=0) * (1.0 + 1e-9) + 1e-12
        prior[:, ~has] = 0.0
        self.prior_targets_ = has
        self.prior_model_ = prior_model
        modes = [mode_key(d, m) for d, m, _ in map(parse_target, self.targets_)]
        unmatched = sorted(set(modes) - set(mode_map))
        unexplained = [t for t, key, h, c in zip(self.targets_, modes, has, self.cross_) if not h and not c and key in mode_map]
        info = {"used": True, "stiffness_scales": scales.tolist(), "targets_with_prior": int(has.sum()), "fit_converged": bool(result.success),
                "mode_map": mode_map}
        if unmatched:
            info["modes_without_prior"] = unmatched
        if unexplained:  # matched, but the twin's values vary more over the poses than the data (a mode shape that turns away from the direction)
            info["targets_without_prior"] = unexplained
        return prior, info

    def _median_modes(self, logY: np.ndarray, robot, params, inertias, count: int):
        """({(d, m): the table mode's median (fn, k)}, {d: [the twin row's median (fn, k), ...]})
        over the training poses (`match_twin_modes`' input)."""
        median = {t: float(np.exp(np.median(logY[:, j]))) for j, t in enumerate(self.targets_)}
        measured = {(d, m): (median[target_name(d, m, "fn_hz")], median[target_name(d, m, "k_n_per_m")])
                    for d, m, param in map(parse_target, self.targets_) if param == "fn_hz"}
        all_modes = [modes_at(inertia, params) for inertia in inertias]
        twin = {d: np.median([[r[0::2] for r in direction_rows(modes, d, count)] for modes in all_modes], axis=0).tolist() for d in DIRECTIONS}
        return measured, twin

    def observation_noise_std(self) -> np.ndarray:
        """The fitted observation noise std of every target in model space (T,): a measurement is
        the latent value plus this (the predictive std excludes it)."""
        out = np.zeros(len(self.targets_))
        for gp, targets in zip(self.gps_, self.groups_):
            out[targets] = np.sqrt(gp.noise_variances) * self.y_scale_[targets]
        return out

    def predict_log(self, poses: PoseSet):
        """Mean and std of ln(value) for every target at every pose, (n, T) each."""
        X = (feature_matrix(poses, self.features_) - self.x_mean_) / self.x_scale_
        predictor = self.__dict__.get("_predictor")
        if predictor is None or predictor[0] is not self.gps_:  # all groups at once, built on first use
            predictor = self._predictor = (self.gps_, Predictor.of(self.gps_, self.groups_))
        mean, std = predictor[1].predict(X, return_std=True)
        mean = mean * self.y_scale_ + self.y_mean_
        std = std * self.y_scale_
        if self.physics_ and self.physics_.get("used"):
            prior = self.prior_model_.log_values(poses, self.targets_)
            mean = mean + np.where(self.prior_targets_, np.nan_to_num(prior), 0.0)
        return mean, std

    def predict_log_cov(self, poses: PoseSet):
        """Mean (n, T) and covariance (n, T, T) of ln(value) of the targets at every pose: the
        latent predictive covariance, correlated within a multi-task group (seed 003 eq. 28)."""
        mean, _ = self.predict_log(poses)
        X = (feature_matrix(poses, self.features_) - self.x_mean_) / self.x_scale_
        cov = self._predictor[1].predict_cov(X)  # built by predict_log
        return mean, cov * np.outer(self.y_scale_, self.y_scale_)[None]

    def predict_distributions(self, poses: PoseSet, table: ModalTable | None = None) -> list[ModalDistribution]:
        """The predictive distribution of every pose's modes (`posedyn.uncertainty`), rows as
        in `predict_table` (pass its result as `table` if already made); cross stiffnesses at
        their means."""
        table = self.predict_table(poses) if table is None else table
        mean, cov = self.predict_log_cov(poses)
        index = {t: j for j, t in enumerate(self.targets_)}
        out = []
        for p in range(len(poses)):
            one = table.select_poses([p])
            columns = [index[target_name(d, int(m), param)] for d, m in zip(one.direction, one.mode) for param in PARAMS]
            out.append(ModalDistribution(one, mean[p, columns].reshape(-1, 3), cov[p][np.ix_(columns, columns)]))
        return out

    def predict(self, poses: PoseSet, return_std: bool = False):
        """Mean (and std) of every target at every pose, original units, (n, T): log-normal
        moments for the positive parameters; for a cross stiffness k = 1 / c with c normal,
        1 / mu and s / mu^2 (first order)."""
        return self._original_units(*self.predict_log(poses), return_std)

    def _original_units(self, mu: np.ndarray, s: np.ndarray, return_std: bool = False):
        """`predict` from `predict_log`'s mean and std in model space."""
        cross = getattr(self, "cross_", np.zeros(len(self.targets_), dtype=bool))
        mean = np.where(cross, 1.0 / np.where(mu != 0, mu, np.inf), np.exp(mu + 0.5 * s**2))
        if not return_std:
            return mean
        std = np.where(cross, s / np.where(mu != 0, mu, np.inf) ** 2, mean * np.sqrt(np.expm1(s**2)))
        return mean, std

    def workspace_bounds(self) -> dict[str, tuple[float, float]]:
        """{pose column: (lo, hi)}: the training range of each pose feature widened by a quarter
        of it, at least 50 mm or 15 deg, and 50 mm or 15 deg either side of a column the training
        poses all share (`fixed_pose_`: not a feature, so the model cannot see it change: trained
        at y = 0, a pose at y = 300 mm got the y = 0 prediction with its tight std). Beyond, a
        Gaussian process returns its prior (the service refuses such poses, `posedyn schedule`
        warns)."""
        X = self.X_train_ * self.x_scale_ + self.x_mean_
        lo, hi = X.min(axis=0), X.max(axis=0)
        margin = np.maximum(0.25 * (hi - lo), np.array([_least_margin(f) for f in self.features_]))
        bounds = {f: (float(a - m), float(b + m)) for f, a, b, m in zip(self.features_, lo, hi, margin)}
        bounds.update({c: (v - _least_margin(c), v + _least_margin(c)) for c, v in self.fixed_pose_.items()})
        return bounds

    def outside_workspace(self, poses: PoseSet) -> list[str]:
        """One line per pose feature outside `workspace_bounds` ('pose P: x_mm = 1000 outside
        [1050, 1950]'), and per pose given in another orientation convention than the training
        poses (a/b/c_deg to a model of beta_deg poses: it had been answered as beta = 0)."""
        bounds, columns = self.workspace_bounds(), poses.numeric_columns()
        out = [f"pose {poses.pose_id[i]}: {f} = {float(columns[f][i]):g} outside [{lo:g}, {hi:g}]"
               for i in range(len(poses)) for f, (lo, hi) in bounds.items() if f in columns and not lo <= float(columns[f][i]) <= hi]
        known = [c for c in sum(ORIENTATION_COLUMNS.values(), ()) if c in bounds]  # (none: a model saved before fixed_pose, its orientation constant)
        foreign = [c for c in ORIENTATION_COLUMNS[poses.orientation] if c not in bounds]
        if known and foreign:
            out += [f"pose {poses.pose_id[i]}: {foreign[0]} given, the model knows the orientation as {', '.join(known)}" for i in range(len(poses))]
        return out

    def predict_table(self, poses: PoseSet) -> ModalTable:
        """Predictions as a modal table (std_* columns hold the predictive std)."""
        mean, std = self.predict(poses, return_std=True)
        keys = []
        for t in self.targets_:
            d, m, _ = parse_target(t)
            if (d, m) not in keys:
                keys.append((d, m))
        rows = {k: [] for k in ("pose_index", "direction", "mode", "fn_hz", "zeta", "k_n_per_m")}
        stds = {"std_fn_hz": [], "std_zeta": [], "std_k_n_per_m": []}
        index = {t: j for j, t in enumerate(self.targets_)}
        cross_names = [c for c in CROSS if any(t.endswith("." + c) for t in self.targets_)]
        cross = {c: [] for c in cross_names}
        for p in range(len(poses)):
            for d, m in keys:
                rows["pose_index"].append(p)
                rows["direction"].append(d)
                rows["mode"].append(m)
                for param in PARAMS:
                    j = index[target_name(d, m, param)]
                    value = mean[p, j]
                    if param == "zeta":
                        value = min(value, 0.999)
                    rows[param].append(value)
                    stds["std_" + param].append(std[p, j])
                for c in cross_names:
                    j = index.get(target_name(d, m, c))
                    cross[c].append(mean[p, j] if j is not None else np.nan)
        _one_mode_per_coupled_pair(rows, cross)
        return ModalTable(poses=poses, std=stds, source=("predicted by posedyn " + self.method,) * len(rows["fn_hz"]), cross=cross, **rows)


def _one_mode_per_coupled_pair(rows: dict, cross: dict) -> None:
    """In place: the two rows of a predicted coupled mode (k_xy on the x row, k_yx on the y row)
    made one rank-one mode, as `ToolTipDynamics.from_table` reads it and the table parser checks:
    fn and zeta their means, the y row's stiffness k_xy k_yx / k_xx (predicted independently, it
    drifted 2.5x from that away from the training poses). Cross terms predicted with opposite
    signs have no such mode (k_yy would be negative): those rows stay as predicted, and the table
    parser refuses them, naming the row."""
    if not {"k_xy_n_per_m", "k_yx_n_per_m"} <= set(cross):
        return
    at = {(p, d, m): i for i, (p, d, m) in enumerate(zip(rows["pose_index"], rows["direction"], rows["mode"]))}
    for (p, d, m), i in at.items():
        j = at.get((p, "y", m))
        if d != "x" or j is None or not (np.isfinite(cross["k_xy_n_per_m"][i]) and np.isfinite(cross["k_yx_n_per_m"][j])):
            continue
        for param in ("fn_hz", "zeta"):
            rows[param][i] = rows[param][j] = 0.5 * (rows[param][i] + rows[param][j])
        rank_one = coupled_y_stiffness(rows["k_n_per_m"][i], cross["k_xy_n_per_m"][i], cross["k_yx_n_per_m"][j])
        if rank_one > 0:
            rows["k_n_per_m"][j] = rank_one


def r2_score(predicted: np.ndarray, actual: np.ndarray) -> float:
    """Coefficient of determination (seed 003 eq. 31); NaN where the values do not vary (a
    spread of rounding, relative 1e-10, counts as none: a constant zeta column whose copies
    differed in the last bit gave a pooled R2 of -7e16)."""
    ss = np.sum((actual - actual.mean()) ** 2)
    if not ss > 1e-20 * len(actual) * np.mean(actual**2):
        return float("nan")
    return float(1.0 - np.sum((predicted - actual) ** 2) / ss)


def check_folds(folds: int, n_poses: int) -> None:
    """The k of a k-fold cross-validation over n_poses poses: 2 <= k <= n_poses."""
    if not 2 <= folds <= n_poses:
        raise InputError(f"between 2 and {n_poses} folds", got=folds, column="--cv")


def cross_validate(make_model, table: ModalTable, folds: int = 5, seed: int = 0) -> dict:
    """k-fold cross-validation over poses (seed 003 section 5.2): per target the mean and
    sample standard deviation of R^2 over the folds, the R^2 of all held-out predictions pooled,
    the RMSE over all held-out poses and how honest the predictive distribution of a measurement
    was there (`z_rms`: the rms of the held-out errors in its stds, latent std and the fitted
    observation noise together, in model space; 1 is honest). R^2 is undefined on a fold of fewer than two poses (or
    whose values do not vary): the mean and std then cover the folds where it is defined, are
    None where fewer than one (mean) or two (std) folds have it, and `note` says so."""
    n = len(table.poses)
    check_folds(folds, n)
    order = np.random.default_rng(seed).permutation(n)
    parts = np.array_split(order, folds)
    names, Y = table_targets(table)
    predicted = np.full_like(Y, np.nan)
    spread = np.full_like(Y, np.nan)
    r2 = []
    for test in parts:
        train = np.setdiff1d(order, test)
        model = make_model().fit(table.select_poses(train))
        index = [model.targets_.index(t) for t in names]
        mean_m, std_m = model.predict_log(table.select_poses(test).poses)  # in model space (logs; compliances for cross terms), where the noise is
        out = model._original_units(mean_m, std_m)[:, index]
        predicted[test] = out
        total = np.hypot(std_m, model.observation_noise_std())[:, index]
        with np.errstate(divide="ignore", invalid="ignore"):
            spread[test] = (to_model_space(names, Y[test]) - mean_m[:, index]) / total
        r2.append([r2_score(out[:, j], Y[test, j]) if len(test) >= 2 else float("nan") for j in range(len(names))])
    r2 = np.array(r2)
    result = {}
    for j, name in enumerate(names):
        defined = r2[:, j][np.isfinite(r2[:, j])]
        pooled = r2_score(predicted[:, j], Y[:, j])
        entry = {
            "r2_mean": float(defined.mean()) if len(defined) else None,
            "r2_std": float(defined.std(ddof=1)) if len(defined) >= 2 else None,
            "r2_pooled": pooled if np.isfinite(pooled) else None,
            "rmse": float(np.sqrt(np.mean((predicted[:, j] - Y[:, j]) ** 2))),
            "z_rms": float(np.sqrt(np.mean(spread[:, j] ** 2))) if np.all(np.isfinite(spread[:, j])) else None,
        }
        if len(defined) < folds:
            entry["note"] = (f"R2 is undefined on {folds - len(defined)} of {folds} folds (fewer than two poses, or values that do not vary): "
                             f"r2_mean and r2_std cover the other {len(defined)}; r2_pooled is over all held-out poses")
        result[name] = entry
    return result


#: `suspect_measurements` flags at this familywise rate: in Gaussian data without a bad
#: measurement, a 1 % chance that a campaign shows any flag at all.
SUSPECT_FAMILYWISE = 0.01


def suspect_measurements(model: PoseModel, table: ModalTable, familywise: float = SUSPECT_FAMILYWISE) -> list[dict]:
    """Training measurements far from what the model says from the other poses: the
    leave-one-pose-out residual of every target (`loo_residuals`, at the fitted hyperparameters,
    in model space, the fitted noise included) beyond the Bonferroni threshold
    z* = Phi^-1(1 - familywise / (2 N)) over all N = poses x targets values (4.6 stds for 112
    poses and 24 targets, 3.7 for 7 and 6). A mode misidentified at one pose (fn 30 % low among
    112 poses: -9 stds) shows there; so does a stiffness in a direction the mode hardly moves
    (heavy-tailed, not wrong). `table`: the one the model was fitted on. Largest |z| first: [{pose_id, target,
    measured, loo_predicted (original units), z}, ...]."""
    if training_hash(table) != model.training_hash_:
        raise ValueError("the table the model was fitted on (its training_data_hash differs)")
    names, Y = table_targets(table)
    if names != model.targets_:
        raise ValueError("the table the model was fitted on (other targets)")
    z = np.empty_like(Y)
    residual = np.empty_like(Y)
    for gp, targets in zip(model.gps_, model.groups_):
        r, s = loo_residuals(gp)
        z[:, targets], residual[:, targets] = r / s, r * model.y_scale_[targets]
    threshold = float(scipy.stats.norm.isf(familywise / (2 * z.size)))
    measured = to_model_space(names, Y)
    predicted = model._original_units(measured - residual, np.zeros_like(residual))
    flagged = np.argwhere(np.abs(z) > threshold)
    out = [{"pose_id": table.poses.pose_id[i], "target": names[j], "measured": float(Y[i, j]), "loo_predicted": float(predicted[i, j]),
            "z": float(z[i, j])} for i, j in flagged]
    return sorted(out, key=lambda d: -abs(d["z"]))
