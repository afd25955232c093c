"""Candidates that act through the robot twin (issue 18): a device on the flange is added to the
twin and the modes are recomputed at every campaign pose, so the candidate moves fn and the modal
stiffness together as the physics does (M(q) += m J_p^T J_p, K_theta phi = w^2 M phi, k_rd =
w_r^2 / u_rd^2; seed 003 eqs. 15-17, seed 000 Fig. 2). Candidates that act through the twin
combine into one changed twin (`CandidateEffect.combine`), not into a product of factors.

Not here: per-joint stiffness candidates. Tried (axis 2 30 % softer and axis 3 25 % stiffer than
the twin): with modes numbered by frequency rank per direction, as the twin's tables number them,
the fit's landscape jumps wherever two modes cross, and neither one-joint-at-a-time selection nor
a six-joint fit from a grid of starts found the truth. They need modes matched by shape (MAC)
between the twin and the campaign.

A row's correction is the ratio of the changed twin's value to the nominal twin's for the row's
(direction, mode) as modal tables number them (`posedyn.robot.direction_rows`), applied to the
baseline, so the candidates also correct a trained model's predictions. Rows carry their pose's
joint angles as the context columns `model_q1_rad` .. `model_q6_rad` (the gap baseline adds them).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from posedyn.gap.analysis import CandidateEffect, Measurements, Parameter
from posedyn.robot import Robot, TwinParameters, direction_rows
from posedyn.robot.twin import twin_modes

MODEL_JOINT_COLUMNS = tuple(f"model_q{j}_rad" for j in range(1, 7))


def twin_candidates(robot: Robot, params: TwinParameters) -> dict[str, CandidateEffect]:
    """`flange_device`: a device's mass on the flange where `device` = 1, at the twin's flange
    offset (kg, 0-200)."""
    cache: dict = {}

    def table(q: tuple, flange_kg: float) -> dict:
        key = (q, round(flange_kg, 12))
        if key not in cache:
            p = replace(params, flange_mass_kg=params.flange_mass_kg + flange_kg) if flange_kg else params
            modes = twin_modes(robot, np.asarray(q), p)
            if len(cache) > 20000:
                cache.clear()
            cache[key] = {(d, j): row for d in ("x", "y", "z") for j, row in enumerate(direction_rows(modes, d, params.robot_modes_per_direction), 1)}
        return cache[key]

    def ratio(m: Measurements, flange_kg: float) -> np.ndarray:
        """changed / nominal twin for every fn_hz and k_n_per_m row (1 elsewhere)."""
        out = np.ones(len(m))
        q_all = np.column_stack([m.column(c) for c in MODEL_JOINT_COLUMNS])
        modal = np.isin(m.quantity, ("fn_hz", "k_n_per_m")) & np.all(np.isfinite(q_all), axis=1)
        flange = np.where(np.isfinite(m.column("device")), m.column("device"), 0.0) * flange_kg
        for i in np.flatnonzero(modal):
            q = tuple(np.round(q_all[i], 12))
            key = (str(m.direction[i]), int(m.mode[i]))
            nominal, changed = table(q, 0.0), table(q, float(flange[i]))
            if key in nominal and key in changed:
                column = 0 if m.quantity[i] == "fn_hz" else 2
                with np.errstate(all="ignore"):
                    value = changed[key][column] / nominal[key][column]
                out[i] = value if math.isfinite(value) else 1.0
        return out

    def combine(y, m, thetas: dict) -> np.ndarray:
        """Every chosen twin candidate at once: one changed twin, one ratio per row."""
        return y * ratio(m, float(thetas["flange_device"][0]))

    return {"flange_device": CandidateEffect(
        "flange_device", "a device mounted on the flange (the twin's modes recomputed with its mass: fn and modal stiffness change)",
        "seed 000 section 2 and Fig. 2 (actuator mass lowers and splits the robot modes)",
        ("fn_hz", "k_n_per_m"), ("device",), (Parameter("mass_kg", 2.0, 0.0, 200.0),), lambda y, m, t: combine(y, m, {"flange_device": t}),
        combine=combine)}
