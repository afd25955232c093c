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

Honest statistics (issue 18). The noise is not taken on trust: the normalised residual is
modelled as the stated noise N(0, 1), as Gaussian with its own scale s, or as Student-t with
scale s and nu degrees of freedom, whichever has the lowest BIC (`fit_noise`); every candidate
is fitted under the current noise model (a Student-t likelihood is a robust fit: outliers are not
read as an effect) and scored by the BIC of its best noise model, -2 ln L + (p + noise
parameters) ln n. So noise larger than stated, or heavier-tailed, is reported as such (`noise`)
instead of being explained by an effect. An effect whose fit sits on a parameter bound (its
physical range) is not claimed; two effects whose conditions vary together in the design
(|correlation| >= CONFOUNDED) and both lower BIC are reported as undecided with the measurement
that separates them; a candidate whose signal does not survive within the residual's own
structure is not named (`within_structure`); after the forward selection, an effect the others
make unnecessary is dropped (`_drop_unneeded`).

Effects through a model. A candidate with `combine` changes a model (the twin: `posedyn.gap.
twin_candidates`) and all such chosen candidates are applied as one changed model; one with
`fit_quantities` follows the pose and is selected first on those rows alone
(`_pose_following_first`), its refinement on every row started by a coarse-to-fine coordinate
search; two changes of one model that tie are reported with the measurement that separates
them (`separate`: for the twin, the pose and mode where they differ most).

Surface location error rows (`sle_um`) carry the model's SLE and mean surface-normal force as
context; their candidates (tool radius, runout, path-following offset, compliance under load,
cutting coefficients) each name the direct measurement that isolates them (`separate_by`).
Where nothing explains the residual, `posedyn.gap.discrepancy` maps it smoothly over the pose
and the conditions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
from scipy import stats
from scipy.optimize import least_squares, minimize_scalar
from scipy.special import gammaln

from posedyn.gap.discrepancy import DiscrepancyMap, discrepancy_map

