"""The current model's predictions for a measurement campaign (the gap workflow's baseline), and
synthetic campaigns from the twin with named effects hidden in them.

Baseline per quantity: `fn_hz` and `k_n_per_m` of a direction's mode from the twin (or a trained
model) as a modal table numbers them; `k_xy_n_per_m` zero (the modal-table model has no cross
terms); `critical_depth_mm` from the converged stability engine on the pose's x-y modes at the row's
`rpm` with the cut file; `absorber_fn_hz` and `absorber_zeta` from the MRF absorber model at the
row's `field_mt` (and `temperature_c` where the absorber file states a modulus temperature law);
`sle_um` from `posedyn.sle` on the pose's x-y modes with the row's tool and cut.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from absorber.coil_dynamics import absorber_frequency
from absorber.files import read_absorber, read_drive
from absorber.gap_candidates import absorber_candidates
from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError
from posedyn.gap import LIBRARY, Measurements, predict
from posedyn.gap.twin_candidates import MODEL_JOINT_COLUMNS, twin_candidates
from posedyn.io.cut import read_cut, read_sle_cut
from posedyn.io.model_dir import load_model
from posedyn.io.params import read_params
from posedyn.io.twin_file import load_twin
from posedyn.robot import GridPose, direction_rows, pose_modes, tool_pose
from posedyn.sle import SleCut, mean_normal_force_n, sle_m
from posedyn.stability import critical_points
from posedyn.table import JOINT_COLUMNS, ORIENTATION_COLUMNS, POSITION_COLUMNS, Mode, PoseSet


#: Noise of generated measurements: relative std per quantity (k_xy: of sqrt(k_x k_y)).
NOISE = {"fn_hz": 0.003, "k_n_per_m": 0.03, "k_xy_n_per_m": 0.02, "critical_depth_mm": 0.03, "absorber_fn_hz": 0.005, "absorber_zeta": 0.05}


class Baseline:
    """Predictions of the current model: the twin (`twin_file`) or a trained model directory."""

    def __init__(self, twin_file: Path | None = None, model_dir: Path | None = None, cut_file: Path | None = None, absorber_file: Path | None = None):
        if (twin_file is None) == (model_dir is None):
            raise InputError("either a twin file or a model directory", column="--twin")
        self.model = None
        if model_dir is not None:
            self.model = load_model(model_dir)
        else:
            self.robot, self.params = load_twin(twin_file)
        self.cut = read_cut(cut_file)[0] if cut_file is not None else None
        sle = read_sle_cut(cut_file) if cut_file is not None else None  # its offset belongs to its own cut (feed speed, tool), not to a row's
        self.helix_deg = math.degrees(sle[0].helix_rad) if sle is not None else 0.0
        self.engagement = sle[0].engagement if sle is not None else "nominal"  # (an updated cut says "geometric")
        self.absorber = read_absorber(absorber_file)
        # the fluid's modulus temperature law, where the absorber file states one ([drive], as `posedyn gap` writes it)
        self.drive = read_drive(absorber_file) if absorber_file is not None and "modulus_tempco_per_k" in read_params(absorber_file).get("drive", {}) else None

    def twin(self):
        """(Robot, TwinParameters) behind the predictions, or None (a model without a twin): the
        twin file's, or a physics model's prior twin as it uses it (its fitted stiffness scales
        applied)."""
        if self.model is None:
            return self.robot, self.params
        if not (self.model.physics_ or {}).get("used"):
            return None
        prior = self.model.prior_model_
        return prior.robot, prior.params.scaled(prior.scales)

    def surrogate_library(self) -> dict:
        """The library with the MRF temperature law through this baseline's absorber (what a
        synthetic campaign hides its effects with)."""
        return dict(LIBRARY, **absorber_candidates(self.absorber, self.drive))

    def library(self) -> dict:
        """The candidates for this baseline: the library with the MRF temperature law through the
        absorber model (`absorber.gap_candidates`), and where a twin is behind the predictions the
        candidates that act through it (`posedyn.gap.twin_candidates`), which then replace the
        surrogate `device_mass` (the twin's flange mass moves fn and k together)."""
        out = self.surrogate_library()
        twin = self.twin()
        if twin is not None:
            del out["device_mass"]
            out.update(twin_candidates(*twin))
        return out

    def joint_angles(self, m: Measurements) -> dict:
        """{pose_id: joint angles (rad)} of the campaign's poses, by the twin's inverse kinematics
        (as `pose_rows` computes the twin's modes)."""
        twin = self.twin()
        if twin is None:
            return {}
        robot = twin[0]
        first = {}
        for i, p in enumerate(m.pose_id):
            first.setdefault(p, i)
        ids = list(first)
        poses = campaign_poses(m, [first[p] for p in ids])
        data = robot.model.createData()
        return {p: robot.inverse(tool_pose(poses, k), data) for k, p in enumerate(ids)}

    def pose_rows(self, m: Measurements) -> dict:
        """{pose_id: {(direction, mode): (fn, zeta, k)}} for every pose of the campaign."""
        out = {}
        first = {}
        for i, p in enumerate(m.pose_id):
            first.setdefault(p, i)
        ids = list(first)
        poses = campaign_poses(m, [first[p] for p in ids])
        if self.model is not None:
            table = self.model.predict_table(poses)
            for p_index, p in enumerate(ids):
                rows = np.flatnonzero(table.pose_index == p_index)
                out[p] = {(str(table.direction[r]), int(table.mode[r])): (float(table.fn_hz[r]), float(table.zeta[r]), float(table.k_n_per_m[r])) for r in rows}
            return out
        data = self.robot.model.createData()
        count = self.params.robot_modes_per_direction
        for index, p in enumerate(ids):
            _, modes = pose_modes(self.robot, GridPose(p, tool_pose(poses, index)), self.params, data=data)
            out[p] = {(d, j): row for d in ("x", "y", "z") for j, row in enumerate(direction_rows(modes, d, count), 1)}
        return out

    def predict(self, m: Measurements) -> tuple[np.ndarray, Measurements]:
        """Baseline predictions for every row, and the campaign with the model's context added
        (`model_k_n_per_m` on modal rows, `model_k_x_n_per_m`/`model_k_y_n_per_m` on k_xy rows)."""
        modes = self.pose_rows(m)
        n = len(m)
        y = np.full(n, np.nan)
        model_k = np.full(n, np.nan)
        kx, ky = np.full(n, np.nan), np.full(n, np.nan)
        depth_rows, sle_rows = [], []
        for i in range(n):
            q, p = m.quantity[i], m.pose_id[i]
            if q in ("fn_hz", "k_n_per_m"):
                key = (str(m.direction[i]), int(m.mode[i]))
                if key not in modes[p]:
                    raise InputError(f"a mode the model predicts ({sorted(modes[p])[:6]})", got=key, row=i + 1, column="mode")
                fn, _, k = modes[p][key]
                y[i] = fn if q == "fn_hz" else k
                model_k[i] = k
            elif q == "k_xy_n_per_m":
                y[i] = 0.0
                kx[i], ky[i] = modes[p][("x", 1)][2], modes[p][("y", 1)][2]
            elif q in ("absorber_fn_hz", "absorber_zeta"):
                field_t = m.column("field_mt")[i] * 1e-3
                if not np.isfinite(field_t):
                    raise InputError("a field_mt for an absorber row", row=i + 1, column="field_mt")
                temperature_c = m.column("temperature_c")[i]
                if q == "absorber_zeta":
                    y[i] = self.absorber.damping_ratio(field_t)
                elif self.drive is not None and np.isfinite(temperature_c):
                    y[i] = float(absorber_frequency(self.absorber, self.drive, field_t, temperature_c))
                else:
                    y[i] = self.absorber.natural_frequency_hz(field_t)
            elif q == "critical_depth_mm":
                if not np.isfinite(m.column("rpm")[i]):
                    raise InputError("an rpm for a critical_depth_mm row", row=i + 1, column="rpm")
                depth_rows.append(i)
            elif q == "sle_um":
                sle_rows.append(i)
        if (depth_rows or sle_rows) and self.cut is None:
            raise InputError("a cut for the critical_depth_mm and sle_um rows (--cut CUT.toml, or a model directory trained with --cut)",
                             row=(depth_rows or sle_rows)[0] + 1, column="--cut")
        structures = {p: _structure(rows) for p, rows in modes.items()}
        if depth_rows:
            results = critical_points([structures[m.pose_id[i]] for i in depth_rows], self.cut, m.column("rpm")[depth_rows], frequencies=False)
            y[depth_rows] = [r.depth_m * 1e3 for r in results]
        conditions = dict(m.conditions, model_k_n_per_m=model_k, model_k_x_n_per_m=kx, model_k_y_n_per_m=ky)
        if sle_rows:
            conditions.update(self._sle(m, sle_rows, structures, y))
        joints = self.joint_angles(m)
        if joints:
            q = np.array([joints[p] for p in m.pose_id])
            conditions.update({c: q[:, j] for j, c in enumerate(MODEL_JOINT_COLUMNS)})
        return y, replace(m, conditions=conditions)

    def _sle(self, m: Measurements, rows: list[int], structures: dict, y: np.ndarray) -> dict:
        """SLE rows (`posedyn.sle.sle_m`, + = undercut; with the cut file's engagement) into y, and
        their context: the model's SLE and mean surface-normal force (model_sle_um,
        model_sle_mean_force_n) and the feed speed
        (feed_mm_per_min = feed per tooth x teeth x rpm where the campaign does not give it)."""
        n = len(m)
        model_sle, force = np.full(n, np.nan), np.full(n, np.nan)
        feed_speed = m.column("feed_mm_per_min").copy()
        for i in rows:
            cut, rpm, face = self._sle_cut(m, i)
            dyn = structures[m.pose_id[i]]
            if face == "x":  # the surface normal is x: turn the axes so that it becomes y (as `posedyn sle --direction x`)
                dyn = dyn.rotated(-math.pi / 2)
            y[i] = model_sle[i] = float(sle_m(dyn, cut, rpm)[0]) * 1e6
            force[i] = mean_normal_force_n(cut)
            if not np.isfinite(feed_speed[i]):
                feed_speed[i] = cut.feed_per_tooth_m * 1e3 * cut.teeth * rpm
        return {"model_sle_um": model_sle, "model_sle_mean_force_n": force, "feed_mm_per_min": feed_speed}

    def _sle_cut(self, m: Measurements, i: int) -> tuple[SleCut, float, str]:
        """(SleCut, rpm, surface-normal direction) of SLE row i: the row's tool and cut, with k_t,
        k_n from the row (kt_mpa, kn_mpa) or the cut file, the helix from the row (helix_deg), the
        cut file's [sle] section or 0, down milling unless up_milling = 1."""
        where = dict(row=i + 1)
        face = str(m.direction[i])
        if face not in ("x", "y"):
            raise InputError("the surface-normal direction x or y for an sle_um row", got=face, column="direction", **where)

        def value(column, default=np.nan):
            v = m.column(column)[i]
            if np.isfinite(v):
                return float(v)
            if math.isfinite(default):
                return default
            raise InputError(f"a {column} for an sle_um row", got="empty", column=column, **where)

        teeth = value("teeth")
        if teeth != round(teeth):
            raise InputError("an integer number of teeth", got=teeth, column="teeth", **where)
        up = value("up_milling", 0.0)
        if up not in (0.0, 1.0):
            raise InputError("up_milling 0 (down milling) or 1 (up milling)", got=up, column="up_milling", **where)
        try:
            cut = SleCut(
                teeth=int(teeth), kt_pa=value("kt_mpa", self.cut.kt_pa * 1e-6) * 1e6, kn_pa=value("kn_mpa", self.cut.kn_pa * 1e-6) * 1e6,
                tool_diameter_m=value("tool_diameter_mm") * 1e-3, helix_rad=math.radians(value("helix_deg", self.helix_deg)),
                radial_depth_m=value("radial_depth_mm") * 1e-3, axial_depth_m=value("axial_depth_mm") * 1e-3,
                feed_per_tooth_m=value("feed_per_tooth_mm") * 1e-3, milling="up" if up else "down", engagement=self.engagement,
            )
        except InputError as exc:
            raise exc.located(**where) from None
        return cut, value("rpm"), face


def _structure(rows: dict) -> ToolTipDynamics:
    """The tool tip's x-y structure from a pose's {(direction, mode): (fn, zeta, k)}."""
    return ToolTipDynamics.from_modes(x=[Mode(*rows[k]) for k in sorted(rows) if k[0] == "x"], y=[Mode(*rows[k]) for k in sorted(rows) if k[0] == "y"])


def campaign_poses(m: Measurements, rows: list[int]) -> PoseSet:
    """The poses of campaign rows: position and orientation (A/B/C when the campaign gives
    them for these rows, else beta) and joints when given, with the rows' pose_ids."""
    names = POSITION_COLUMNS + ORIENTATION_COLUMNS["abc"] + ORIENTATION_COLUMNS["beta"] + JOINT_COLUMNS
    columns = {c: m.conditions[c][rows] for c in names if c in m.conditions and np.all(np.isfinite(m.conditions[c][rows]))}
    try:
        return PoseSet.from_columns([m.pose_id[i] for i in rows], columns)
    except InputError as exc:
        raise exc.located(row=rows[0] + 1) from None


def generate_measurements(baseline: Baseline, hidden: dict, seed: int = 0, poses: int = 10, unknown=None) -> Measurements:
    """A campaign over random poses of the seed 003 workspace with every condition the library
    depends on varied independently, the named effects `hidden` ({name: {parameter: value}})
    applied to the baseline (the MRF temperature law through the absorber model), and Gaussian
    noise (NOISE). `unknown(m, y) -> y` hides an effect
    that is not in the library (for tests)."""
    design = campaign_design(seed, poses)
    y, with_context = baseline.predict(design)
    return hide(design, y, with_context, hidden, seed, unknown, library=baseline.surrogate_library())


def campaign_design(seed: int = 0, poses: int = 10) -> Measurements:
    """The rows of a synthetic campaign (poses, quantities, conditions; values still zero)."""
    rng = np.random.default_rng(seed)
    rows = []

    def add(pid, pose, quantity, direction="", mode=np.nan, **conditions):
        rows.append((pid, pose, quantity, direction, mode, conditions))

    for k in range(poses):
        pose = {"x_mm": rng.uniform(1300, 1900), "y_mm": rng.uniform(-300, 300), "z_mm": 600.0, "beta_deg": rng.uniform(-60, 60)}
        pid = f"p{k}"
        for _ in range(4):
            c = {"device": float(rng.integers(0, 2)), "moving": float(rng.integers(0, 2)), "fixture": float(rng.integers(0, 2)), "force_n": float(rng.choice([100.0, 400.0, 800.0]))}
            for d in ("x", "y"):
                add(pid, pose, "fn_hz", d, 1.0, **c)
                add(pid, pose, "k_n_per_m", d, 1.0, **c)
        add(pid, pose, "k_xy_n_per_m")
        for rpm in rng.choice([800.0, 1200.0, 2000.0, 4000.0, 6000.0], size=2, replace=False):
            add(pid, pose, "critical_depth_mm", rpm=float(rpm))
    first = {"x_mm": 1600.0, "y_mm": 0.0, "z_mm": 600.0, "beta_deg": 0.0}
    for _ in range(24):
        c = {"field_mt": float(rng.choice([0, 100, 200, 300, 400, 500])), "temperature_c": float(rng.uniform(15, 45)), "absorber_angle_deg": float(rng.choice([0, 45, 90]))}
        add("absorber", first, "absorber_fn_hz", **c)
        add("absorber", first, "absorber_zeta", **c)
    names = ["x_mm", "y_mm", "z_mm", "beta_deg", "rpm", "field_mt", "temperature_c", "absorber_angle_deg", "device", "moving", "fixture", "force_n"]
    conditions = {c: np.array([r[1].get(c, r[5].get(c, np.nan)) for r in rows], dtype=float) for c in names}
    return Measurements(
        quantity=np.array([r[2] for r in rows]),
        value=np.zeros(len(rows)),
        std=np.ones(len(rows)),
        pose_id=np.array([r[0] for r in rows]),
        direction=np.array([r[3] for r in rows]),
        mode=np.array([r[4] for r in rows], dtype=float),
        conditions=conditions,
    )


def hide(design: Measurements, y: np.ndarray, with_context: Measurements, hidden: dict, seed: int = 0, unknown=None, library: dict | None = None) -> Measurements:
    """Measured values: the baseline y with the hidden effects (of `library`, default the
    library's surrogates) applied, plus noise (seeded)."""
    library = LIBRARY if library is None else library
    names_hidden = tuple(hidden)
    theta = np.array([hidden[n][p.name] for n in names_hidden for p in library[n].parameters])
    truth = predict(names_hidden, theta, y, with_context, library) if names_hidden else y
    if unknown is not None:
        truth = unknown(with_context, truth)
    m = design
    relative = np.array([NOISE[q] for q in m.quantity])
    scale = np.where(m.quantity == "k_xy_n_per_m", np.sqrt(np.abs(with_context.conditions["model_k_x_n_per_m"] * with_context.conditions["model_k_y_n_per_m"])), np.abs(truth))
    std = relative * scale
    value = truth + np.random.default_rng([seed, 1]).standard_normal(len(truth)) * std
    return replace(m, value=value, std=std)
