"""Active damping with an inertial actuator and direct velocity feedback (seed 000).

Actuator (seed 000 eqs. 2-3, Table 2): F / v = T s^2 exp(-t_a s) / (s^2 + 2 zeta w s + w^2).
Its natural frequency depends on how it hangs: 9 Hz with the axis horizontal, 14 Hz vertical.
Interpolation law used here: the suspension's tangent stiffness changes with the static preload
the moving mass puts on it, and to first order linearly in that preload, which is the weight's
component along the axis, m g |cos theta| (theta = angle between the actuator axis and gravity):

    w(theta)^2 = w_h^2 + (w_v^2 - w_h^2) |cos theta|,

exact at both ends of seed 000's two measurements, symmetric in up/down, smooth in between.

Controller (seed 000 eq. 8): velocity of the actuator location times K, through two 2nd-order
low-pass filters (50 Hz), a high-pass (4 Hz), a notch (3 Hz, bandwidth 4 Hz), the actuator and
the model-based compensator C1 = (s^2 + 2 zeta w s + w^2) / (s^2 + 2 zeta w_c s + w_c^2)
(eq. 4, w_c = 2 pi 0.5 rad/s) that flattens the actuator mode. With the open-loop path
F(s) = LPF^2 HPF NF C1 (s^2 e^(-t_a s) / (s^2 + 2 zeta w s + w^2)) the actuator pushes
-K s F y2 on location 2, so

    y2 / F2 = H22 / (1 + K s F H22),
    y1 / F1 = H11 - H12 H21 K s F / (1 + K s F H22)        (seed 000 eq. 9)

and the closed-loop poles are the roots of 1 + K s F(s) H22(s) = 0 (eq. 10), the delay by a
Pade approximant. Robot FRFs come in seed 000's residue form (eq. 1) or from modal parameters.
"""

from __future__ import annotations

import math
from functools import lru_cache
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from absorber.tuning import LAYOUTS, min_real_part, tune_sims
from posedyn.errors import InputError, check_choice, check_non_negative, check_positive
from posedyn.robot import pose_rotation

if TYPE_CHECKING:
    import control


def _tf():
    """python-control's transfer-function constructor, imported on first use."""
    import control  # heavy: it imports scipy.signal and matplotlib.pyplot, ~1.8 s of every command's start; only the controller design needs it

    return control.tf


def _pade(delay_s: float, order: int):
    import control  # heavy, as in _tf

    return control.pade(delay_s, order)


@dataclass(frozen=True)
class Actuator:
    """Inertial actuator (seed 000 Table 2 defaults): T (N/V), damping, natural frequencies
    horizontal / vertical, delay, force limit."""

    transducer_n_per_v: float = 4.8
    zeta: float = 0.15
    fn_horizontal_hz: float = 9.0
    fn_vertical_hz: float = 14.0
    delay_s: float = 0.6e-3
    force_limit_n: float = 36.0

    def __post_init__(self):
        for name in ("transducer_n_per_v", "zeta", "fn_horizontal_hz", "fn_vertical_hz", "force_limit_n"):
            check_positive(name, getattr(self, name))
        check_non_negative("delay_s", self.delay_s)

    def fn_hz(self, angle_to_gravity_rad: float) -> float:
        """w(theta)^2 = w_h^2 + (w_v^2 - w_h^2) |cos theta| (see the module docstring)."""
        c = abs(math.cos(angle_to_gravity_rad))
        return math.sqrt(self.fn_horizontal_hz**2 + (self.fn_vertical_hz**2 - self.fn_horizontal_hz**2) * c)


@dataclass(frozen=True)
class Filters:
    """Seed 000 section 5: LPF 50 Hz (x2, zeta 0.707), HPF 4 Hz, notch 3 Hz with a 4 Hz bandwidth,
    compensator cut frequency 0.5 Hz."""

    lpf_hz: float = 50.0
    lpf_count: int = 2
    hpf_hz: float = 4.0
    filter_zeta: float = 0.707
    notch_hz: float = 3.0
    notch_bandwidth_hz: float = 4.0
    compensator_hz: float = 0.5