#: A candidate must lower BIC by this much to be named (strong evidence, Kass and Raftery).
MIN_BIC_DROP = 10.0
#: Two candidates within this BIC of each other explain the data equally well.
TIE_BIC = 6.0
#: The residual is noise when the chi-square test's p-value is above this.
NOISE_P = 0.01
#: Two conditions vary together in a design when their correlation over the rows is at least this.
CONFOUNDED = 0.95
#: A residual whose fitted noise scale or RMS is above this many stated stds is not called noise,
#: however unstructured it looks (a stated std is not that far off; a cause outside the library is likelier).
PLAUSIBLE_NOISE_SCALE = 3.0
#: Student-t degrees of freedom searched (below 1.5 the variance does not exist: not a noise model).
DOF_RANGE = (1.5, 200.0)


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
    combine: Callable | None = field(default=None, repr=False)  # (y, m, {name: theta}): effects that change one model together (the twin)
    fit_quantities: tuple | None = None  # a pose-following model candidate: selected and fitted first on these rows only (`analyse`)
    separate_by: str = ""  # a direct measurement of this effect (named where it is undecided against another)
    separate: Callable | None = field(default=None, repr=False)  # (m, {name: value}, {name: value}): the measurement that tells two changed models apart

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
        # G'(T) = G'(T_ref) exp(-a (T - T_ref)): the model's modulus holds at T_ref (seed 004's at
        # 25 C, a fitted parameter here), f_a ~ sqrt(G')
        dT = _cond(m, "temperature_c", t[1]) - t[1]
        return _on(m, ("absorber_fn_hz",), y, y * np.exp(-0.5 * t[0] * 1e-3 * dT))

    def force_level(y, m, t):
        soft = np.maximum(1.0 - t[0] * _cond(m, "force_n") / 1000.0, 1e-3)
        y = _on(m, ("k_n_per_m",), y, y * soft)
        return _on(m, ("fn_hz",), y, y * np.sqrt(soft))

    def process_damping(y, m, t):
        rpm = _cond(m, "rpm", np.inf)
        return _on(m, ("critical_depth_mm",), y, y * (1.0 + t[0] * (1000.0 / rpm) ** 2))

    # surface location error rows (`sle_um`, + = undercut; seed 001): the model's SLE, y_0 =
    # model_sle_um, and the mean surface-normal force as it pushes toward undercut, F_0 =
    # model_sle_mean_force_n, are the baseline's context for each row
    def radius_error(y, m, t):
        # a tool t um larger in radius than nominal cuts the wall t um deeper (both milling directions)
        return _on(m, ("sle_um",), y, y - t[0])

    def runout(y, m, t):
        # the tooth reaching farthest cuts the wall: radii R + e cos(theta + 2 pi i / N); over a
        # random clamping phase the expected farthest reach is e (N / pi) sin(pi / N)
        n = np.maximum(_cond(m, "teeth", 1.0), 1.0)
        return _on(m, ("sle_um",), y, y - t[0] * n / np.pi * np.sin(np.pi / n))

    def path_following(y, m, t):
        # the robot's path lags outside the commanded path in proportion to the feed speed (seed
        # 001 Table 2: 14 um at 4.0 m/min, 32-34 um at 8.0-8.2 m/min, undercut on every side)
        return _on(m, ("sle_um",), y, y + t[0] * _cond(m, "feed_mm_per_min") / 1000.0)

    def load_compliance(y, m, t):
        # a compliance the impact test does not see (joints under the cutting load, well below the
        # tooth-passing frequency) responds to the mean force only: dy = dC F_0
        return _on(m, ("sle_um",), y, y + t[0] * _cond(m, "model_sle_mean_force_n"))

    def cutting_coefficients(y, m, t):
        # k_t and k_n both (1 + s) times the model's: the SLE is linear in the force, and the
        # critical depth of the delay equation (a k_t H(t), H fixed by k_n / k_t) is 1 / (1 + s) times
        s = t[0] / 100.0
        y = _on(m, ("sle_um",), y, y + s * _cond(m, "model_sle_um"))
        return _on(m, ("critical_depth_mm",), y, y / (1.0 + s))

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
                        ("absorber_fn_hz",), ("temperature_c",), (Parameter("modulus_drop_per_mk", 1.0, -50.0, 50.0), Parameter("reference_c", 25.0, -20.0, 80.0)), mrf_temperature),
        CandidateEffect("force_level_stiffness", "joint stiffness softens with the force level (nonlinear stiffness)", "robot joint stiffness is load dependent (seed 003 section 2; Dumas et al. 2011)",
                        ("k_n_per_m", "fn_hz"), ("force_n",), (Parameter("softening_per_kn", 0.01, -0.9, 0.9),), force_level),
        CandidateEffect("process_damping", "process damping raises the critical depth at low cutting speed", "Altintas, Eynian, Onozuka 2008; not in the seeds",
                        ("critical_depth_mm",), ("rpm",), (Parameter("strength", 0.1, 0.0, 100.0),), process_damping),
        CandidateEffect("tool_radius_error", "the tool's cutting radius differs from nominal (a constant overcut or undercut)", "seed 001 section 2.3 (the part dimension is the radial depth minus the SLE)",
                        ("sle_um",), (), (Parameter("radius_error_um", 5.0, -500.0, 500.0),), radius_error,
                        separate_by="measure the tool radius on a presetter"),
        CandidateEffect("spindle_runout", "tool runout: the tooth reaching farthest cuts the wall, more so with more teeth", "milling surface generation (Schmitz and Smith, Machining Dynamics, ch. 7); not in the seeds",
                        ("sle_um",), ("teeth",), (Parameter("runout_um", 5.0, 0.0, 200.0),), runout,
                        separate_by="measure the runout at the tool with a dial indicator"),
        CandidateEffect("path_following_offset", "the robot's path runs outside the commanded path, more so the faster it feeds", "seed 001 section 4.1, Table 2 and Fig. 3",
                        ("sle_um",), ("feed_mm_per_min",), (Parameter("offset_um_per_m_per_min", 1.0, -50.0, 50.0),), path_following,
                        separate_by="record the robot's path during the cut (controller positions, seed 001 Fig. 3)"),
        CandidateEffect("load_compliance", "under the cutting load the tool tip is more compliant than the impact-test modes say (the static deflection differs)", "seed 001 section 4.5 (robot SLE set by its low modes); seed 003 (load-dependent joint stiffness)",
                        ("sle_um",), ("model_sle_mean_force_n",), (Parameter("compliance_um_per_n", 0.05, -5.0, 50.0),), load_compliance,
                        separate_by="a static stiffness test at the tool tip under a cutting-size load"),
        CandidateEffect("cutting_coefficient_error", "the specific cutting forces k_t and k_n differ from the cut file's (every force, SLE and critical depth scale)", "seed 001 Table 3 (coefficients from cutting tests); seed 004 eqs. 1-3",
                        ("sle_um", "critical_depth_mm"), ("model_sle_um",), (Parameter("force_error_pct", 5.0, -80.0, 300.0),), cutting_coefficients,
                        separate_by="measure the cutting force on a dynamometer"),
    ]
    return {e.name: e for e in effects}


LIBRARY: dict[str, CandidateEffect] = _library()


# --- fitting ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Noise:
    """The noise of the normalised residual: `stated` N(0, 1), `scaled` N(0, s^2) or `student_t`
    (scale s, dof nu); its maximised log-likelihood and number of fitted parameters."""

    model: str
    scale: float
    dof: float  # inf: Gaussian
    log_likelihood: float
    free: int

    def to_json(self) -> dict:
        return {"model": self.model, "scale": self.scale, "dof": self.dof if math.isfinite(self.dof) else None}


