"""Stability limits under uncertain host dynamics: Latin-hypercube Monte Carlo (seed 002 section 4).

The host mode's stiffness K, natural frequency f_n and damping ratio zeta are drawn normally
(seed 002 Table 3: means from the identification, standard deviations 20 % of K, 1 % of f_n and
20 % of zeta) by Latin-hypercube sampling (scipy.stats.qmc, the inverse normal CDF on each
stratum). The absorber stays what it was tuned to be for the nominal host (its physical mass,
springs, damper and inerter do not know the host changed):

    m = mu M0, k_o = m (gamma w0)^2, c = 2 zeta_a m gamma w0, b = delta m, k_i = b (eta gamma w0)^2,
    G(s) = 1 / (M s^2 + C s + K + m s^2 Z(s) / (m s^2 + Z(s)))   (absorber.tuning, seed 002 eq. 16)

with Z the layout's impedance in physical units (Z~ of `Tuning.impedance` at s / w0, times
M0 w0^2). Every sample's stability limit at a spindle speed comes from the zeroth-order
approximation for a structure flexible in y only, nu = G(i w) H0_yy (seed 002 eq. 12,
posedyn.stability.zoa), on a chatter-frequency grid dense around the host and absorber modes.
Per speed: mean, std, coefficient of variation, the lower bound of the 95 % interval
mean - 1.96 std (seed 002 Figs. 7-8, the normal interval the seed draws; floored at 0, a depth
nobody can count on) and the empirical 5 % quantile (the honest figure where the distribution
is skewed, near lobe peaks).

The actuator force of a virtual absorber (seed 002 section 5): F_a / F of eq. 20 at the
harmonics of the tooth-passing frequency, times the harmonics of the steady cutting force at the
guaranteed depth, summed (a bound on the force's peak); per speed the upper end of its 95 %
interval over the samples and its ratio to the nominal host's (the seed's Fig. 12: about 1.5x in
the absolute-stability region, up to 2.5x in the lobing region).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize
from scipy.stats import norm, qmc

from absorber.coupling import with_absorber
from absorber.tuning import BOUNDS, Host, Tuning
from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError, check_choice, check_positive
from posedyn.stability import critical_points
from posedyn.stability.cutting import Cut, force_matrix, mean_force_matrix
from posedyn.stability.zoa import branches_from_eigenvalues, depth_at_speed
from posedyn.table import Mode

#: Two-sided 95 % normal interval: mean -+ 1.96 std.
Z95 = float(norm.ppf(0.975))


@dataclass(frozen=True)
class HostUncertainty:
    """Normal distributions of the host mode: the nominal host and relative standard deviations
    (seed 002 Table 3: 0.2, 0.01, 0.2)."""

    nominal: Host
    k_rel_std: float = 0.2
    fn_rel_std: float = 0.01
    zeta_rel_std: float = 0.2

    def __post_init__(self):
        for name in ("k_rel_std", "fn_rel_std", "zeta_rel_std"):
            value = getattr(self, name)
            if not 0.0 <= value < 0.5:
                raise InputError("a relative standard deviation in [0, 0.5)", got=value, column=name)

    def sample(self, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(k_n_per_m, fn_hz, zeta) of n Latin-hypercube samples; draws beyond 4.5 std, which
        would give a negative stiffness or damping at these spreads, are clipped there."""
        check_positive("samples", n)
        u = qmc.LatinHypercube(d=3, seed=seed).random(n)
        z = np.clip(norm.ppf(u), -4.5, 4.5)
        h = self.nominal
        return (h.k_n_per_m * (1.0 + self.k_rel_std * z[:, 0]), h.fn_hz * (1.0 + self.fn_rel_std * z[:, 1]), h.zeta * (1.0 + self.zeta_rel_std * z[:, 2]))