def residue_frf(modes) -> control.TransferFunction:
    """H(s) = sum_k (alpha_k + beta_k s) / (s^2 + 2 zeta_k w_k s + w_k^2), alpha = 2 (zeta w s_re - w_d s_im),
    beta = 2 s_re (seed 000 eq. 1); `modes` is a list of (fn_hz, zeta, sigma_re, sigma_im)."""
    tf = _tf()
    total = tf([0.0], [1.0])
    for fn, zeta, s_re, s_im in modes:
        w = 2 * math.pi * fn
        wd = w * math.sqrt(1 - zeta**2)
        alpha = 2 * (zeta * w * s_re - wd * s_im)
        beta = 2 * s_re
        total = total + tf([beta, alpha], [1.0, 2 * zeta * w, w * w])
    return total


def modal_frf(modes) -> control.TransferFunction:
    """A direct receptance from modal parameters: sum 1 / (m (s^2 + 2 zeta w s + w^2)); `modes`
    is a list of (fn_hz, zeta, k_n_per_m)."""
    tf = _tf()
    total = tf([0.0], [1.0])
    for fn, zeta, k in modes:
        w = 2 * math.pi * fn
        total = total + tf([w * w / k], [1.0, 2 * zeta * w, w * w])
    return total


@lru_cache(maxsize=256)
def path(actuator: Actuator, fn_act_hz: float, filters: Filters = Filters(), pade_order: int | None = None, fn_compensator_hz: float | None = None):
    """F(s) without s K and without the delay, unless `pade_order` folds a Pade approximant of it
    in. The compensator C1 is designed for `fn_compensator_hz` (default: the actuator's own
    frequency, i.e. perfectly matched)."""
    two_pi = 2 * math.pi
    wa = two_pi * fn_act_hz
    wd = two_pi * (fn_compensator_hz or fn_act_hz)
    z = filters.filter_zeta
    lp = two_pi * filters.lpf_hz
    hp = two_pi * filters.hpf_hz
    wn = two_pi * filters.notch_hz
    wc = two_pi * filters.compensator_hz
    tf = _tf()
    F = tf([1.0], [1.0])
    for _ in range(filters.lpf_count):
        F = F * tf([lp * lp], [1.0, 2 * z * lp, lp * lp])
    F = F * tf([1.0, 0.0, 0.0], [1.0, 2 * z * hp, hp * hp])
    F = F * tf([1.0, 0.0, wn * wn], [1.0, two_pi * filters.notch_bandwidth_hz, wn * wn])
    compensator = tf([1.0, 2 * actuator.zeta * wd, wd * wd], [1.0, 2 * actuator.zeta * wc, wc * wc])
    act = tf([1.0, 0.0, 0.0], [1.0, 2 * actuator.zeta * wa, wa * wa])
    F = F * compensator * act
    if pade_order:
        num, den = _pade(actuator.delay_s, pade_order)
        F = F * tf(num, den)
    return F