STATED = Noise("stated", 1.0, math.inf, math.nan, 0)


def _gauss_ll(r: np.ndarray, s: float) -> float:
    return float(np.sum(-0.5 * math.log(2 * math.pi) - math.log(s) - 0.5 * (r / s) ** 2))


def _t_ll(r: np.ndarray, s: float, nu: float) -> float:
    """Student-t log-likelihood: ln G((nu+1)/2) - ln G(nu/2) - ln(sqrt(nu pi) s) - (nu+1)/2 ln(1 + r^2/(nu s^2))."""
    return float(np.sum(gammaln((nu + 1) / 2) - gammaln(nu / 2) - 0.5 * math.log(nu * math.pi) - math.log(s) - (nu + 1) / 2 * np.log1p((r / s) ** 2 / nu)))


def _t_scale(r: np.ndarray, nu: float, start: float) -> float:
    """The maximum-likelihood scale of a Student-t with nu dof (EM: s^2 = mean(w r^2), w =
    (nu + 1) / (nu + r^2 / s^2))."""
    s = start
    for _ in range(200):
        w = (nu + 1) / (nu + (r / s) ** 2)
        new = max(math.sqrt(float(np.mean(w * r**2))), 1e-12)
        if abs(new - s) <= 1e-9 * s:
            return new
        s = new
    return s


def fit_noise(r: np.ndarray) -> Noise:
    """The noise model of normalised residuals r with the lowest BIC = -2 ln L + free ln n among
    the stated N(0, 1), N(0, s^2) (s = rms r) and Student-t (s, nu by maximum likelihood)."""
    r = np.asarray(r, dtype=float)
    n = len(r)
    stated = Noise("stated", 1.0, math.inf, _gauss_ll(r, 1.0), 0)
    rms = max(float(np.sqrt(np.mean(r**2))), 1e-12)
    scaled = Noise("scaled", rms, math.inf, _gauss_ll(r, rms), 1)
    mad = max(1.4826 * float(np.median(np.abs(r))), 1e-12)
    best = minimize_scalar(lambda x: -_t_ll(r, _t_scale(r, math.exp(x), mad), math.exp(x)), bounds=tuple(math.log(v) for v in DOF_RANGE),
                           method="bounded", options={"xatol": 1e-3})
    nu = math.exp(best.x)
    student = Noise("student_t", _t_scale(r, nu, mad), nu, -float(best.fun), 2)
    return min((stated, scaled, student), key=lambda z: -2 * z.log_likelihood + z.free * math.log(max(n, 2)))


@dataclass(frozen=True)
class Fit:
    effects: tuple[str, ...]
    theta: np.ndarray
    theta_std: np.ndarray
    chi2: float
    bic: float  # -2 ln L of the best noise model + (parameters + its noise parameters) ln n
    cv_chi2_per_row: float
    noise: Noise = STATED
    at_bound: tuple[str, ...] = ()  # parameters whose fit sits on a bound of their physical range


def predict(effects: tuple[str, ...], theta: np.ndarray, baseline: np.ndarray, m: Measurements, library: dict | None = None) -> np.ndarray:
    """The baseline with the named effects applied in order (parameters concatenated in theta)."""
    library = LIBRARY if library is None else library
    y = baseline.copy()
    i = 0
    together: dict = {}  # effects that act through one model are applied at once (they do not compose as factors)
    for name in effects:
        e = library[name]
        k = len(e.parameters)
        if e.combine is not None:
            together.setdefault(e.combine, {})[name] = theta[i : i + k]
        else:
            y = e.apply(y, m, theta[i : i + k])
        i += k
    for combine, thetas in together.items():
        y = combine(y, m, thetas)
    return y


def fit(effects: tuple[str, ...], baseline: np.ndarray, m: Measurements, folds: int = 5, seed: int = 0, noise: Noise = STATED, library: dict | None = None,
        prior=None) -> Fit:
    """The effects' parameters under `noise` (Student-t: a robust fit; `prior`: the already chosen
    effects' parameters as their start), the noise model of the residual they leave (`fit_noise`),
    BIC and a `folds`-fold held-out chi-square per row."""
    library = LIBRARY if library is None else library
    params = [p for name in effects for p in library[name].parameters]
    n = len(m)
    if not params:
        r = (m.value - baseline) / m.std
        z = fit_noise(r)
        chi2 = float(r @ r)
        return Fit((), np.zeros(0), np.zeros(0), chi2, -2 * z.log_likelihood + z.free * math.log(n), chi2 / n, z)
    theta, cov, active = _least_squares(effects, params, baseline, m, noise=noise, library=library, prior=prior)
    r = (m.value - predict(effects, theta, baseline, m, library)) / m.std
    chi2 = float(r @ r)
    z = fit_noise(r)
    bic = -2 * z.log_likelihood + (len(params) + z.free) * math.log(n)
    held = held_out_chi2(effects, theta, baseline, m, folds, seed, noise, library) if folds else math.nan
    return Fit(tuple(effects), theta, np.sqrt(np.maximum(np.diag(cov), 0.0)), chi2, bic, held, z,
               tuple(p.name for p, a in zip(params, active) if a))


