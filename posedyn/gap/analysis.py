"""Where simulation and measurement disagree, and which named physical effect closes the gap.

A measurement campaign is a list of rows: a pose, the conditions of the test (spindle speed,
absorber field, temperature, whether a device is mounted, the robot moving, the force level,
...), the measured `quantity`, its `value` and `std`. The current model predicts every row
(`baseline`); the normalised residuals r = (value - prediction) / std are noise when
sum r^2 follows a chi-square law with n degrees of freedom.

Each candidate effect is a small parametric extension of the prediction, y = f(baseline,
conditions; theta), acting on some quantities and depending on some conditions. A candidate
is *eligible* only where the data vary what it depends on (identifiability). It is fitted by
weighted least squares (parameter std from the Gauss-Newton covariance), scored by BIC =
chi^2 + p ln n and by 5-fold held-out chi^2 per row; effects are added greedily (forward
selection) while BIC drops by more than `MIN_BIC_DROP` and the residual is not yet noise. When
the best two candidates explain the data equally well (BIC within `TIE_BIC`) the workflow names
both and the measurement that would separate them instead of choosing. When the residual stays
structured and nothing in the library explains it, it says so and reports the variables the
residual correlates with.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy import stats
from scipy.optimize import least_squares

#: A candidate must lower BIC by this much to be named (strong evidence, Kass and Raftery).
MIN_BIC_DROP = 10.0
#: Two candidates within this BIC of each other explain the data equally well.
TIE_BIC = 6.0
#: The residual is noise when the chi-square test's p-value is above this.
NOISE_P = 0.01


@dataclass(frozen=True)
class Measurements:
    """Campaign rows as columns: `quantity` (str), `value`, `std`, `pose_id`, and numeric
    `conditions` (pose columns included, NaN where a row does not have the condition; columns
    named `model_*` are the model's context for a row, e.g. the predicted modal stiffness)."""

    quantity: np.ndarray
    value: np.ndarray
    std: np.ndarray
    pose_id: np.ndarray
    direction: np.ndarray
    mode: np.ndarray
    conditions: dict

    def __len__(self) -> int:
        return len(self.value)

    def column(self, name: str) -> np.ndarray:
        return self.conditions.get(name, np.full(len(self), np.nan))

    def take(self, index) -> "Measurements":
        return Measurements(
            self.quantity[index], self.value[index], self.std[index], self.pose_id[index], self.direction[index], self.mode[index],
            {k: v[index] for k, v in self.conditions.items()},
        )


@dataclass(frozen=True)
class Parameter:
    name: str
    start: float
    lower: float
    upper: float


@dataclass(frozen=True)
class CandidateEffect:
    """A named extension: `apply(y, m, theta)` returns the corrected predictions for all rows
    (rows it does not touch unchanged)."""

    name: str
    description: str
    source: str
    quantities: tuple[str, ...]
    depends_on: tuple[str, ...]
    parameters: tuple[Parameter, ...]
    apply: Callable = field(repr=False)

    def touches(self, m: Measurements) -> np.ndarray:
        mask = np.isin(m.quantity, self.quantities)
        for c in self.depends_on:
            mask &= np.isfinite(m.column(c))
        return mask

    def identifiable(self, m: Measurements) -> tuple[bool, str]:
        """The data must hold its quantities and vary each condition it depends on."""
        mask = self.touches(m)
        if mask.sum() < 3:
            return False, f"no {'/'.join(self.quantities)} rows with {', '.join(self.depends_on)}"
        for c in self.depends_on:
            if len(np.unique(m.column(c)[mask])) < 2:
                return False, f"{c} does not vary in the {'/'.join(self.quantities)} rows"
        return True, ""


def _on(m: Measurements, quantities, y, new):
    mask = np.isin(m.quantity, quantities)
    return np.where(mask, new, y)


def _cond(m: Measurements, name: str, default: float = 0.0) -> np.ndarray:
    c = m.column(name)
    return np.where(np.isfinite(c), c, default)


def _library() -> dict[str, CandidateEffect]:
    def device_mass(y, m, t):
        # fn of mode r with modal mass m_r = k / w^2 and a device of mass M at the tool: fn / sqrt(1 + M / m_r)
        k = _cond(m, "model_k_n_per_m", np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            modal_mass = k / (2 * np.pi * y) ** 2
            new = y / np.sqrt(1.0 + t[0] * _cond(m, "device") / modal_mass)
        return _on(m, ("fn_hz",), y, np.where(np.isfinite(new), new, y))

    def absorber_gravity(y, m, t):
        c = np.cos(np.radians(_cond(m, "absorber_angle_deg", 90.0))) ** 2
        return _on(m, ("absorber_fn_hz",), y, y * np.sqrt(np.maximum(1.0 + t[0] / 100.0 * c, 1e-6)))

    def moving(y, m, t):
        return _on(m, ("fn_hz",), y, y * (1.0 + t[0] / 100.0 * _cond(m, "moving")))

    def fixture(y, m, t):
        kf = 10.0 ** t[0]
        on = _cond(m, "fixture") > 0.5
        with np.errstate(divide="ignore"):
            softened = 1.0 / (1.0 / y + 1.0 / kf)
        return _on(m, ("k_n_per_m",), y, np.where(on, softened, y))

    def coupling(y, m, t):
        beta = np.radians(_cond(m, "beta_deg"))
        scale = np.sqrt(np.abs(_cond(m, "model_k_x_n_per_m", 0.0) * _cond(m, "model_k_y_n_per_m", 0.0)))
        return _on(m, ("k_xy_n_per_m",), y, y + t[0] * np.sin(2 * beta) * scale)

    def mrf_loss(y, m, t):
        return _on(m, ("absorber_zeta",), y, y + t[0] * _cond(m, "field_mt") / 1000.0)

    def mrf_temperature(y, m, t):
        dT = _cond(m, "temperature_c", 25.0) - 25.0
        return _on(m, ("absorber_fn_hz",), y, y * np.sqrt(np.maximum(1.0 - t[0] * 1e-3 * dT, 1e-6)))

    def force_level(y, m, t):
        soft = np.maximum(1.0 - t[0] * _cond(m, "force_n") / 1000.0, 1e-3)
        y = _on(m, ("k_n_per_m",), y, y * soft)
        return _on(m, ("fn_hz",), y, y * np.sqrt(soft))

    def process_damping(y, m, t):
        rpm = _cond(m, "rpm", np.inf)
        return _on(m, ("critical_depth_mm",), y, y * (1.0 + t[0] * (1000.0 / rpm) ** 2))

    effects = [
        CandidateEffect("device_mass", "added device mass on the spindle housing lowers the robot modes", "seed 000 section 2, Fig. 2",
                        ("fn_hz",), ("device",), (Parameter("mass_kg", 2.0, 0.0, 200.0),), device_mass),
        CandidateEffect("absorber_gravity_stiffness", "the absorber's stiffness changes with its orientation to gravity", "seed 000 section 3 (actuator frequency with orientation)",
                        ("absorber_fn_hz",), ("absorber_angle_deg",), (Parameter("stiffness_change_pct", 1.0, -90.0, 300.0),), absorber_gravity),
        CandidateEffect("moving_robot", "a moving robot's modes differ from the stationary ones measured by impact tests", "seed 001 section 4.3",
                        ("fn_hz",), ("moving",), (Parameter("fn_shift_pct", 0.5, -50.0, 50.0),), moving),
        CandidateEffect("fixture_compliance", "a compliant fixture / workpiece adds its flexibility to the tool tip", "seed 001 Table 5 (workpiece/fixture FRFs)",
                        ("k_n_per_m",), ("fixture",), (Parameter("log10_k_fixture_n_per_m", 8.0, 5.0, 14.0),), fixture),
        CandidateEffect("xy_cross_coupling", "the x and y tool-tip directions are coupled (cross stiffness turning with the redundant angle)", "seed 003 (coupled multi-output dynamics)",
                        ("k_xy_n_per_m",), ("beta_deg",), (Parameter("coupling", 0.05, -1.0, 1.0),), coupling),
        CandidateEffect("mrf_loss_modulus", "the MRF loss modulus adds field-dependent absorber damping (seed 004 keeps only G')", "seed 004 section 2 (storage modulus model only)",
                        ("absorber_zeta",), ("field_mt",), (Parameter("zeta_per_tesla", 0.01, -1.0, 1.0),), mrf_loss),
        CandidateEffect("mrf_temperature_drift", "the MRF storage modulus falls with temperature", "MRF rheology (modulus temperature coefficient); seed 004 tests at room temperature",
                        ("absorber_fn_hz",), ("temperature_c",), (Parameter("modulus_drop_per_mk", 1.0, -50.0, 50.0),), mrf_temperature),
        CandidateEffect("force_level_stiffness", "joint stiffness softens with the force level (nonlinear stiffness)", "robot joint stiffness is load dependent (seed 003 section 2; Dumas et al. 2011)",
                        ("k_n_per_m", "fn_hz"), ("force_n",), (Parameter("softening_per_kn", 0.01, -0.9, 0.9),), force_level),
        CandidateEffect("process_damping", "process damping raises the critical depth at low cutting speed", "Altintas, Eynian, Onozuka 2008; not in the seeds",
                        ("critical_depth_mm",), ("rpm",), (Parameter("strength", 0.1, 0.0, 100.0),), process_damping),
    ]
    return {e.name: e for e in effects}


LIBRARY: dict[str, CandidateEffect] = _library()


# --- fitting ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Fit:
    effects: tuple[str, ...]
    theta: np.ndarray
    theta_std: np.ndarray
    chi2: float
    bic: float
    cv_chi2_per_row: float


def predict(effects: tuple[str, ...], theta: np.ndarray, baseline: np.ndarray, m: Measurements) -> np.ndarray:
    y = baseline.copy()
    i = 0
    for name in effects:
        e = LIBRARY[name]
        k = len(e.parameters)
        y = e.apply(y, m, theta[i : i + k])
        i += k
    return y


def fit(effects: tuple[str, ...], baseline: np.ndarray, m: Measurements, folds: int = 5, seed: int = 0) -> Fit:
    params = [p for name in effects for p in LIBRARY[name].parameters]
    n = len(m)
    if not params:
        chi2 = float(np.sum(((m.value - baseline) / m.std) ** 2))
        return Fit((), np.zeros(0), np.zeros(0), chi2, chi2, chi2 / n)
    theta, cov = _least_squares(effects, params, baseline, m)
    r = (m.value - predict(effects, theta, baseline, m)) / m.std
    chi2 = float(r @ r)
    # held-out: refit on k-1 folds, score the left-out rows
    order = np.random.default_rng(seed).permutation(n)
    held = 0.0
    for part in np.array_split(order, folds):
        train = np.setdiff1d(order, part)
        t, _ = _least_squares(effects, params, baseline[train], m.take(train), start=theta)
        rr = (m.value[part] - predict(effects, t, baseline, m)[part]) / m.std[part]
        held += float(rr @ rr)
    return Fit(tuple(effects), theta, np.sqrt(np.maximum(np.diag(cov), 0.0)), chi2, chi2 + len(params) * math.log(n), held / n)


def _least_squares(effects, params, baseline, m, start=None):
    lo = np.array([p.lower for p in params])
    hi = np.array([p.upper for p in params])
    x0 = np.array([p.start for p in params]) if start is None else np.clip(start, lo, hi)

    def residual(t):
        return (m.value - predict(effects, t, baseline, m)) / m.std

    best = None
    for x in (x0, np.clip(x0 * 10.0, lo, hi), np.clip(-x0, lo, hi)) if start is None else (x0,):
        result = least_squares(residual, x, bounds=(lo, hi), x_scale="jac")
        if best is None or result.cost < best.cost:
            best = result
    J = best.jac
    try:
        cov = np.linalg.pinv(J.T @ J)
    except np.linalg.LinAlgError:
        cov = np.full((len(x0), len(x0)), np.inf)
    dof = max(len(m) - len(x0), 1)
    cov = cov * max(2.0 * best.cost / dof, 1.0)  # inflate when the fit is worse than the stated noise
    return best.x, cov


# --- the workflow ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class GapResult:
    effects: list  # [{"name", "parameters", "parameter_std", "evidence", "description", "source"}]
    rmse_before: float
    rmse_after: float
    noise_std: float
    explained: bool
    noise_p_before: float
    noise_p_after: float
    evidence_table: list  # per candidate: eligible, reason, delta_bic, cv
    ambiguous: list  # [{"candidates": [a, b], "separating_measurement": str}]
    correlates: list  # [{"variable", "spearman_rho", "p"}] when unexplained
    prediction_after: np.ndarray

    def to_json(self) -> dict:
        return {
            "effects": self.effects,
            "rmse_before": self.rmse_before,
            "rmse_after": self.rmse_after,
            "noise_std": self.noise_std,
            "explained": self.explained,
            "noise_p_before": self.noise_p_before,
            "noise_p_after": self.noise_p_after,
            "candidates": self.evidence_table,
            "ambiguous": self.ambiguous,
            "residual_correlates": self.correlates,
        }


def chi2_p(chi2: float, n: int) -> float:
    return float(stats.chi2.sf(chi2, n))


def analyse(m: Measurements, baseline: np.ndarray, library: dict[str, CandidateEffect] | None = None, max_effects: int = 3) -> GapResult:
    """Forward selection of named effects from the library (see the module docstring)."""
    library = LIBRARY if library is None else library
    n = len(m)
    current = fit((), baseline, m)
    p_before = chi2_p(current.chi2, n)
    chosen: tuple[str, ...] = ()
    table = {}
    ambiguous = []
    eligible = {}
    for name, e in library.items():
        ok, why = e.identifiable(m)
        eligible[name] = ok
        table[name] = {"name": name, "eligible": ok, "reason": why, "delta_bic": None, "cv_chi2_per_row": None, "chosen": False}
    while len(chosen) < max_effects and chi2_p(current.chi2, n) < NOISE_P:
        trials = {}
        for name in library:
            if name in chosen or not eligible[name]:
                continue
            trials[name] = fit(chosen + (name,), baseline, m)
            table[name]["delta_bic"] = round(trials[name].bic - current.bic, 3)
            table[name]["cv_chi2_per_row"] = round(trials[name].cv_chi2_per_row, 4)
        if not trials:
            break
        ranked = sorted(trials, key=lambda k: trials[k].bic)
        best = trials[ranked[0]]
        if current.bic - best.bic < MIN_BIC_DROP:
            break
        if len(ranked) > 1 and trials[ranked[1]].bic - best.bic < TIE_BIC and current.bic - trials[ranked[1]].bic >= MIN_BIC_DROP:
            a, b = library[ranked[0]], library[ranked[1]]
            ambiguous.append({"candidates": [a.name, b.name], "separating_measurement": separating_measurement(a, b)})
            break
        chosen = best.effects
        current = best
        table[ranked[0]]["chosen"] = True
    prediction = predict(current.effects, current.theta, baseline, m) if chosen else baseline.copy()
    effects = []
    i = 0
    for name in chosen:
        e = library[name]
        k = len(e.parameters)
        effects.append({
            "name": name,
            "description": e.description,
            "source": e.source,
            "parameters": {p.name: float(v) for p, v in zip(e.parameters, current.theta[i : i + k])},
            "parameter_std": {p.name: float(s) for p, s in zip(e.parameters, current.theta_std[i : i + k])},
            "evidence": float(-table[name]["delta_bic"]) if table[name]["delta_bic"] is not None else None,
        })
        i += k
    before = (m.value - baseline) / m.std
    after = (m.value - prediction) / m.std
    p_after = chi2_p(float(after @ after), n)
    explained = p_after >= NOISE_P
    correlates = [] if explained else residual_correlates(m, after)
    return GapResult(
        effects=effects,
        rmse_before=float(np.sqrt(np.mean(before**2))),
        rmse_after=float(np.sqrt(np.mean(after**2))),
        noise_std=1.0,
        explained=bool(explained),
        noise_p_before=p_before,
        noise_p_after=p_after,
        evidence_table=list(table.values()),
        ambiguous=ambiguous,
        correlates=correlates,
        prediction_after=prediction,
    )


def separating_measurement(a: CandidateEffect, b: CandidateEffect) -> str:
    only_a = [c for c in a.depends_on if c not in b.depends_on]
    only_b = [c for c in b.depends_on if c not in a.depends_on]
    q_a = [q for q in a.quantities if q not in b.quantities]
    q_b = [q for q in b.quantities if q not in a.quantities]
    parts = []
    if only_a or only_b:
        parts.append(f"vary {', '.join(only_a) or '-'} while holding {', '.join(only_b) or '-'} fixed (and the reverse)")
    if q_a or q_b:
        parts.append(f"measure {', '.join(q_a + q_b)}: only one of them changes it")
    return "; ".join(parts) or "repeat with the conditions they depend on varied independently"


def residual_correlates(m: Measurements, r: np.ndarray, top: int = 3) -> list:
    """Spearman correlation of the normalised residual with every condition, per quantity
    (the strongest first, p < 0.01 only)."""
    out = []
    for q in np.unique(m.quantity):
        rows = m.quantity == q
        for name, values in m.conditions.items():
            if name.startswith("model_"):  # the model's own context, not a test condition
                continue
            v = values[rows]
            ok = np.isfinite(v)
            if ok.sum() < 6 or len(np.unique(v[ok])) < 2:
                continue
            rho, p = stats.spearmanr(v[ok], r[rows][ok])
            if np.isfinite(rho) and p < 0.01:
                out.append({"quantity": str(q), "variable": name, "spearman_rho": float(rho), "p": float(p)})
    return sorted(out, key=lambda d: d["p"])[:top]