@dataclass(frozen=True)
class DVF:
    """A direct-velocity-feedback loop on a structure: H11, H12 = H21, H22 and the controller path."""

    h11: control.TransferFunction
    h21: control.TransferFunction
    h22: control.TransferFunction
    actuator: Actuator = field(default_factory=Actuator)
    fn_act_hz: float = 9.0
    filters: Filters = field(default_factory=Filters)
    fn_compensator_hz: float | None = None

    def _path_frf(self, omega):
        F = path(self.actuator, self.fn_act_hz, self.filters, fn_compensator_hz=self.fn_compensator_hz)
        return F(1j * omega) * np.exp(-1j * omega * self.actuator.delay_s)

    def closed_loop_frf(self, gain_ns_per_m, omega: np.ndarray, where: str = "22") -> np.ndarray:
        """Closed-loop receptance at 22 or 11 over omega (a column of gains gives one row each)."""
        s = 1j * omega
        loop = gain_ns_per_m * s * self._path_frf(omega)
        h22 = self.h22(s)
        if where == "22":
            return h22 / (1 + loop * h22)
        h21 = self.h21(s)
        return self.h11(s) - h21 * h21 * loop / (1 + loop * h22)

    def open_loop_frf(self, omega: np.ndarray, where: str = "22") -> np.ndarray:
        return (self.h22 if where == "22" else self.h11)(1j * omega)

    def poles(self, gain_ns_per_m: float, pade_order: int = 3) -> np.ndarray:
        """Roots of 1 + K s F(s) H22(s) = 0 (delay by a Pade approximant)."""
        F = path(self.actuator, self.fn_act_hz, self.filters, pade_order, self.fn_compensator_hz)
        loop = gain_ns_per_m * _tf()([1.0, 0.0], [1.0]) * F * self.h22
        num = np.atleast_1d(np.squeeze(loop.num[0][0]))
        den = np.atleast_1d(np.squeeze(loop.den[0][0]))
        size = max(len(num), len(den))
        return np.roots(np.pad(den, (size - len(den), 0)) + np.pad(num, (size - len(num), 0)))

    def open_loop_stable(self) -> bool:
        """Every pole of the controller path and of H22 in the left half plane (the Nyquist
        gain limit assumes it)."""
        F = path(self.actuator, self.fn_act_hz, self.filters, None, self.fn_compensator_hz)
        return all(np.max(np.roots(np.squeeze(tf.den[0][0])).real, initial=-np.inf) < 0 for tf in (F, self.h22))

    def stable(self, gain_ns_per_m: float) -> bool:
        return bool(np.max(self.poles(gain_ns_per_m).real) < 0)

    def max_stable_gain(self, upper: float = 1e6, tol: float = 1e-4) -> float:
        """The largest K with every closed-loop pole in the left half plane (first loss of
        stability, by doubling then bisection)."""
        if not self.stable(1e-9):
            return 0.0
        lo, hi = 0.0, 100.0
        while self.stable(hi):
            lo, hi = hi, 2 * hi
            if hi > upper:
                return math.inf
        while hi - lo > tol * hi:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self.stable(mid) else (lo, mid)
        return lo

    def nyquist_gain_limit(self, fmax_hz: float = 2000.0, points: int = 6000) -> float:
        """The same first loss of stability from the Nyquist criterion with the exact delay: the
        loop per unit gain L(jw) = jw F(jw) H22(jw) exp(-jw T) is open-loop stable, so the
        smallest K that puts K L(jw) on -1 is min 1 / |L| over the phase crossovers (Im L = 0,
        Re L < 0), located on a log grid and refined linearly. Inf when L never crosses."""
        omega = 2 * math.pi * np.geomspace(0.05, fmax_hz, points)
        L = 1j * omega * self._path_frf(omega) * self.h22(1j * omega)
        i = np.flatnonzero((np.sign(L.imag[:-1]) != np.sign(L.imag[1:])) & (L.real[:-1] + L.real[1:] < 0))
        if not len(i):
            return math.inf
        t = L.imag[i] / (L.imag[i] - L.imag[i + 1])
        crossing = L.real[i] + t * (L.real[i + 1] - L.real[i])
        return float(np.min(-1.0 / crossing))

    def stiffness_improvement_pct(self, gain_ns_per_m, fn_hz: float, where: str = "22", band: float = 0.25):
        """Dynamic-stiffness improvement at a mode: (max |H_open| / max |H_closed| - 1) 100 over
        fn (1 +- band); `gain_ns_per_m` may be an array of gains."""
        omega = 2 * math.pi * np.linspace(fn_hz * (1 - band), fn_hz * (1 + band), 801)
        gains = np.atleast_1d(np.asarray(gain_ns_per_m, dtype=float))
        open_ = np.abs(self.open_loop_frf(omega, where)).max()
        closed = np.array([np.abs(c).max() for c in self.closed_loop_frf(gains[:, None], omega, where)])
        out = (open_ / closed - 1.0) * 100.0
        return float(out[0]) if np.ndim(gain_ns_per_m) == 0 else out

    def max_force_n(self, gain_ns_per_m, disturbance_n: float, fmax_hz: float = 200.0):
        """Largest actuator force amplitude for a harmonic force of `disturbance_n` at location 2,
        at any frequency up to fmax: |K s F H22 / (1 + K s F H22)| |F2| (N); `gain_ns_per_m` may
        be an array of gains."""
        omega = 2 * math.pi * np.geomspace(0.5, fmax_hz, 1500)
        unit = 1j * omega * self._path_frf(omega) * self.h22(1j * omega)
        gains = np.atleast_1d(np.asarray(gain_ns_per_m, dtype=float))[:, None]
        # |K U / (1 + K U)|^2 = K^2 |U|^2 / (1 + 2 K Re U + K^2 |U|^2): real arrays over gains x frequencies
        loop2 = gains**2 * (unit.real**2 + unit.imag**2)[None, :]
        out = np.sqrt(np.max(loop2 / (1.0 + 2.0 * gains * unit.real[None, :] + loop2), axis=1)) * disturbance_n
        return float(out[0]) if np.ndim(gain_ns_per_m) == 0 else out


