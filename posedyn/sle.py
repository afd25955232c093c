"""Surface location error (SLE) of a stable milling cut: seed 001 section 2.2, the Schmitz-Mann
frequency-domain method (seed ref. [32]; details and code in ref. [26], Schmitz and Smith).

Conventions, each with the seed equation or sentence it comes from ("S" = seed 001):

| convention | posedyn.sle | source |
|---|---|---|
| axes | feed along +x, surface normal along y; only y vibration locates the surface | S 2.2 first assertion ("y direction vibrations dominate the final surface location for an x direction feed") |
| x and y faces | the face whose normal is x uses the x-direction FRF as its normal FRF (the CLI turns the table by -90 deg, `--direction x`), the y face the y-direction FRF | S 4.5: "the x direction part dimensions ... were calculated using the x direction FRFs because this is the surface normal direction" |
| cutter-angle origin | phi from +y, increasing with time (clockwise seen from the spindle); the edge points along r = (sin phi, cos phi), so the chip is h = f_t sin(phi), largest at phi = pi/2 (edge along the feed) | S eqs. 9-10 (h = f_t sin phi) and Fig. 4 (start/exit angles, feed along x) |
| engagement limits | fixed nominal angles: down milling phi in [phi_s, pi], phi_s = arccos(2a/d - 1) = pi - arccos((r - a)/r); up milling [0, arccos(1 - 2a/d)] | S Fig. 4 / sec. 4.2 (start angle phi_s, exit angle phi_e) and S 2.1 ("cut start and exit angles, which depend on the radial depth and milling type"); no stock clipping, no regeneration (S 2.2 second assertion) |
| force | per slice db and tooth: F_t = k_t db h, F_n = k_n db h (eqs. 9-10 with b -> db), on the tool: F_y = F_t sin(phi) - F_n cos(phi) | S 4.2: "rotating coordinate system forces were projected into the x and y directions using the time-dependent cutter angle" |
| helix lag | phi_ij = w t + 2 pi (i - 1)/N_t - chi (j - 1), chi = 2 db tan(gamma)/d, slice j = 1 at the tool tip, higher slices lag (right-hand helix, right-hand cut) | S eqs. 7-8 |
| force series | F_y over one tooth period sampled on a fine grid, FFT -> coefficients F_k (k = 0..n) | S eq. 6 |
| response | y(t) = sum_k G_yy(k w_T) F_k exp(i k w_T t) (two-sided, i.e. G_0 F_0 + 2 Re sum_{k>=1}) | S eq. 5 |
| mean term | y_0 = G_yy(0) F_0: mean deflection = mean force x static compliance (sum of 1/k over the modes) | physics: the time average of a linear system's periodic steady response; see below |
| surface instant | the surface at slice j's height is generated when that slice's own edge leaves the cut (phi_ij = pi, down milling) or enters it (phi_ij = 0, up milling): the bottom tooth is then at pi + chi (j - 1) (resp. chi (j - 1)); SLE = mean over the slices (the CMM dimension is a fit over the wall height, S 4.6) | S 2.2 step 4 ("sample y(t) at the cut entry (up milling) or exit (down milling)") applied where the surface is actually cut: with a helix each height exits at its own time (eqs. 7-8) |
| surface normal / sign | down milling: the wall is on the -y side (the edge at phi = pi points to -y), so SLE = +y; up milling: the wall is on the +y side (phi = 0 points to +y), so SLE = -y. Positive = undercut (less material removed than commanded) | S 4.5 ("a positive SLE value indicates an undercut condition"); geometry of the rows above |
| robot path offset | optional constant added to the SLE | S Table 2 / Fig. 10 caption |

Two readings that the check below rejects. (1) Sampling every slice at one instant (the bottom
slice's exit, the literal single-instant reading of step 4): at seed 001 Table 7 it gives
0.31-3.64 um (x face) and 0.09-3.00 um (y face) for the machine tool at 10,700 rpm and 7-27 %
more than the geometry for the spindle-robot; the geometric simulation gives 0.12-1.00 um and
-0.47 to -0.12 um. (2) Before this
revision up milling returned +y, i.e. the wrong surface normal (sign) for up milling.

Mean (zero-frequency) term. The steady response of a linear structure to a tau-periodic force has
time average G(0) x mean force, G(0) = sum_r 1/k_r the static compliance: posedyn evaluates the
receptance at w = 0 and weights the k = 0 coefficient once (the k >= 1 ones twice, for the
negative frequencies). Seed eq. 6 writes the series as a_0 + sum (a_n cos + b_n sin) and gives no
formula for a_0; a reading that takes a_0 from the same (2/tau) integral as the a_n (or that
multiplies a one-sided spectrum by the FRF and keeps the real part, halving the oscillating part
instead) does not weight the mean as the physics does, and the seed's printed predictions
(Table 8, withheld from the shared copy) are reported in issue 19 to follow such a treatment.
For scale at Table 7 (10,700 rpm): the mean term is 1.0-4.0 um of the machine tool's -0.5 to
+1.0 um SLE (doubling it or dropping it moves the SLE by that much), and 12-87 um of the
spindle-robot's 11-86 um (its low, soft modes act quasi-statically at these speeds).

Check that shares none of these conventions: tests/independent_sle_sim.py, a geometric
time-domain simulation (edge trajectories of every slice and tooth with the tool-tip vibration,
the wall as the envelope of the edge paths; nothing is sampled at a chosen instant, so the
surface instant, lag direction and normal follow from the geometry). With the nominal
engagement and the deepest point of each feed mark, extrapolated in its time step, it agrees
with sle_m to <= 0.35 um (<= 0.9 %) at all 32 Table 7 points, <= 0.035 um for the machine
tool. The residual is genuine: sle_m samples y at phi = pi exactly, while the edge's deepest point comes slightly before or after
pi when the tool moves in y at that instant (second order in the normal velocity); with the
geometric engagement (the tool's static deflection reduces the true radial depth) the
simulation's SLE differs by up to 9 % for the robot (up to 0.11 um for the machine tool), which
the fixed-angle frequency-domain method leaves out by construction. `SleCut(engagement="geometric")`
takes it in (`_geometric_series`: the deflection and the strip it leaves the edge solved together):
within 1 % of the simulation's geometric engagement on seed 001's spindle-robot Table 7 points
(the fixed angles 3.4-6.5 % high) and within 0.35 um on the shipped wall campaign's 32 robot cuts
(the fixed angles up to 8.8 um, 9 %).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError, check_choice, check_finite, check_positive
from posedyn.stability.sdm import exponentials
from dataclasses import replace


#: How a cut engages the stock: "nominal" (seed 001's fixed angles) or "geometric" (the strip the
#: deflected tool really cuts, `_geometric_series`).
ENGAGEMENTS = ("nominal", "geometric")

#: Largest helix angle a cut may have (80 deg; end mills have 0-60).
HELIX_LIMIT_RAD = math.radians(80.0)


@dataclass(frozen=True)
class SleCut:
    """Tool and cut for SLE (lengths in m, coefficients in N/m^2, angles in rad)."""

    teeth: int
    kt_pa: float
    kn_pa: float
    tool_diameter_m: float
    helix_rad: float
    radial_depth_m: float
    axial_depth_m: float
    feed_per_tooth_m: float
    milling: str = "down"
    engagement: str = "nominal"  # "geometric": the strip the deflected tool really cuts (`_geometric_force`)

    def __post_init__(self):
        if not isinstance(self.teeth, (int, np.integer)) or self.teeth < 1:
            raise InputError("an integer number of teeth >= 1", got=self.teeth, column="teeth")
        for name in ("kt_pa", "tool_diameter_m", "axial_depth_m", "feed_per_tooth_m"):
            check_positive(name, getattr(self, name))
        check_finite("kn_pa", self.kn_pa)
        if not 0.0 <= self.helix_rad < HELIX_LIMIT_RAD:  # tan(90 deg) is 1.6e16: no tool
            raise InputError(f"a helix angle >= 0 and below 80 deg ({HELIX_LIMIT_RAD:.4g} rad)", got=self.helix_rad, column="helix_rad")
        check_choice("milling", self.milling, ("down", "up"))
        check_choice("engagement", self.engagement, ENGAGEMENTS)
        if not 0 < self.radial_depth_m <= self.tool_diameter_m:
            raise InputError("a radial depth in (0, tool diameter]", got=self.radial_depth_m, column="radial_depth_m")

    @property
    def engagement_rad(self) -> tuple[float, float]:
        r = self.radial_depth_m / self.tool_diameter_m
        if self.milling == "up":
            return 0.0, math.acos(1.0 - 2.0 * r)
        return math.acos(2.0 * r - 1.0), math.pi


def normal_force(cut: SleCut, phi_bottom: np.ndarray, slices: int) -> np.ndarray:
    """F_y (N) for the bottom tooth at angles phi_bottom (rad), all teeth and slices."""
    tangential, normal = _unit_forces(cut, phi_bottom, slices)
    return cut.feed_per_tooth_m * (cut.kt_pa * tangential - cut.kn_pa * normal)


def _slice_lag_rad(cut: SleCut, slices: int) -> float:
    """The helix lag between neighbouring slices, chi = 2 db tan(gamma) / d (seed 001 eqs. 7-8)."""
    return 2.0 * (cut.axial_depth_m / slices) * math.tan(cut.helix_rad) / cut.tool_diameter_m


def _unit_forces(cut: SleCut, phi_bottom: np.ndarray, slices: int) -> tuple[np.ndarray, np.ndarray]:
    """The two parts of F_y per unit feed and coefficient, sum over teeth and slices of db sin(phi)
    (sin phi, cos phi) over the engaged angles: F_y = f_t (k_t first - k_n second). They depend on
    the tool's geometry only, so cuts that differ in feed or coefficients share them."""
    st, ex = cut.engagement_rad
    db = cut.axial_depth_m / slices
    chi = _slice_lag_rad(cut, slices)
    tangential = np.zeros_like(phi_bottom, dtype=float)
    normal = np.zeros_like(phi_bottom, dtype=float)
    for i in range(cut.teeth):
        for j in range(slices):
            phi = np.mod(phi_bottom + 2 * math.pi * i / cut.teeth - chi * j, 2 * math.pi)
            engaged = (phi >= st) & (phi <= ex)
            s = np.where(engaged, db * np.sin(phi), 0.0)
            tangential += s * s / db
            normal += s * np.cos(phi)
    return tangential, normal