def chatter_grid(host: Host, points: int = 1500) -> np.ndarray:
    """Chatter frequencies (rad/s): 0.3-3 w0 on a log grid, dense over 0.6-1.6 w0 where the host
    and the absorber modes lie (about 20 points per half-power band at zeta = 1.3 %; 6,000
    points change seed 002's 2700 rpm limits by less than 0.03 %)."""
    w0 = 2.0 * math.pi * host.fn_hz
    return np.unique(np.concatenate([np.geomspace(0.3 * w0, 3.0 * w0, points // 3), np.linspace(0.6 * w0, 1.6 * w0, points)]))


def _host_and_absorber(k, fn, zeta, omega, tuning: Tuning | None, nominal: Host):
    """(host dynamic stiffness M s^2 + C s + K, the absorber's dynamic stiffness
    m s^2 Z / (m s^2 + Z) or 0), shapes (samples, len(omega))."""
    k, fn, zeta = (np.asarray(v, dtype=float)[:, None] for v in (k, fn, zeta))
    wn = 2.0 * math.pi * fn
    mass = k / wn**2
    s = 1j * np.asarray(omega, dtype=float)[None, :]
    host = mass * s**2 + 2.0 * zeta * np.sqrt(k * mass) * s + k
    if tuning is None:
        return host, np.zeros_like(host)
    w0 = 2.0 * math.pi * nominal.fn_hz
    z = nominal.mass_kg * w0**2 * tuning.impedance(s / w0)  # Z = M0 w0^2 Z~(s / w0)
    m = tuning.mass_ratio * nominal.mass_kg
    return host, m * s**2 * z / (m * s**2 + z)


def receptance(k: np.ndarray, fn: np.ndarray, zeta: np.ndarray, omega: np.ndarray, tuning: Tuning | None, nominal: Host) -> np.ndarray:
    """G(i w) (m/N) of hosts (k, fn, zeta), shape (samples, len(omega)), with the absorber tuned
    for `nominal` (None: no absorber)."""
    host, absorber = _host_and_absorber(k, fn, zeta, omega, tuning, nominal)
    return 1.0 / (host + absorber)


def actuator_force_frf(k: np.ndarray, fn: np.ndarray, zeta: np.ndarray, omega: np.ndarray, tuning: Tuning, nominal: Host) -> np.ndarray:
    """F_a / F (i w), the force the (virtual) absorber applies to the host per unit cutting force
    (seed 002 eq. 20), shape (samples, len(omega)):

        F_a / F = -L m s^2 / ((M s^2 + C s + K + L)(m s^2 + L) - L^2) = -(m s^2 L / (m s^2 + L)) G,

    the absorber's dynamic stiffness times the host's displacement (L = Z, the layout's
    impedance)."""
    host, absorber = _host_and_absorber(k, fn, zeta, omega, tuning, nominal)
    return -absorber / (host + absorber)


def cutting_force_harmonics(cut: Cut, feed_per_tooth_m: float, harmonics: int = 64) -> np.ndarray:
    """Single-sided amplitudes (N per m of depth) of the harmonics k = 1..`harmonics` of the
    tooth-passing frequency in the steady y cutting force, straight flutes: F = a H(phi) (f_t, 0)
    (the chip h = f_t sin phi of a feed f_t along x; posedyn.stability.cutting's H)."""
    check_positive("feed_per_tooth_m", feed_per_tooth_m)
    samples = max(4096, 8 * harmonics)
    phi = np.arange(samples) * (2.0 * math.pi / cut.teeth) / samples
    force = feed_per_tooth_m * force_matrix(cut, phi)[:, 1, 0]
    return 2.0 * np.abs(np.fft.rfft(force)[1 : harmonics + 1]) / samples


@dataclass(frozen=True)
class LimitStatistics:
    """Stability limit statistics at each spindle speed (depths in m), and the actuator force
    per m of depth (N/m: the upper end of its 95 % interval over the samples and the nominal
    host's; NaN without an absorber or a feed) summed over the tooth-passing harmonics."""

    rpm: np.ndarray
    mean_m: np.ndarray
    std_m: np.ndarray
    q05_m: np.ndarray
    nominal_m: np.ndarray
    force_upper95_n_per_m: np.ndarray
    force_nominal_n_per_m: np.ndarray
    method: tuple = ()  # per speed: "zoa", "sdm<steps>" or "engine"
    zoa_deviation: np.ndarray | None = None  # per speed: the nominal structure's zeroth-order limit / the engine's - 1 (NaN: not checked)

    @property
    def cv(self) -> np.ndarray:
        return self.std_m / self.mean_m

    @property
    def lower95_m(self) -> np.ndarray:
        return np.maximum(self.mean_m - Z95 * self.std_m, 0.0)

    @property
    def force_upper95_n(self) -> np.ndarray:
        """The actuator force (N, peak bound) the uncertainty can demand when cutting at the
        guaranteed depth: the upper end of its 95 % interval (seed 002 Fig. 12)."""
        return self.force_upper95_n_per_m * self.lower95_m

    @property
    def force_ratio(self) -> np.ndarray:
        """That force over the nominal host's at the same depth (seed 002 Fig. 12's F_a / F_a,ideal)."""
        return self.force_upper95_n_per_m / self.force_nominal_n_per_m


def _force_per_depth(k, fn, zeta, tuning: Tuning, nominal: Host, teeth: int, rpm: float, harmonics: np.ndarray) -> np.ndarray:
    """sum_k |F_a / F (i k w_T)| |F_k| per m of depth for every sample: a bound on the peak of the
    steady actuator force (the static force's k = 0 term gives none: F_a / F (0) = 0)."""
    omega = 2.0 * math.pi * rpm / 60.0 * teeth * np.arange(1, len(harmonics) + 1)
    return np.abs(actuator_force_frf(k, fn, zeta, omega, tuning, nominal)) @ harmonics


#: A cheaper method is trusted at a speed where it gives the nominal structure's limit within
#: this of the converged engine (`method="auto"`).
METHOD_TOLERANCE = 0.02
#: The semi-discretization's steps per delay tried after the zeroth order, cheapest first.
SDM_STEPS = (40, 80, 160)
METHODS = ("auto", "zoa", "engine")


def engine_structures(k, fn, zeta, tuning: Tuning | None, nominal: Host) -> list[ToolTipDynamics] | None:
    """Hosts (k, fn, zeta) flexible in y, with the TMD tuned for `nominal` coupled as an extra
    degree of freedom, for the converged engine; None for the inerter layouts (their inerter
    networks have massless internal nodes, which a modal model of the structure does not hold)."""
    if tuning is not None and tuning.layout != "tmd":
        return None
    hosts = [ToolTipDynamics.from_modes(y=[Mode(float(f), float(z), float(kk))]) for kk, f, z in zip(k, fn, zeta)]
    if tuning is None:
        return hosts
    m = tuning.mass_ratio * nominal.mass_kg
    k_o = m * (tuning.gamma * 2.0 * math.pi * nominal.fn_hz) ** 2
    return [with_absorber(h, m, k_o, tuning.zeta_a, directions=("y",)) for h in hosts]


def monte_carlo_limits(uncertainty: HostUncertainty, tuning: Tuning | None, cut: Cut, rpm, samples: int = 500, seed: int = 0,
                       force_harmonics: np.ndarray | None = None, method: str = "auto") -> LimitStatistics:
    """The stability limit of every sample at every speed, summarised per speed; with an absorber
    and the cut's force harmonics (`cutting_force_harmonics`), the actuator force too.

    `method`: "zoa" the zeroth-order approximation (seed 002's eq. 12, vectorised over the
    samples) at every speed; "engine" the converged engine (`posedyn.stability.critical_points`,
    verified) at every speed; "auto", per speed, the cheapest of the zeroth order and the
    semi-discretization at SDM_STEPS that gives the nominal structure's limit within
    METHOD_TOLERANCE of the engine's, else the engine (the zeroth order misses lobe peaks and
    flip lobes by 5-50 % on seed 002's host). Where the engine does not converge on the nominal
    structure, the finest semi-discretization stands in for it. The inerter layouts have no engine model (their
    networks have massless internal nodes): zeroth order at every speed, `zoa_deviation` NaN."""
    check_choice("method", method, METHODS)
    h_yy = mean_force_matrix(cut)[1, 1]
    nominal = uncertainty.nominal
    omega = chatter_grid(nominal)
    k, fn, zeta = uncertainty.sample(samples, seed)
    b = branches_from_eigenvalues(omega, (receptance(k, fn, zeta, omega, tuning, nominal) * h_yy)[:, None, :])
    b0 = branches_from_eigenvalues(omega, (receptance([nominal.k_n_per_m], [nominal.fn_hz], [nominal.zeta], omega, tuning, nominal) * h_yy)[:, None, :])
    rpm = np.atleast_1d(np.asarray(rpm, dtype=float))
    depths = np.array([depth_at_speed(b, cut.teeth, r) for r in rpm])  # (speeds, samples)
    nominal_m = np.array([depth_at_speed(b0, cut.teeth, r)[0] for r in rpm])
    used = np.array(["zoa"] * len(rpm), dtype=object)
    deviation = np.full(len(rpm), np.nan)
    one = engine_structures([nominal.k_n_per_m], [nominal.fn_hz], [nominal.zeta], tuning, nominal)
    if method != "zoa" and one is not None:
        results = critical_points(one * len(rpm), cut, rpm, frequencies=False)
        converged = np.array([r.depth_m for r in results])
        failed = np.flatnonzero([not r.converged for r in results])
        if len(failed):  # the engine could not answer there (a safeguard; seen at a flip-lobe peak before its repair was fixed): the finest semi-discretization is the reference
            converged[failed] = [r.depth_m for r in critical_points(one * len(failed), cut, rpm[failed], SDM_STEPS[-1], frequencies=False)]
        deviation = nominal_m / converged - 1.0
        todo = np.flatnonzero(~(np.abs(deviation) <= METHOD_TOLERANCE)) if method == "auto" else np.arange(len(rpm))
        structures = engine_structures(k, fn, zeta, tuning, nominal) if len(todo) else None
        for steps in SDM_STEPS if method == "auto" else ():
            if not len(todo):
                break
            sdm = np.array([r.depth_m for r in critical_points(one * len(todo), cut, rpm[todo], steps, frequencies=False)])
            good = todo[np.abs(sdm / converged[todo] - 1.0) <= METHOD_TOLERANCE]
            if len(good):
                results = critical_points(structures * len(good), cut, np.repeat(rpm[good], samples), steps, frequencies=False)
                depths[good] = np.array([r.depth_m for r in results]).reshape(len(good), samples)
                nominal_m[good] = sdm[np.isin(todo, good)]
                used[good] = f"sdm{steps}"
                todo = np.setdiff1d(todo, good)
        if len(todo):  # method "engine", or no cheaper method agrees (the engine then converged: its failures have the finest SDM agree)
            results = critical_points(structures * len(todo), cut, np.repeat(rpm[todo], samples), frequencies=False)
            depths[todo] = np.array([r.depth_m for r in results]).reshape(len(todo), samples)
            nominal_m[todo] = converged[todo]
            used[todo] = "engine"
    force_upper, force_nominal = np.full(len(rpm), np.nan), np.full(len(rpm), np.nan)
    if tuning is not None and force_harmonics is not None:
        for i, r in enumerate(rpm):
            per_sample = _force_per_depth(k, fn, zeta, tuning, nominal, cut.teeth, r, force_harmonics)
            force_upper[i] = per_sample.mean() + Z95 * per_sample.std(ddof=1)
            force_nominal[i] = _force_per_depth([nominal.k_n_per_m], [nominal.fn_hz], [nominal.zeta], tuning, nominal, cut.teeth, r, force_harmonics)[0]
    return LimitStatistics(rpm, depths.mean(axis=1), depths.std(axis=1, ddof=1), np.quantile(depths, 0.05, axis=1), nominal_m, force_upper, force_nominal,
                           tuple(used), deviation)


def robust_tuning(uncertainty: HostUncertainty, nominal: Tuning, cut: Cut, rpm, samples: int = 250, seed: int = 0, max_evaluations: int = 80,
                  force_harmonics: np.ndarray | None = None, force_limit_n: float | None = None) -> Tuning:
    """The absorber parameters that maximise the 95 % lower bound of the limit (its least over
    the speeds `rpm`) instead of the nominal host's limit (seed 002 eq. 18), starting from the
    nominal tuning. With an actuator force limit F_max (and the cut's force harmonics), the depth
    counted at a speed is min(lower bound, F_max / F95), F95 the upper end of the 95 % interval
    of the actuator force per m of depth: the depth the actuator can also deliver without
    saturating (seed 002 section 5). The same samples serve every candidate (common random
    numbers: the objective is smooth in the parameters); Nelder-Mead on the logarithms of the
    layout's dimensionless parameters (gamma, zeta_a, delta, eta), kept inside
    absorber.tuning.BOUNDS."""
    names = ["gamma", "zeta_a"] + ([] if nominal.layout == "tmd" else ["delta", "eta"])
    h_yy = mean_force_matrix(cut)[1, 1]
    omega = chatter_grid(uncertainty.nominal)
    k, fn, zeta = uncertainty.sample(samples, seed)
    speeds = np.atleast_1d(np.asarray(rpm, dtype=float))
    limited = force_limit_n is not None and force_harmonics is not None

    def make(x) -> Tuning:
        values = {n: float(np.clip(np.exp(v), *BOUNDS[n])) for n, v in zip(names, x)}
        return Tuning(nominal.layout, nominal.mass_ratio, values["gamma"], values["zeta_a"], values.get("delta"), values.get("eta"))

    def guaranteed(tuning: Tuning) -> float:
        b = branches_from_eigenvalues(omega, (receptance(k, fn, zeta, omega, tuning, uncertainty.nominal) * h_yy)[:, None, :])
        depths = np.array([depth_at_speed(b, cut.teeth, r) for r in speeds])
        lower = depths.mean(axis=1) - Z95 * depths.std(axis=1, ddof=1)
        if limited:
            for i, r in enumerate(speeds):
                per_m = _force_per_depth(k, fn, zeta, tuning, uncertainty.nominal, cut.teeth, r, force_harmonics)
                lower[i] = min(lower[i], force_limit_n / (per_m.mean() + Z95 * per_m.std(ddof=1)))
        return float(np.min(lower))

    x0 = np.log([getattr(nominal, n) for n in names])
    result = minimize(lambda x: -guaranteed(make(x)), x0, method="Nelder-Mead", options={"maxfev": max_evaluations, "xatol": 1e-4, "fatol": 1e-9})
    best = make(result.x)
    return best if guaranteed(best) > guaranteed(nominal) else nominal