def gain_schedule(loop: DVF, fn_hz: float, disturbance_n: float, margin_db: float = 6.0) -> dict:
    """The DVF gain that maximises the dynamic-stiffness improvement of the mode at fn_hz with a
    gain margin of at least `margin_db` and the actuator force within its limit. The stability
    limit is the Nyquist one (exact delay; `DVF.max_stable_gain` finds it from the closed-loop
    poles with a Pade delay, the independent check in the tests)."""
    k_max = loop.nyquist_gain_limit() if loop.open_loop_stable() else 0.0
    if not math.isfinite(k_max) or k_max <= 0:
        raise InputError(f"a velocity-feedback loop at {fn_hz:.4g} Hz that is stable at small gains and loses stability at some finite gain "
                         "(the actuator's delay_ms, fn_hz and zeta decide it)", got=k_max, column="actuator")
    cap = k_max / 10 ** (margin_db / 20)
    gains = np.linspace(cap / 40, cap, 40)
    forces = loop.max_force_n(gains, disturbance_n)
    ok = forces <= loop.actuator.force_limit_n
    if not ok.any():
        improvement, gain, force = 0.0, 0.0, 0.0
    else:
        improvements = np.where(ok, loop.stiffness_improvement_pct(gains, fn_hz), -np.inf)
        best = int(np.argmax(improvements))
        improvement, gain, force = float(improvements[best]), float(gains[best]), float(forces[best])
    return {
        "actuator_fn_hz": loop.fn_act_hz,
        "dvf_gain_ns_per_m": gain,
        "max_stable_gain_ns_per_m": float(k_max),
        "gain_margin_db": float(20 * math.log10(k_max / gain)) if gain > 0 else math.inf,
        "dynamic_stiffness_gain_pct": improvement,
        "max_force_n": force,
    }


# --- per-pose schedules ----------------------------------------------------------------------


@dataclass(frozen=True)
class ControlConfig:
    """What the cell has: the actuator, the tool-frame axis it is mounted along (x is the tool
    axis; the default y is perpendicular to it, on the spindle housing), the disturbance force
    the force check assumes, the required gain margin, and the virtual absorber to realise."""

    actuator: Actuator = field(default_factory=Actuator)
    filters: Filters = field(default_factory=Filters)
    mount_axis: str = "y"
    disturbance_n: float = 20.0
    margin_db: float = 6.0
    virtual_layout: str = "idva-c3"
    virtual_mass_ratio: float = 0.0055
    source: str | None = field(default=None, compare=False)  # the actuator file it was read from (named in errors)

    def __post_init__(self):
        check_choice("mount_axis", self.mount_axis, ("x", "y", "z"))
        check_positive("disturbance_n", self.disturbance_n)
        check_non_negative("margin_db", self.margin_db)
        check_choice("virtual_layout", self.virtual_layout, LAYOUTS)
        check_positive("virtual_mass_ratio", self.virtual_mass_ratio)