def held_out_chi2(effects: tuple[str, ...], theta: np.ndarray, baseline: np.ndarray, m: Measurements, folds: int = 5, seed: int = 0,
                  noise: Noise = STATED, library: dict | None = None) -> float:
    """Chi-square per row on rows held out of the fit: refit on k-1 folds (from theta), score the
    left-out rows."""
    library = LIBRARY if library is None else library
    params = [p for name in effects for p in library[name].parameters]
    n = len(m)
    order = np.random.default_rng(seed).permutation(n)
    held = 0.0
    for part in np.array_split(order, folds):
        train = np.setdiff1d(order, part)
        t, _, _ = _least_squares(effects, params, baseline[train], m.take(train), start=theta, noise=noise, library=library)
        rr = (m.value[part] - predict(effects, t, baseline, m, library)[part]) / m.std[part]
        held += float(rr @ rr)
    return held / n


def _t_loss(nu: float):
    """scipy least_squares loss for a Student-t likelihood: rho(z) = (nu + 1) ln(1 + z / nu),
    z = r^2 / s^2 (f_scale = s), so the cost is s^2 times the negative log-likelihood."""

    def rho(z):
        return np.vstack([(nu + 1) * np.log1p(z / nu), (nu + 1) / (nu + z), -(nu + 1) / (nu + z) ** 2])

    return rho


#: Grid points of a model-level candidate's extra start.
GRID_STARTS = 17
#: Offsets tried around each parameter of pose-following candidates before their refinement on every
#: row, coarse to fine (each scale a sixth of the one before: steps 0.05, 0.008, 0.0014).
REFINE_OFFSETS = np.linspace(-0.3, 0.3, 13)
REFINE_SCALES = (1.0, 1.0 / 6.0, 1.0 / 36.0)


def _cost(r: np.ndarray, noise: Noise) -> float:
    """The least-squares objective of normalised residuals r under `noise` (`_least_squares`)."""
    if not math.isfinite(noise.dof):
        return float(r @ r)
    return float(np.sum(_t_loss(noise.dof)(r**2 / noise.scale**2)[0]))


def _least_squares(effects, params, baseline, m, start=None, noise: Noise = STATED, library: dict | None = None, prior=None):
    """(theta, covariance, active bounds) of the effects' parameters: weighted least squares under
    Gaussian noise, the Student-t likelihood under Student-t noise."""
    lo = np.array([p.lower for p in params])
    hi = np.array([p.upper for p in params])
    x0 = np.array([p.start for p in params]) if start is None else np.clip(start, lo, hi)
    if start is None and prior is not None and len(prior):
        x0[: len(prior)] = np.clip(prior, lo[: len(prior)], hi[: len(prior)])
    robust = math.isfinite(noise.dof)
    loss = _t_loss(noise.dof) if robust else "linear"
    scale = noise.scale if robust else 1.0

    def residual(t):
        return (m.value - predict(effects, t, baseline, m, library)) / m.std

    starts = [x0]
    if start is None:
        new = slice(len(prior) if prior is not None else 0, len(x0))
        for factor in (10.0, -1.0):
            x = x0.copy()
            x[new] = np.clip(x0[new] * factor, lo[new], hi[new])
            starts.append(x)
        if library is not None and library[effects[-1]].combine is not None and new.stop - new.start == 1:
            # a model-level candidate (its modes recomputed: the landscape has kinks where modes
            # cross): the best of a grid over its range as one more start
            grid = np.linspace(lo[new][0], hi[new][0], GRID_STARTS)
            costs = []
            for g in grid:
                x = x0.copy()
                x[new] = g
                costs.append(_cost(residual(x), noise))
            x = x0.copy()
            x[new] = grid[int(np.nanargmin(costs))]
            starts.append(x)
    best = None
    for x in starts:
        result = least_squares(residual, x, bounds=(lo, hi), x_scale="jac", loss=loss, f_scale=scale)
        if best is None or result.cost < best.cost:
            best = result
    J = best.jac
    if robust:  # IRLS weights of the t likelihood at the solution
        w = (noise.dof + 1) / (noise.dof + (best.fun / scale) ** 2)
        J = J * np.sqrt(w)[:, None]
    try:
        cov = np.linalg.pinv(J.T @ J)
    except np.linalg.LinAlgError:
        cov = np.full((len(x0), len(x0)), np.inf)
    dof = max(len(m) - len(x0), 1)
    inflate = noise.scale**2 if noise.model != "stated" else max(float(best.fun @ best.fun) / dof, 1.0)
    return best.x, cov * inflate, np.asarray(best.active_mask) != 0