def _exit_phases(cut: SleCut, slices: int) -> np.ndarray:
    """Bottom-tooth angle at which each slice's edge generates the surface."""
    chi = _slice_lag_rad(cut, slices)
    surface = math.pi if cut.milling == "down" else 0.0
    return surface + chi * np.arange(slices)


def _normal_sign(cut: SleCut) -> float:
    """SLE (+ = undercut) per unit tool displacement +y: the down-milling wall is on the -y side
    (exit at phi = pi), the up-milling wall on the +y side (entry at phi = 0)."""
    return 1.0 if cut.milling == "down" else -1.0


def sle_m(dyn: ToolTipDynamics, cut: SleCut, rpm, slices: int = 20, harmonics: int = 200, offset_m: float = 0.0) -> np.ndarray:
    """SLE (m, + = undercut) at each spindle speed, frequency domain (conventions: module docstring)."""
    rpm = np.atleast_1d(np.asarray(rpm, dtype=float))
    if np.any(~np.isfinite(rpm) | (rpm <= 0)):
        raise InputError("spindle speeds > 0 rpm", got=rpm.tolist()[:3], column="rpm")
    if not (isinstance(slices, (int, np.integer)) and slices >= 1):
        raise InputError("an integer number of axial slices >= 1", got=slices, column="slices")
    if not math.isfinite(offset_m):
        raise InputError("a finite path offset", got=offset_m, column="offset_m")
    coeff = _force_series(cut, slices, harmonics)
    k = np.arange(min(harmonics, len(coeff) - 1) + 1)
    weights = np.where(k == 0, 1.0, 2.0)
    exit_phase = _exit_phases(cut, slices)  # bottom-tooth angle at each slice's surface instant
    out = np.empty(len(rpm))
    for n, speed in enumerate(rpm):
        omega_t = 2 * math.pi * speed / 60.0 * cut.teeth  # tooth-passing frequency, rad/s
        H = dyn.frf(k * omega_t)[:, 1, 1]
        if cut.engagement == "geometric":
            coeff = _geometric_series(cut, H, slices, len(coeff))
        # y(t) at bottom-tooth angle phi: sum_k Re(w_k H_k F_k exp(i k N phi)), N phi = w_T t
        phase = np.exp(1j * np.outer(exit_phase * cut.teeth, k))
        y = (phase * (weights * H * coeff[k])).real.sum(axis=1)
        out[n] = _normal_sign(cut) * y.mean()
    return out + offset_m