def actuator_angle_to_gravity(tool_rotation: np.ndarray, mount_axis: str = "y") -> float:
    """Angle between the actuator axis (a tool-frame axis, expressed in the base frame by the
    tool rotation) and gravity (base -z)."""
    axis = np.asarray(tool_rotation, dtype=float)[:, "xyz".index(mount_axis)]
    return math.acos(min(1.0, abs(float(axis @ np.array([0.0, 0.0, -1.0])))))


def actuator_direction(tool_rotation: np.ndarray, mount_axis: str = "y") -> str:
    """The modal-table direction (x or y of the base) nearest the actuator's axis."""
    axis = np.asarray(tool_rotation, dtype=float)[:, "xyz".index(mount_axis)]
    return "x" if abs(axis[0]) >= abs(axis[1]) else "y"


def dominant_mode(modes) -> tuple[float, float, float]:
    """The (fn_hz, zeta, k_n_per_m) with the largest peak compliance 1 / (2 zeta k)."""
    return max(modes, key=lambda m: 1.0 / (2.0 * m[1] * m[2]))


def virtual_absorber(host: tuple[float, float, float], config: ControlConfig) -> dict:
    """Controller parameters that make the actuator act as a passive TMD / IDVA on the host
    mode (seed 002), tuned by max-min Re G for the host's damping (the non-dimensional optimum is
    kept per layout, mass ratio and damping by tune_sims), and the largest actuator force it needs
    for the disturbance force acting on the host."""
    fn, zeta, k = host
    design_zeta = max(round(zeta, 2), 0.005)  # tune for the damping to two decimals: one optimisation serves many poses
    t = tune_sims(config.virtual_layout, config.virtual_mass_ratio, design_zeta)
    wn = 2 * math.pi * fn
    M = k / wn**2
    m = config.virtual_mass_ratio * M
    lam = np.linspace(0.2, 3.0, 4000)
    s = 1j * lam
    Z = t.impedance(s)
    mu = t.mass_ratio
    absorber_force = np.abs(mu * s**2 * Z / (mu * s**2 + Z) * t.receptance(lam, zeta))  # |F_a / F|
    out = {
        "layout": t.layout,
        "mass_ratio": mu,
        "gamma": float(t.gamma),
        "zeta_a": float(t.zeta_a),
        "delta": None if t.delta is None else float(t.delta),
        "eta": None if t.eta is None else float(t.eta),
        "virtual_mass_kg": m,
        "k_o_n_per_m": m * (t.gamma * wn) ** 2,
        "c_ns_per_m": 2 * t.zeta_a * m * t.gamma * wn,
        "min_real_part_gain": float(min_real_part(t, zeta) / uncontrolled(zeta)),
        "max_force_n": float(absorber_force.max() * config.disturbance_n),
    }
    if t.delta is not None:
        out["b_kg"] = t.delta * m
        out["k_i_n_per_m"] = t.delta * m * (t.eta * t.gamma * wn) ** 2
    out["force_ok"] = out["max_force_n"] <= config.actuator.force_limit_n
    return out


def uncontrolled(zeta: float) -> float:
    return -1.0 / (4.0 * zeta * (1.0 + zeta))