# --- the workflow ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class GapResult:
    effects: list  # [{"name", "parameters", "parameter_std", "evidence", "description", "source"}]
    rmse_before: float
    rmse_after: float
    noise_std: float  # the fitted noise scale in units of the stated std (1: as stated)
    explained: bool
    noise_p_before: float
    noise_p_after: float
    evidence_table: list  # per candidate: eligible, reason, delta_bic, cv
    ambiguous: list  # [{"candidates": [a, b], "separating_measurement": str}]
    correlates: list  # [{"variable", "spearman_rho", "p"}] when unexplained
    prediction_after: np.ndarray
    noise: dict = field(default_factory=dict)  # {"model", "scale", "dof", "verdict"}
    held_out: dict = field(default_factory=dict)  # {"before", "after"}: chi-square per row on rows held out of the fit (5 folds)
    discrepancy: DiscrepancyMap | None = None  # where the unexplained residual lives (None when explained)

    def to_json(self) -> dict:
        return {
            "effects": self.effects,
            "rmse_before": self.rmse_before,
            "rmse_after": self.rmse_after,
            "noise_std": self.noise_std,
            "noise": self.noise,
            "held_out_chi2_per_row": self.held_out,
            "explained": self.explained,
            "noise_p_before": self.noise_p_before,
            "noise_p_after": self.noise_p_after,
            "candidates": self.evidence_table,
            "ambiguous": self.ambiguous,
            "residual_correlates": self.correlates,
            "discrepancy_map": self.discrepancy.to_json() if self.discrepancy is not None else None,
        }


def chi2_p(chi2: float, n: int) -> float:
    return float(stats.chi2.sf(chi2, n))


def noise_verdict(noise: Noise) -> str:
    if noise.model == "stated":
        return "the residual is noise of the stated std"
    if noise.model == "scaled":
        word = "small" if noise.scale > 1 else "large"
        return f"the residual is Gaussian noise {noise.scale:.2g} x the stated std: the stated std looks too {word}"
    return (f"heavy-tailed noise (Student-t, {noise.dof:.2g} degrees of freedom, scale {noise.scale:.2g} x the stated std): "
            "fitted robustly, outliers are not read as effects")


