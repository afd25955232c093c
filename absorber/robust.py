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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize
from scipy.stats import norm, qmc

from absorber.tuning import BOUNDS, Host, Tuning
from posedyn.errors import InputError, check_positive
from posedyn.stability.cutting import Cut, mean_force_matrix
from posedyn.stability.zoa import branches_from_eigenvalues, depth_at_speed

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


def receptance(k: np.ndarray, fn: np.ndarray, zeta: np.ndarray, omega: np.ndarray, tuning: Tuning | None, nominal: Host) -> np.ndarray:
    """G(i w) (m/N) of hosts (k, fn, zeta), shape (samples, len(omega)), with the absorber tuned
    for `nominal` (None: no absorber)."""
    k, fn, zeta = (np.asarray(v, dtype=float)[:, None] for v in (k, fn, zeta))
    wn = 2.0 * math.pi * fn
    mass = k / wn**2
    s = 1j * np.asarray(omega, dtype=float)[None, :]
    dyn = mass * s**2 + 2.0 * zeta * np.sqrt(k * mass) * s + k
    if tuning is not None:
        w0 = 2.0 * math.pi * nominal.fn_hz
        scale = nominal.mass_kg * w0**2  # Z = M0 w0^2 Z~(s / w0)
        z = scale * tuning.impedance(s / w0)
        m = tuning.mass_ratio * nominal.mass_kg
        dyn = dyn + m * s**2 * z / (m * s**2 + z)
    return 1.0 / dyn


@dataclass(frozen=True)
class LimitStatistics:
    """Stability limit statistics at each spindle speed (depths in m)."""

    rpm: np.ndarray
    mean_m: np.ndarray
    std_m: np.ndarray
    q05_m: np.ndarray
    nominal_m: np.ndarray

    @property
    def cv(self) -> np.ndarray:
        return self.std_m / self.mean_m

    @property
    def lower95_m(self) -> np.ndarray:
        return np.maximum(self.mean_m - Z95 * self.std_m, 0.0)


def monte_carlo_limits(uncertainty: HostUncertainty, tuning: Tuning | None, cut: Cut, rpm, samples: int = 500, seed: int = 0) -> LimitStatistics:
    """The stability limit of every sample at every speed, summarised per speed."""
    h_yy = mean_force_matrix(cut)[1, 1]
    nominal = uncertainty.nominal
    omega = chatter_grid(nominal)
    k, fn, zeta = uncertainty.sample(samples, seed)
    b = branches_from_eigenvalues(omega, (receptance(k, fn, zeta, omega, tuning, nominal) * h_yy)[:, None, :])
    b0 = branches_from_eigenvalues(omega, (receptance([nominal.k_n_per_m], [nominal.fn_hz], [nominal.zeta], omega, tuning, nominal) * h_yy)[:, None, :])
    rpm = np.atleast_1d(np.asarray(rpm, dtype=float))
    depths = np.array([depth_at_speed(b, cut.teeth, r) for r in rpm])  # (speeds, samples)
    nominal_m = np.array([depth_at_speed(b0, cut.teeth, r)[0] for r in rpm])
    return LimitStatistics(rpm, depths.mean(axis=1), depths.std(axis=1, ddof=1), np.quantile(depths, 0.05, axis=1), nominal_m)


def robust_tuning(uncertainty: HostUncertainty, nominal: Tuning, cut: Cut, rpm, samples: int = 250, seed: int = 0, max_evaluations: int = 80) -> Tuning:
    """The absorber parameters that maximise the 95 % lower bound of the limit (its least over
    the speeds `rpm`) instead of the nominal host's limit (seed 002 eq. 18), starting from the
    nominal tuning. The same samples serve every candidate (common random numbers: the
    objective is smooth in the parameters); Nelder-Mead on the logarithms of the layout's
    dimensionless parameters (gamma, zeta_a, delta, eta), kept inside absorber.tuning.BOUNDS."""
    names = ["gamma", "zeta_a"] + ([] if nominal.layout == "tmd" else ["delta", "eta"])
    h_yy = mean_force_matrix(cut)[1, 1]
    omega = chatter_grid(uncertainty.nominal)
    k, fn, zeta = uncertainty.sample(samples, seed)
    speeds = np.atleast_1d(np.asarray(rpm, dtype=float))

    def make(x) -> Tuning:
        values = {n: float(np.clip(np.exp(v), *BOUNDS[n])) for n, v in zip(names, x)}
        return Tuning(nominal.layout, nominal.mass_ratio, values["gamma"], values["zeta_a"], values.get("delta"), values.get("eta"))

    def lower_bound(tuning: Tuning) -> float:
        b = branches_from_eigenvalues(omega, (receptance(k, fn, zeta, omega, tuning, uncertainty.nominal) * h_yy)[:, None, :])
        depths = np.array([depth_at_speed(b, cut.teeth, r) for r in speeds])
        return float(np.min(depths.mean(axis=1) - Z95 * depths.std(axis=1, ddof=1)))

    x0 = np.log([getattr(nominal, n) for n in names])
    result = minimize(lambda x: -lower_bound(make(x)), x0, method="Nelder-Mead", options={"maxfev": max_evaluations, "xatol": 1e-4, "fatol": 1e-9})
    best = make(result.x)
    return best if lower_bound(best) > lower_bound(nominal) else nominal
