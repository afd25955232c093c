"""Candidates that act through the robot twin (issue 18): the twin is changed and its modes are
recomputed at every campaign pose, so a candidate moves fn and the modal stiffness together as
the physics does (M(q) += m J_p^T J_p, K_theta phi = w^2 M phi, k_rd = w_r^2 / u_rd^2; seed 003
eqs. 15-17, seed 000 Fig. 2). Candidates that act through the twin combine into one changed twin
(`CandidateEffect.combine`), not into a product of factors.

- `flange_device`: a device's mass on the flange in the `device` = 1 rows.
- `joint_stiffness_a1` .. `a6`, `gravity_softening` (k_j / (1 + c |tau_g,j(q)|)): they follow
  the pose with no condition column, so `posedyn.gap.analysis` selects them first on the fn
  rows (continuous in the stiffness, where the modal stiffness of a mode numbered by frequency
  rank jumps as modes cross) and refines them on every row from a coordinate search.
- `sensor_mass`: the impact test's sensor at the tool tip on every row (measurement chain: it
  explains the measured modes; the machining twin does not get it, `MEASUREMENT_CHAIN`).

Two changed twins that explain a campaign alike are told apart by the pose and mode where their
fn differ most (`separate`). A row's correction is the ratio of the changed twin's value to the
nominal twin's for the row's (direction, mode) as modal tables number them
(`posedyn.robot.direction_rows`), applied to the baseline, so the candidates also correct a
trained model's predictions. Rows carry their pose's joint angles as the context columns
`model_q1_rad` .. `model_q6_rad` (the gap baseline adds them).
"""

from __future__ import annotations

import copy
import itertools
import math
from dataclasses import replace

import numpy as np

from posedyn.errors import InputError
from posedyn.gap.analysis import CandidateEffect, Measurements, Parameter
from posedyn.robot import Robot, ToolPose, TwinParameters, direction_rows
from posedyn.robot.twin import modes_at, pose_inertia, twin_modes

MODEL_JOINT_COLUMNS = tuple(f"model_q{j}_rad" for j in range(1, 7))
#: The candidates that act through the twin.
TWIN_EFFECTS = tuple(f"joint_stiffness_a{j}" for j in range(1, 7)) + ("flange_device", "gravity_softening", "sensor_mass")
#: Twin effects of the measurement chain: they explain the measured modes, but the robot that
#: machines does not carry them (not written into an updated twin or model).
MEASUREMENT_CHAIN = ("sensor_mass",)


def twin_changes(values: dict) -> tuple[np.ndarray, float, float, float]:
    """(joint stiffness factors (6,), flange mass kg, added gravity softening per kN m, tool-tip
    mass kg) of named twin candidates {name: parameter}."""
    scale, flange_kg, softening, tip_kg = np.ones(6), 0.0, 0.0, 0.0
    for name, value in values.items():
        if name == "flange_device":
            flange_kg = float(value)
        elif name == "gravity_softening":
            softening = float(value)
        elif name == "sensor_mass":
            tip_kg = float(value)
        else:
            scale[int(name.removeprefix("joint_stiffness_a")) - 1] = 2.0 ** float(value)
    return scale, flange_kg, softening, tip_kg


def updated_twin(params: TwinParameters, values: dict) -> TwinParameters:
    """The twin with named twin candidates applied (the flange mass as mounted in the device rows,
    the sensor's mass as in the impact tests)."""
    return changed_twin(params, *twin_changes(values))


def changed_twin(params: TwinParameters, scale, flange_kg: float, softening: float, tip_kg: float) -> TwinParameters:
    """`params` with the joint stiffnesses scaled and the flange mass, gravity softening and
    tool-tip mass added (`twin_changes`)."""
    return replace(params.scaled(np.asarray(scale)), flange_mass_kg=params.flange_mass_kg + flange_kg,
                   gravity_softening_per_knm=params.gravity_softening_per_knm + softening, tip_mass_kg=params.tip_mass_kg + tip_kg)


def updated_pose_model(model, values: dict, note: str):
    """A copy of a fitted physics pose model whose prior twin carries the named twin candidates
    (`updated_twin` on the prior's parameters; the fitted stiffness scales and the learned
    residual GPs unchanged), so its ln predictions of fn and k move by exactly ln(changed twin /
    nominal twin), as the candidates corrected the model's predictions; `note` is kept in its
    physics record (`gap_effects`)."""
    prior = model.prior_model_
    params = updated_twin(prior.params, values)
    out = copy.copy(model)
    out.prior_model_ = replace(prior, params=params)
    out.twin = (prior.robot, params)
    out.physics_ = dict(model.physics_, gap_effects=list(model.physics_.get("gap_effects", [])) + [note])
    return out