def _edge_angles(cut: SleCut, phi_bottom: np.ndarray, slices: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(cos phi, sin phi, faces the stock) of every tooth and slice (rows) at each bottom-tooth
    angle (columns): down milling the half phi in (pi/2, pi], up milling [0, pi/2)."""
    chi = _slice_lag_rad(cut, slices)
    lag = (2 * math.pi / cut.teeth * np.arange(cut.teeth)[:, None] - chi * np.arange(slices)[None, :]).reshape(-1, 1)
    phi = np.mod(phi_bottom[None, :] + lag, 2 * math.pi)
    side = (phi > math.pi / 2) & (phi <= math.pi) if cut.milling == "down" else (phi < math.pi / 2)
    return np.cos(phi), np.sin(phi), side


def _geometric_force(cut: SleCut, angles: tuple, slices: int, y: np.ndarray) -> np.ndarray:
    """F_y (N) with the tool displaced by y (m, +y) at each bottom-tooth angle (`_edge_angles`):
    the edge cuts the strip between its path and the stock's surface, which the displaced tool
    sees at a radial depth a_e' = a_e - s y (s = `_normal_sign`: an undercut deflection moves the
    edge away from the wall, so the strip is thinner); the chip is f_t sin(phi), clipped where the
    stock's surface is nearer, R - (R - a_e') / |cos phi| along the edge's radius (the edge enters
    at zero thickness, as the geometric simulation tests/independent_sle_sim.py cuts it), on the
    half of the cutter that faces the stock (a_e <= R)."""
    c, s, side = angles
    radius = cut.tool_diameter_m / 2.0
    depth = cut.radial_depth_m - _normal_sign(cut) * np.asarray(y, dtype=float)
    with np.errstate(divide="ignore"):
        to_stock = radius - (radius - depth[None, :]) / np.abs(c)
    h = np.where(side, np.clip(np.minimum(cut.feed_per_tooth_m * s, to_stock), 0.0, None), 0.0)
    return cut.axial_depth_m / slices * (h * (cut.kt_pa * s - cut.kn_pa * c)).sum(axis=0)


def _geometric_series(cut: SleCut, H: np.ndarray, slices: int, size: int, max_iterations: int = 60) -> np.ndarray:
    """Force coefficients F_k (k < size) of the steady cut with the geometric engagement: the
    displacement y(t) = sum_k G(k w_T) F_k e^(i k w_T t) and the force it lets the edge cut
    (`_geometric_force`) solved together by fixed-point iteration from the undeflected tool (it
    contracts by about G(0) dF/da_e, a few % to tens of % on a robot). Against the geometric
    simulation on the shipped wall campaign's 32 cuts without its hidden causes: within 0.35 um
    (the fixed angles: 8.8 um, 9 % of a 98 um wall)."""
    if 2 * cut.radial_depth_m > cut.tool_diameter_m:
        raise InputError("a radial depth up to the tool radius for the geometric engagement", got=cut.radial_depth_m, column="radial_depth_m")
    samples = 2 * (size - 1)
    angles = _edge_angles(cut, np.arange(samples) * (2 * math.pi / cut.teeth) / samples, slices)
    response = np.zeros(size, dtype=complex)
    response[: len(H)] = H
    y = np.zeros(samples)
    for _ in range(max_iterations):
        coeff = np.fft.rfft(_geometric_force(cut, angles, slices, y)) / samples
        new = np.fft.irfft(response * coeff * samples, n=samples)
        if np.max(np.abs(new - y)) <= 1e-11 + 1e-7 * np.max(np.abs(new)):
            return coeff
        y = new
    raise InputError("a cut whose deflected engagement settles (the tool's static compliance times the force's growth with the radial depth below 1)",
                     got=f"{cut.radial_depth_m * 1e3:g} mm radial depth", column="radial_depth_m")


def mean_normal_force_n(cut: SleCut, slices: int = 20, harmonics: int = 200) -> float:
    """The mean surface-normal force (N) as it pushes the tool toward undercut, sign x F_0: the
    SLE's zero-frequency term is G_yy(0) times it (module docstring, mean term)."""
    return _normal_sign(cut) * float(_force_series(cut, slices, harmonics)[0].real)