def analyse(m: Measurements, baseline: np.ndarray, library: dict[str, CandidateEffect] | None = None, max_effects: int = 3) -> GapResult:
    """Forward selection of named effects from the library (see the module docstring)."""
    library = LIBRARY if library is None else library
    n = len(m)
    current = fit((), baseline, m, library=library)
    held_before = current.cv_chi2_per_row
    p_before = chi2_p(current.chi2, n)
    chosen: tuple[str, ...] = ()
    table = {}
    ambiguous = []
    eligible = {}
    for name, e in library.items():
        ok, why = e.identifiable(m)
        eligible[name] = ok
        table[name] = {"name": name, "eligible": ok, "reason": why, "delta_bic": None, "cv_chi2_per_row": None, "chosen": False}
    first, pose_structure, undecided = _pose_following_first(m, baseline, library, current, max_effects)
    for a in undecided:  # two model changes the fn rows cannot tell apart: neither is tried again on every row
        ambiguous.append(a)
        for name in a["candidates"]:
            eligible[name] = False
            table[name]["reason"] = f"undecided on the fn rows between {' and '.join(a['candidates'])}"
    if first is not None:
        for name in first.effects:
            table[name].update(chosen=True, delta_bic=round(first.bic - current.bic, 3))
        chosen, current = first.effects, first
    while len(chosen) < max_effects and not (current.noise.model == "stated" and chi2_p(current.chi2, n) >= NOISE_P):
        trials = {}
        for name in library:
            if name in chosen or not eligible[name] or (library[name].fit_quantities is not None and not pose_structure):
                continue  # pose-following candidates: tried on every row only where the first pass found pose-following structure
            trials[name] = fit(chosen + (name,), baseline, m, folds=0, noise=current.noise, library=library, prior=current.theta)
            table[name]["delta_bic"] = round(trials[name].bic - current.bic, 3)
            if trials[name].at_bound:
                table[name]["reason"] = f"fit on the bound of {', '.join(trials[name].at_bound)} (outside its physical range)"
        passing = [k for k in sorted(trials, key=lambda k: trials[k].bic) if current.bic - trials[k].bic >= MIN_BIC_DROP]
        for k in passing:  # held-out score of the candidates that could be named (the others' would only cost)
            trials[k] = replace(trials[k], cv_chi2_per_row=held_out_chi2(trials[k].effects, trials[k].theta, baseline, m, noise=current.noise, library=library))
            table[k]["cv_chi2_per_row"] = round(trials[k].cv_chi2_per_row, 4)
        for k in list(passing):
            if not within_structure(trials[k], current, baseline, m, [library[c] for c in chosen], library):
                table[k]["reason"] = "its signal goes with the residual's structure over poses or the named effects' conditions, not within them"
                passing.remove(k)
        if not passing or trials[passing[0]].at_bound:  # the strongest signal lies outside the library's physics: claim no surrogate
            break
        best = passing[0]
        rivals = [k for k in passing[1:] if not trials[k].at_bound and (trials[k].bic - trials[best].bic < TIE_BIC or confounded(library[best], library[k], m))]
        if rivals:
            text = separating_measurement(library[best], library[rivals[0]])
            a, b = library[best], library[rivals[0]]
            if a.separate is not None and a.separate is b.separate:  # two changes of one model: where they differ most
                text = a.separate(m, _model_values(trials[best], library), _model_values(trials[rivals[0]], library)) or text
            ambiguous.append({"candidates": [best, rivals[0]], "separating_measurement": text})
            break
        chosen = trials[best].effects
        current = trials[best]
        table[best]["chosen"] = True
    chosen, current = _drop_unneeded(chosen, current, baseline, m, library, table)
    prediction = predict(current.effects, current.theta, baseline, m, library) if chosen else baseline.copy()
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
    noise = current.noise
    if noise.model == "stated":
        explained = p_after >= NOISE_P
    else:  # noise other than stated: explained when nothing structured is left and the scale is one a stated std can be off by
        rms = float(np.sqrt(np.mean(after**2)))
        explained = max(noise.scale, rms) <= PLAUSIBLE_NOISE_SCALE and not residual_correlates(m, after, level=NOISE_P / max(_tests(m), 1))
    correlates = [] if explained else residual_correlates(m, after)
    if explained:  # a tie on the fn rows alone that the named effects resolved (e.g. a device's rows read as a joint) is no ambiguity
        ambiguous = [a for a in ambiguous if a not in undecided]
    where = None
    if not explained:  # a smooth map of what is left, for the quantity that misses most
        counts = {q: np.sum(m.quantity == q) for q in np.unique(m.quantity)}
        worst = max((q for q in counts if counts[q] >= 8), key=lambda q: float(np.mean(after[m.quantity == q] ** 2)), default=None)
        where = discrepancy_map(m, after, str(worst)) if worst is not None else None
    return GapResult(
        effects=effects,
        rmse_before=float(np.sqrt(np.mean(before**2))),
        rmse_after=float(np.sqrt(np.mean(after**2))),
        noise_std=float(noise.scale),
        explained=bool(explained),
        noise_p_before=p_before,
        noise_p_after=p_after,
        evidence_table=list(table.values()),
        ambiguous=ambiguous,
        correlates=correlates,
        prediction_after=prediction,
        noise=dict(noise.to_json(), verdict=noise_verdict(noise)),
        held_out={"before": held_before, "after": current.cv_chi2_per_row},
        discrepancy=where,
    )


def _model_values(trial: Fit, library: dict) -> dict:
    """{name: its (first) parameter} of a fit's effects that change a model (`combine`)."""
    out, i = {}, 0
    for name in trial.effects:
        e = library[name]
        if e.combine is not None:
            out[name] = float(trial.theta[i])
        i += len(e.parameters)
    return out


def _groups(m: Measurements, columns) -> np.ndarray:
    """Group index of every row by quantity and the named condition columns (one with more than
    8 values is cut at its quintiles) or given label arrays (taken as they are)."""
    keys = [m.quantity.astype(str)]
    for c in columns:
        if isinstance(c, str):
            v = m.column(c)
            v = np.where(np.isfinite(v), v, -1e300)
            if len(np.unique(v)) > 8:
                v = np.searchsorted(np.quantile(v, [0.2, 0.4, 0.6, 0.8]), v)
            c = v
        keys.append(np.asarray(c).astype(str))
    return np.unique(np.array(["|".join(t) for t in zip(*keys)]), return_inverse=True)[1]


def _demean(x: np.ndarray, groups: list[np.ndarray], w: np.ndarray, sweeps: int = 20) -> np.ndarray:
    """x with weighted group means removed for several groupings at once (alternating projections)."""
    x = x.copy()
    for _ in range(sweeps if len(groups) > 1 else 1):
        for g in groups:
            x -= (np.bincount(g, w * x) / np.maximum(np.bincount(g, w), 1e-300))[g]
    return x