def control_schedule_pose(pose_id: str, modes, tool_rotation: np.ndarray, config: ControlConfig) -> dict:
    """DVF gain and virtual-absorber parameters for one pose. `modes` are the (fn_hz, zeta,
    k_n_per_m) of the robot seen in the actuator's direction at the spindle (the actuator sits
    next to the tool, so H11 = H12 = H21 = H22 there)."""
    angle = actuator_angle_to_gravity(tool_rotation, config.mount_axis)
    fn_act = config.actuator.fn_hz(angle)
    H = modal_frf(modes)
    loop = DVF(H, H, H, config.actuator, fn_act, config.filters)
    host = dominant_mode(modes)
    entry = {"pose_id": pose_id, "actuator_angle_to_gravity_deg": math.degrees(angle)}
    try:
        entry.update(gain_schedule(loop, host[0], config.disturbance_n, config.margin_db))
    except InputError as exc:  # a property of the actuator file: named with it
        raise exc.located(file=config.source) from None
    entry["force_limit_n"] = config.actuator.force_limit_n
    entry["virtual_absorber"] = virtual_absorber(host, config)
    return entry


def controller_entry(pose_id: str, rows, tool_rotation: np.ndarray, config: ControlConfig) -> dict | None:
    """The control schedule entry of one pose from its modal rows (direction, mode, fn_hz, zeta,
    k_n_per_m, ...): robot modes below 500 Hz in the actuator's direction (the tool frame's
    mounting axis in the x-y plane, nearest of x, y); None when there is none."""
    direction = actuator_direction(tool_rotation, config.mount_axis)
    modes = [(fn, zeta, k) for d, _, fn, zeta, k, *_ in rows if d == direction and fn < 500 and math.isfinite(k)]
    if not modes:
        return None
    entry = control_schedule_pose(pose_id, modes, tool_rotation, config)
    entry["direction"] = direction
    return entry


def robust_gain(sampled_rows, tool_rotation: np.ndarray, config: ControlConfig, nominal_gain_ns_per_m: float) -> dict | None:
    """The DVF gain that keeps the required gain margin in 95 % of sampled structures (issue 23):
    each sample's Nyquist limit k_i (its robot modes below 500 Hz in the actuator's direction,
    as `controller_entry` takes them), the gain min(nominal gain, q05(k_i) / 10^(margin / 20)),
    and the share of samples in which the nominal gain keeps the margin. `sampled_rows`: per
    sample, rows (direction, mode, fn_hz, zeta, k_n_per_m). None without such modes."""
    direction = actuator_direction(tool_rotation, config.mount_axis)
    fn_act = config.actuator.fn_hz(actuator_angle_to_gravity(tool_rotation, config.mount_axis))
    limits = []
    for rows in sampled_rows:
        modes = [(fn, zeta, k) for d, _, fn, zeta, k, *_ in rows if d == direction and fn < 500 and math.isfinite(k)]
        if not modes:
            return None
        H = modal_frf(modes)
        loop = DVF(H, H, H, config.actuator, fn_act, config.filters)
        limits.append(loop.nyquist_gain_limit() if loop.open_loop_stable() else 0.0)
    limits = np.array(limits)
    margin = 10 ** (config.margin_db / 20)
    k05 = float(np.quantile(limits, 0.05))
    return {
        "dvf_gain_ns_per_m": float(min(nominal_gain_ns_per_m, k05 / margin)),
        "max_stable_gain_q05_ns_per_m": k05,
        "nominal_gain_keeps_margin_pct": float(100 * np.mean(limits >= margin * nominal_gain_ns_per_m)),
    }


def control_entries(table, config: ControlConfig) -> list[dict]:
    """One control schedule entry per pose of a modal table."""
    entries = []
    for p, pose_id in enumerate(table.poses.pose_id):
        rows = [(table.direction[i], table.mode[i], float(table.fn_hz[i]), float(table.zeta[i]), float(table.k_n_per_m[i])) for i in np.flatnonzero(table.pose_index == p)]
        entry = controller_entry(pose_id, rows, pose_rotation(table.poses, p), config)
        if entry is None:
            direction = actuator_direction(pose_rotation(table.poses, p), config.mount_axis)
            raise InputError(f"robot modes below 500 Hz in {direction} for pose '{pose_id}'", column="direction")
        entries.append(entry)
    return entries