def _force_series(cut: SleCut, slices: int, harmonics: int) -> np.ndarray:
    """Fourier coefficients F_k of the surface-normal force over one tooth period (k = 0..samples/2):
    f_t (k_t T_k - k_n N_k) with the series of the unit forces (`_unit_forces`), which depend on
    the tool's geometry only, so a pose sweep or a campaign of cuts computes them once per tool
    and engagement."""
    tangential, normal = _unit_series(replace(cut, kt_pa=1.0, kn_pa=0.0, feed_per_tooth_m=1.0), slices, harmonics)
    return cut.feed_per_tooth_m * (cut.kt_pa * tangential - cut.kn_pa * normal)


@lru_cache(maxsize=128)
def _unit_series(geometry: SleCut, slices: int, harmonics: int) -> tuple[np.ndarray, np.ndarray]:
    samples = max(8 * harmonics, 4096)
    phi = np.arange(samples) * (2 * math.pi / geometry.teeth) / samples
    out = tuple(np.fft.rfft(part) / samples for part in _unit_forces(geometry, phi, slices))
    for part in out:
        part.flags.writeable = False
    return out


def sle_time_domain_m(dyn: ToolTipDynamics, cut: SleCut, rpm: float, slices: int = 20, steps_per_tooth: int = 2000) -> float:
    """The same steady forced response computed in the time domain: the modal equations stepped
    over one tooth period with exact exponentials (force linear between samples), the periodic
    state found from z0 = (I - P^n)^-1 z_n(0) instead of waiting for the start-up to die away,
    then y sampled at the surface instants."""
    omega = 2 * math.pi * rpm / 60.0
    tau = 2 * math.pi / (cut.teeth * omega)
    n = int(steps_per_tooth)
    dt = tau / n
    K, C = dyn.stiffness_matrix, dyn.damping_matrix
    size = len(K)
    P, g0, g1 = exponentials(K[None], C[None], np.array([dt]), order=1)
    P, g0, g1 = P[0], g0[0], g1[0]
    phi_y = dyn.shapes[1]
    force = normal_force(cut, omega * dt * np.arange(n + 1), slices)  # F_y at the step instants
    f = np.outer(force, phi_y)  # modal forces

    def run(z):
        states = [z]
        for k in range(n):
            z = P @ z + (g0 - g1) @ f[k] + g1 @ f[k + 1]
            states.append(z)
        return np.array(states)

    zn = run(np.zeros(2 * size))[-1]
    z0 = np.linalg.solve(np.eye(2 * size) - np.linalg.matrix_power(P, n), zn)
    states = run(z0)
    exits = np.mod(_exit_phases(cut, slices), 2 * math.pi / cut.teeth) / (omega * dt)
    y = states[:, :size] @ phi_y
    return _normal_sign(cut) * float(np.mean(np.interp(exits, np.arange(n + 1), y)))