def within_structure(trial: Fit, current: Fit, baseline: np.ndarray, m: Measurements, chosen: list, library: dict | None = None) -> bool:
    """Whether a candidate's signal survives the residual's own structure: the residual r and the
    candidate's signature e (its fitted contribution, in stds) are taken within groups of the
    rows that share the named effects' condition levels (a wrong functional form of a named effect
    leaves structure there) and, where the residual follows the pose (F-test, p < NOISE_P) and the
    signature varies within poses, within each pose's mode; the within-group regression of r on e
    must still pass the BIC criterion, z^2 >= ln n + MIN_BIC_DROP (t-weights under Student-t
    noise). A random condition that happens to be unbalanced across poses or force levels is
    then not named for structure it does not explain."""
    before = predict(current.effects, current.theta, baseline, m, library) if current.effects else baseline
    after = predict(trial.effects, trial.theta, baseline, m, library)
    r = (m.value - before) / m.std
    e = (after - before) / m.std
    noise = current.noise
    w = (noise.dof + 1) / (noise.dof + (r / noise.scale) ** 2) if math.isfinite(noise.dof) else np.ones(len(r))
    groups = [_groups(m, effect_columns)] if (effect_columns := [c for x in chosen for c in x.depends_on]) else []
    pose = _groups(m, [m.pose_id, m.direction, m.mode])
    r_pose = _demean(r, [pose], w)
    k = len(np.unique(pose))
    rss, rss_pose = float(np.sum(w * (r - np.average(r, weights=w)) ** 2)), float(np.sum(w * r_pose**2))
    if k > 1 and len(r) > k and rss_pose > 0:
        f = ((rss - rss_pose) / (k - 1)) / (rss_pose / (len(r) - k))
        follows_pose = stats.f.sf(f, k - 1, len(r) - k) < NOISE_P
        e_within = _demean(e, [pose], w)
        if follows_pose and np.sum(w * e_within**2) >= 0.25 * np.sum(w * (e - np.average(e, weights=w)) ** 2):
            groups.append(pose)
    if not groups:
        return True
    r_a, e_a = _demean(r, groups, w), _demean(e, groups, w)
    see = float(np.sum(w * e_a**2))
    if see <= 0:
        return False
    beta = float(np.sum(w * e_a * r_a)) / see
    dof = max(len(r) - len(np.unique(np.concatenate([g + 1e6 * i for i, g in enumerate(groups)]))) - 1, 1)
    sigma2 = float(np.sum(w * (r_a - beta * e_a) ** 2)) / dof
    return beta**2 * see / max(sigma2, 1e-300) >= math.log(len(r)) + MIN_BIC_DROP


def _drop_unneeded(chosen: tuple, current: Fit, baseline: np.ndarray, m: Measurements, library: dict, table: dict) -> tuple[tuple, Fit]:
    """Backward elimination: a named effect that the others make unnecessary (removing it raises
    BIC by less than MIN_BIC_DROP, e.g. a joint picked up for the pose average of a device named
    later) is dropped, one at a time."""
    while len(chosen) > 1:
        for name in chosen:
            rest = tuple(e for e in chosen if e != name)
            keep = np.concatenate([np.ones(len(library[e].parameters), bool) * (e != name) for e in chosen])
            without = fit(rest, baseline, m, folds=0, noise=current.noise, library=library, prior=current.theta[keep])
            if without.bic - current.bic < MIN_BIC_DROP:
                table[name].update(chosen=False, reason=f"dropped: not needed once {', '.join(rest)} named (BIC {without.bic - current.bic:+.1f} without it)")
                chosen = rest
                current = replace(without, cv_chi2_per_row=held_out_chi2(rest, without.theta, baseline, m, noise=current.noise, library=library))
                break
        else:
            break
    return chosen, current


def _pose_following_first(m: Measurements, baseline: np.ndarray, library: dict, current: Fit, max_effects: int) -> tuple[Fit | None, bool, list]:
    """The pose-following model candidates (`fit_quantities`: a joint's stiffness in the twin)
    selected first, on their rows alone (fn rows: continuous in the twin's parameters, where the
    modal stiffness of a mode numbered by frequency rank jumps as modes cross), by the same
    forward selection; kept, with their parameters refined on every row, when they lower the
    BIC of the whole campaign by MIN_BIC_DROP (else None); whether those rows showed any
    pose-following structure at all (then the candidates are tried on every row as well); and
    the pairs those rows could not tell apart (with the pose to measure next)."""
    own = {k: e for k, e in library.items() if e.fit_quantities is not None}
    if not own:
        return None, False, []
    quantities = sorted({q for e in own.values() for q in e.fit_quantities})
    rows = np.flatnonzero(np.isin(m.quantity, quantities))
    if len(rows) < 6:
        return None, False, []
    sub = analyse(m.take(rows), baseline[rows], library={k: replace(e, fit_quantities=None) for k, e in own.items()}, max_effects=max_effects)
    if not sub.effects:
        return None, bool(sub.ambiguous), sub.ambiguous
    names = tuple(e["name"] for e in sub.effects)
    theta = _coordinate_search(names, np.array([v for e in sub.effects for v in e["parameters"].values()]), baseline, m, library, current.noise)
    whole = fit(names, baseline, m, library=library, prior=theta, noise=current.noise)
    return (whole if current.bic - whole.bic >= MIN_BIC_DROP and not whole.at_bound else None), True, sub.ambiguous