def twin_candidates(robot: Robot, params: TwinParameters) -> dict[str, CandidateEffect]:
    """`joint_stiffness_a1` .. `a6` (log2 of a joint's stiffness factor, -2..2; pose-following,
    selected on the fn rows first) and `flange_device` (a device's mass on the flange where
    `device` = 1, at the twin's flange offset, kg 0-200)."""
    cache: dict = {}
    inertia: dict = {}  # pose_inertia per (q, flange mass, tip mass): a stiffness fit changes neither
    changed: dict = {}  # TwinParameters per (scale, flange mass, softening, tip mass)
    data = robot.model.createData()

    def table(q: tuple, scale: tuple, flange_kg: float, softening: float, tip_kg: float) -> dict:
        key = (q, scale, round(flange_kg, 12), round(softening, 14), round(tip_kg, 12))
        if key not in cache:
            p = changed_params(key[1:])
            masses = (q, key[2], key[4])
            if masses not in inertia:
                if len(inertia) > 20000:
                    inertia.clear()
                inertia[masses] = pose_inertia(robot, np.asarray(q), p, data)
            modes = modes_at(inertia[masses], p)
            if len(cache) > 20000:
                cache.clear()
            cache[key] = {(d, j): row for d in ("x", "y", "z") for j, row in enumerate(direction_rows(modes, d, params.robot_modes_per_direction), 1)}
        return cache[key]

    def changed_params(key: tuple) -> TwinParameters:
        """The twin's parameters with (scale, flange kg, softening, tip kg) applied; the same for
        every pose of a candidate's evaluation, so made once per evaluation, not per pose."""
        if key not in changed:
            if len(changed) > 20000:
                changed.clear()
            changed[key] = changed_twin(params, *key)
        return changed[key]

    def ratio(m: Measurements, scale, flange_kg: float, softening: float, tip_kg: float) -> np.ndarray:
        """changed / nominal twin for every fn_hz and k_n_per_m row (1 elsewhere); the twins'
        tables looked up once per distinct (pose, flange mass), not per row."""
        out = np.ones(len(m))
        q_all = np.column_stack([m.column(c) for c in MODEL_JOINT_COLUMNS])
        modal = np.flatnonzero(np.isin(m.quantity, ("fn_hz", "k_n_per_m")) & np.all(np.isfinite(q_all), axis=1))
        if not len(modal):
            return out
        flange = np.where(np.isfinite(m.column("device")), m.column("device"), 0.0)[modal] * flange_kg
        scale = tuple(float(v) for v in scale)
        column = np.where(m.quantity[modal] == "fn_hz", 0, 2)
        groups, inverse = np.unique(np.column_stack([np.round(q_all[modal], 12), flange]), axis=0, return_inverse=True)
        order = np.argsort(inverse.reshape(-1), kind="stable")
        bounds = np.searchsorted(inverse.reshape(-1)[order], np.arange(len(groups) + 1))
        keys = list(zip(m.direction[modal].astype(str).tolist(), m.mode[modal].astype(int).tolist()))
        with np.errstate(all="ignore"):
            for g, group in enumerate(groups):
                q = tuple(group[:6])
                nominal, changed = table(q, (1.0,) * 6, 0.0, 0.0, 0.0), table(q, scale, float(group[6]), softening, tip_kg)
                for k in order[bounds[g] : bounds[g + 1]].tolist():
                    if keys[k] in nominal and keys[k] in changed:
                        value = changed[keys[k]][column[k]] / nominal[keys[k]][column[k]]
                        out[modal[k]] = value if math.isfinite(value) else 1.0
        return out

    def combine(y, m, thetas: dict) -> np.ndarray:
        """Every chosen twin candidate at once: one changed twin, one ratio per row."""
        return y * ratio(m, *twin_changes({name: float(t[0]) for name, t in thetas.items()}))

    def joint(j: int) -> CandidateEffect:
        name = f"joint_stiffness_a{j + 1}"
        return CandidateEffect(
            name, f"axis {j + 1}'s joint stiffness differs from the twin's (the modes recomputed at every pose)",
            "seed 003 section 2 (joint stiffness identification); Dumas et al. 2011", ("fn_hz", "k_n_per_m"), (),
            (Parameter("log2_factor", 0.1, -2.0, 2.0),), lambda y, m, t: combine(y, m, {name: t}), combine=combine, fit_quantities=("fn_hz",),
            separate=separate)

    def separate(m: Measurements, a: dict, b: dict) -> str | None:
        """The pose (over the campaign's x, y, beta box, 5 x 5 x 5) and mode where the twin changed
        by `a` and by `b` predict the most different fn, as the measurement to take next."""
        x, y, z, beta = (m.column(c) for c in ("x_mm", "y_mm", "z_mm", "beta_deg"))
        ok = np.isfinite(x) & np.isfinite(y) & np.isfinite(z) & np.isfinite(beta)
        if not ok.any():
            return None
        params_a, params_b = updated_twin(params, a), updated_twin(params, b)
        data = robot.model.createData()
        best = None
        box = (np.linspace(v[ok].min(), v[ok].max(), 5) for v in (x, y, beta))
        for px, py, pb in itertools.product(*box):
            try:
                q = robot.inverse(ToolPose.from_beta(px * 1e-3, py * 1e-3, float(np.median(z[ok])) * 1e-3, math.radians(pb)), data)
            except InputError:
                continue
            rows_a, rows_b = (direction_fn(twin_modes(robot, q, p, data)) for p in (params_a, params_b))
            for key in rows_a.keys() & rows_b.keys():
                gap = abs(rows_a[key] / rows_b[key] - 1.0)
                if best is None or gap > best[0]:
                    best = (gap, px, py, pb, key, rows_a[key], rows_b[key])
        if best is None:
            return None
        gap, px, py, pb, (d, j), fa, fb = best
        names_a, names_b = ", ".join(f"{k} {v:.3g}" for k, v in a.items()), ", ".join(f"{k} {v:.3g}" for k, v in b.items())
        mounted = " with the device mounted" if "flange_device" in a or "flange_device" in b else ""
        return (f"measure fn of {d} mode {j}{mounted} at x {px:.0f} mm, y {py:.0f} mm, z {np.median(z[ok]):.0f} mm, beta {pb:.0f} deg: "
                f"{fa:.3f} Hz with {names_a}, {fb:.3f} Hz with {names_b} ({100 * gap:.2g} % apart)")

    def direction_fn(modes) -> dict:
        return {(d, j): row[0] for d in ("x", "y") for j, row in enumerate(direction_rows(modes, d, params.robot_modes_per_direction), 1)}

    out = {f"joint_stiffness_a{j + 1}": joint(j) for j in range(6)}
    out["sensor_mass"] = CandidateEffect(
        "sensor_mass", "the impact test's sensor at the tool tip adds its mass to every measured mode (the modes recomputed with it at every pose)",
        "modal testing practice (mass loading by the accelerometer); seed 001 section 3 (impact tests at the tool tip)", ("fn_hz", "k_n_per_m"), (),
        (Parameter("mass_kg", 0.1, 0.0, 5.0),), lambda y, m, t: combine(y, m, {"sensor_mass": t}), combine=combine,
        separate=separate, separate_by="repeat a test with a lighter sensor or a laser vibrometer")
    out["gravity_softening"] = CandidateEffect(
        "gravity_softening", "the joints soften under the gravity torque they carry (k / (1 + c |tau_g| / 1 kN m), the modes recomputed at every pose)",
        "seed 003 section 2 (load-dependent joint stiffness); Dumas et al. 2011", ("fn_hz", "k_n_per_m"), (),
        (Parameter("softening_per_knm", 0.02, -0.15, 2.0),), lambda y, m, t: combine(y, m, {"gravity_softening": t}), combine=combine,
        fit_quantities=("fn_hz",), separate=separate)
    out["flange_device"] = CandidateEffect(
        "flange_device", "a device mounted on the flange (the twin's modes recomputed with its mass: fn and modal stiffness change)",
        "seed 000 section 2 and Fig. 2 (actuator mass lowers and splits the robot modes)",
        ("fn_hz", "k_n_per_m"), ("device",), (Parameter("mass_kg", 2.0, 0.0, 200.0),), lambda y, m, t: combine(y, m, {"flange_device": t}),
        combine=combine, separate=separate)
    return out
