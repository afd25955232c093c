"""Absorber tuning: passive TMD and inerter-based IDVA layouts (seed 002 section 2.2 and
Appendix A) on a host mode, and the target-frequency policies.

Host mode (M, C, K) with an absorber mass m = mu M joined to it through an impedance Z(s):

    TMD:  Z = k_o + c s
    C3:   Z = k_o + b c k_i s^2 / (b c s^2 + (b s + c) k_i)
    C4:   Z = k_o + b (c s + k_i) s^2 / (b s^2 + c s + k_i)
    C5:   Z = k_o + (b s^2 + k_i) c s / (b s^2 + c s + k_i)
    C6:   Z = k_o + (b s + c) k_i s / (b s^2 + c s + k_i)

The absorber mass obeys m s^2 Y_a = Z (Y - Y_a), so the host sees the dynamic stiffness
m s^2 Z / (m s^2 + Z) and

    G(s) = 1 / (M s^2 + C s + K + m s^2 Z / (m s^2 + Z)),

which is seed 002 eq. 16 with L(s) the absorber's dynamic stiffness; with M = K = 1 it equals
the seed's non-dimensional R, I polynomials of Appendix A (those are printed for zeta_m = 0; the
host damping is kept here, as the seed's optimisation does). Non-dimensional parameters (seed
002): gamma = w_m / w_n, zeta_a = c / (2 sqrt(m k_o)), delta = b / m, eta = w_b / w_m,
w_m = sqrt(k_o / m), w_b = sqrt(k_i / b), lambda = w / w_n.

Tuning policies:
- `sims` (seed 002 eq. 18): maximise over the parameters the minimum over lambda of Re G~, the
  most negative real part of K G, which sets the absolute stability limit a_lim = 1 / (2 h (-min
  Re G)) of a mode cut with mean directional coefficient h > 0. Global optimiser: scipy's
  differential evolution (seeded) then a local polish; checked in the tests against a brute-force
  grid for the TMD and against the equal-trough property of the optimum.
- `den-hartog`: equal peaks of |G| (Den Hartog's fixed points), closed form for the TMD:
  gamma = 1 / (1 + mu), zeta_a = sqrt(3 mu / (8 (1 + mu)^3)).
- `match`: absorber frequency = the dominant chatter frequency (seed 004's policy).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import differential_evolution, minimize_scalar

from posedyn.errors import check_choice, check_open_interval, check_positive

LAYOUTS = ("tmd", "idva-c3", "idva-c4", "idva-c5", "idva-c6")
BOUNDS = {"gamma": (0.5, 1.5), "zeta_a": (1e-4, 1.0), "delta": (1e-3, 20.0), "eta": (0.05, 20.0)}


@dataclass(frozen=True)
class Host:
    """The host mode: natural frequency, modal stiffness, damping ratio."""

    fn_hz: float
    k_n_per_m: float
    zeta: float

    def __post_init__(self):
        check_positive("fn_hz", self.fn_hz)
        check_positive("k_n_per_m", self.k_n_per_m)
        check_open_interval("zeta", self.zeta, 0.0, 1.0)

    @property
    def mass_kg(self) -> float:
        return self.k_n_per_m / (2 * math.pi * self.fn_hz) ** 2


@dataclass(frozen=True)
class Tuning:
    layout: str
    mass_ratio: float
    gamma: float
    zeta_a: float
    delta: float | None = None
    eta: float | None = None

    def impedance(self, s: np.ndarray) -> np.ndarray:
        """Z(s) for a host with M = 1, w_n = 1 (non-dimensional s = i lambda)."""
        num, den = self._impedance_parts(s, s * s)
        return num / den

    def _impedance_parts(self, s: np.ndarray, s2: np.ndarray):
        """Z(s) = num / den, polynomials in s (den = 1 for the TMD); s2 = s * s."""
        m = self.mass_ratio
        ko = m * self.gamma**2
        c = 2.0 * self.zeta_a * m * self.gamma
        if self.layout == "tmd":
            return ko + c * s, np.ones_like(s)
        b = self.delta * m
        ki = b * (self.eta * self.gamma) ** 2
        if self.layout == "idva-c3":
            den = b * c * s2 + (b * s + c) * ki
            return ko * den + b * c * ki * s2, den
        den = b * s2 + c * s + ki
        if self.layout == "idva-c4":
            return ko * den + b * (c * s + ki) * s2, den
        if self.layout == "idva-c5":
            return ko * den + (b * s2 + ki) * c * s, den
        return ko * den + (b * s + c) * ki * s, den

    def receptance(self, lam: np.ndarray, zeta_m: float) -> np.ndarray:
        """G~ = K G at lambda = w / w_n (seed 002 eq. 17), as one quotient of polynomials: with
        Z = num / den, m s^2 Z / (m s^2 + Z) = m s^2 num / (m s^2 den + num) and
        G~ = (m s^2 den + num) / ((s^2 + 2 zeta_m s + 1)(m s^2 den + num) + m s^2 num) (one complex
        division instead of four: the tuning's objective evaluates it tens of thousands of times)."""
        s = 1j * np.asarray(lam, dtype=float)
        s2 = s * s
        num, den = self._impedance_parts(s, s2)
        ms2 = self.mass_ratio * s2
        inner = ms2 * den + num
        return inner / ((s2 + 2.0 * zeta_m * s + 1.0) * inner + ms2 * num)


def min_real_part(tuning: Tuning, zeta_m: float, grid: np.ndarray | None = None) -> float:
    """min over lambda of Re G~: a dense grid, then a bounded scalar refinement."""
    lam = np.linspace(0.3, 2.0, 3401) if grid is None else grid
    values = tuning.receptance(lam, zeta_m).real
    i = int(np.argmin(values))
    lo, hi = lam[max(i - 1, 0)], lam[min(i + 1, len(lam) - 1)]
    refined = minimize_scalar(lambda x: tuning.receptance(np.array([x]), zeta_m).real[0], bounds=(lo, hi), method="bounded", options={"xatol": 1e-10})
    return float(min(values[i], refined.fun))


def uncontrolled_min_real_part(zeta_m: float) -> float:
    """-1 / (4 zeta (1 + zeta)): the most negative real part of a single mode's K G."""
    return -1.0 / (4.0 * zeta_m * (1.0 + zeta_m))


_TUNED: dict[tuple, Tuning] = {}  # (layout, mass_ratio, zeta_m, seed) -> the optimum


def tune_sims(layout: str, mass_ratio: float, zeta_m: float, seed: int = 0) -> Tuning:
    """Maximise min Re G~ over the layout's parameters (seed 002 eq. 18). Deterministic for a
    seed, so each optimum is kept (`known_tunings`, `remember_tunings`: a differential evolution
    takes seconds; the service keeps them across restarts)."""
    check_choice("layout", layout, LAYOUTS)
    check_positive("mass_ratio", mass_ratio)
    key = (layout, float(mass_ratio), float(zeta_m), int(seed))
    if key not in _TUNED:
        _TUNED[key] = _differential_evolution(layout, mass_ratio, zeta_m, seed)
    return _TUNED[key]


def known_tunings() -> list[dict]:
    """Every optimum computed or remembered in this process, as JSON-ready rows."""
    return [{"zeta_m": z, "seed": seed, **asdict(t)} for (_, _, z, seed), t in list(_TUNED.items())]


def remember_tunings(rows: list[dict]) -> int:
    """Take optima computed elsewhere (rows of `known_tunings`); returns how many were new.
    A row that does not describe a tuning raises ValueError / KeyError / TypeError."""
    new = 0
    for row in rows:
        tuning = Tuning(str(row["layout"]), float(row["mass_ratio"]), float(row["gamma"]), float(row["zeta_a"]),
                        None if row["delta"] is None else float(row["delta"]), None if row["eta"] is None else float(row["eta"]))
        check_choice("layout", tuning.layout, LAYOUTS)
        key = (tuning.layout, tuning.mass_ratio, float(row["zeta_m"]), int(row["seed"]))
        if key not in _TUNED:
            _TUNED[key] = tuning
            new += 1
    return new


def _differential_evolution(layout: str, mass_ratio: float, zeta_m: float, seed: int) -> Tuning:
    names = ["gamma", "zeta_a"] + ([] if layout == "tmd" else ["delta", "eta"])
    grid = np.concatenate([np.linspace(0.3, 0.85, 400), np.linspace(0.85, 1.15, 3000), np.linspace(1.15, 2.0, 400)])

    def make(x):
        values = dict(zip(names, x))
        return Tuning(layout, mass_ratio, values["gamma"], values["zeta_a"], values.get("delta"), values.get("eta"))

    def objective(x):
        return -float(np.min(make(x).receptance(grid, zeta_m).real))

    result = differential_evolution(objective, [BOUNDS[n] for n in names], seed=seed, tol=1e-10, maxiter=3000, popsize=30, polish=True)
    return make(result.x)


def tune_den_hartog(mass_ratio: float) -> Tuning:
    """Equal-peak TMD (Den Hartog): gamma = 1 / (1 + mu), zeta_a = sqrt(3 mu / (8 (1 + mu)^3))."""
    check_positive("mass_ratio", mass_ratio)
    mu = mass_ratio
    return Tuning("tmd", mu, 1.0 / (1.0 + mu), math.sqrt(3.0 * mu / (8.0 * (1.0 + mu) ** 3)))


def absolute_limit_m(min_re_g_nondim: float, host: Host, h_mean_pa: float) -> float:
    """a_lim = 1 / (2 h (-min Re G)), G = G~ / K (seed 002 eq. 12 with h = -N Kt a_yy / (4 pi))."""
    if min_re_g_nondim >= 0:
        return math.inf
    return 1.0 / (2.0 * h_mean_pa * (-min_re_g_nondim / host.k_n_per_m))