def _coordinate_search(effects: tuple, theta: np.ndarray, baseline: np.ndarray, m: Measurements, library: dict, noise: Noise, sweeps: int = 2) -> np.ndarray:
    """theta moved to the best of REFINE_OFFSETS around each parameter in turn (all rows), at each
    of REFINE_SCALES: the start of the refinement on every row. That objective is rough where
    modes numbered by rank cross: a modal-stiffness row jumps by 20 stds when a joint's factor is
    0.7 % off, so the basin of the truth is narrow (fits from the fn rows' optimum alone ended in
    local minima up to 70 % off)."""
    params = [p for name in effects for p in library[name].parameters]
    lo, hi = np.array([p.lower for p in params]), np.array([p.upper for p in params])
    theta = np.clip(theta.astype(float), lo, hi)
    best = _cost((m.value - predict(effects, theta, baseline, m, library)) / m.std, noise)
    for scale in REFINE_SCALES:
        for _ in range(sweeps):
            moved = False
            for j in range(len(theta)):
                for value in np.unique(np.clip(theta[j] + scale * REFINE_OFFSETS, lo[j], hi[j])):
                    trial = theta.copy()
                    trial[j] = value
                    cost = _cost((m.value - predict(effects, trial, baseline, m, library)) / m.std, noise)
                    if cost < best:
                        best, theta, moved = cost, trial, True
            if not moved:
                break
    return theta


def confounded(a: CandidateEffect, b: CandidateEffect, m: Measurements) -> bool:
    """Whether two effects' conditions vary together in the design: over the rows either touches
    where both conditions are given, |correlation| >= CONFOUNDED for some pair of them, or one
    is a function of the other's levels (a device mounted exactly when the force is high).
    Conditions only: `model_*` context columns (what the model predicts for a row) are left to
    the BIC tie (TIE_BIC)."""
    rows = a.touches(m) | b.touches(m)
    for ca in a.depends_on:
        for cb in b.depends_on:
            if ca == cb or ca.startswith("model_") or cb.startswith("model_"):
                continue  # the model's own context (e.g. its SLE and mean force) is not designed: the BIC tie decides there
            x, y = m.column(ca), m.column(cb)
            ok = rows & np.isfinite(x) & np.isfinite(y)
            if ok.sum() < 3 or np.std(x[ok]) == 0 or np.std(y[ok]) == 0:
                continue
            if abs(np.corrcoef(x[ok], y[ok])[0, 1]) >= CONFOUNDED or _determines(x[ok], y[ok]) or _determines(y[ok], x[ok]):
                return True
    return False


def _determines(x: np.ndarray, y: np.ndarray) -> bool:
    """Whether y is a function of x's levels (x with repeated levels: at most a third as many as rows)."""
    levels, index = np.unique(x, return_inverse=True)
    if len(levels) > len(x) / 3:
        return False
    return all(len(np.unique(y[index == i])) == 1 for i in range(len(levels)))


def separating_measurement(a: CandidateEffect, b: CandidateEffect) -> str:
    only_a = [c for c in a.depends_on if c not in b.depends_on and not c.startswith("model_")]  # conditions one can set
    only_b = [c for c in b.depends_on if c not in a.depends_on and not c.startswith("model_")]
    q_a = [q for q in a.quantities if q not in b.quantities]
    q_b = [q for q in b.quantities if q not in a.quantities]
    parts = []
    if only_a or only_b:
        parts.append(f"vary {', '.join(only_a) or '-'} while holding {', '.join(only_b) or '-'} fixed (and the reverse)")
    if q_a or q_b:
        parts.append(f"measure {', '.join(q_a + q_b)}: only one of them changes it")
    parts += [e.separate_by for e in (a, b) if e.separate_by]
    return "; ".join(parts) or "repeat with the conditions they depend on varied independently"


def _condition_tests(m: Measurements):
    """(quantity, condition name, rows, values) of every residual-versus-condition test."""
    for q in np.unique(m.quantity):
        rows = m.quantity == q
        for name, values in m.conditions.items():
            if name.startswith("model_"):  # the model's own context, not a test condition
                continue
            v = values[rows]
            ok = np.isfinite(v)
            if ok.sum() < 6 or len(np.unique(v[ok])) < 2:
                continue
            yield q, name, rows, v, ok


def _tests(m: Measurements) -> int:
    return sum(1 for _ in _condition_tests(m))


def residual_correlates(m: Measurements, r: np.ndarray, top: int = 3, level: float = 0.01) -> list:
    """Spearman correlation of the normalised residual with every condition, per quantity
    (the strongest first, p < level only)."""
    out = []
    for q, name, rows, v, ok in _condition_tests(m):
        rho, p = stats.spearmanr(v[ok], r[rows][ok])
        if np.isfinite(rho) and p < level:
            out.append({"quantity": str(q), "variable": name, "spearman_rho": float(rho), "p": float(p)})
    return sorted(out, key=lambda d: d["p"])[:top]