def sle_quasi_static_m(dyn: ToolTipDynamics, cut: SleCut, slices: int = 20) -> float:
    """Low-speed limit: the deflection under the instantaneous force, y = G_yy(0) F_y(t), at the
    surface instants."""
    compliance = float(dyn.frf(np.array([0.0]))[0, 1, 1].real)
    return _normal_sign(cut) * float(np.mean(normal_force(cut, _exit_phases(cut, slices), slices)) * compliance)


def compensate(dyn: ToolTipDynamics, cut: SleCut, rpm: float, tolerance_m: float = 2e-6, max_iterations: int = 20, slices: int = 20, offset_m: float = 0.0):
    """Seed 001 section 2.3: command the radial depth a_(k+1) = a_0 + SLE(a_k) until the part error
    a_0 - (a_k - SLE(a_k)) is below the tolerance. Returns [(radial_depth_m, sle_m, part_error_m)]."""
    if not (math.isfinite(tolerance_m) and tolerance_m > 0):
        raise InputError("a tolerance > 0", got=tolerance_m, column="tolerance_m")
    target = cut.radial_depth_m
    depth = target
    history = []
    for _ in range(max_iterations):
        current = replace(cut, radial_depth_m=min(depth, cut.tool_diameter_m))
        error_sle = float(sle_m(dyn, current, rpm, slices, offset_m=offset_m)[0])
        part_error = target - (current.radial_depth_m - error_sle)
        history.append((current.radial_depth_m, error_sle, part_error))
        if abs(part_error) < tolerance_m:
            break
        depth = target + error_sle
    return history
