"""Surface location error (SLE) of a stable milling cut: seed 001 section 2.2 (Schmitz and Mann).

Feed along x, the machined wall on the -y side of the tool (Altintas' angle phi from +y,
clockwise rotation; down milling engages phi in (phi_st, pi), up milling (0, phi_ex)). A tooth
at angle phi in the cut removes h = f_t sin(phi) and feels (seed 001 eqs. 9-10)

    F_t = k_t db h,   F_n = k_n db h,   F_y = F_t sin(phi) - F_n cos(phi)

on each of A axial slices db = b / A; slice j lags the bottom slice by the helix angle
chi = 2 db tan(gamma) / d (eq. 8), so phi_ij = Omega t + 2 pi (i - 1) / N - chi (j - 1) (eq. 7).
F_y(t) is tau-periodic (tau = 60 / (N rpm)); its Fourier coefficients F_k (eq. 6, sampled
exactly on a fine grid and FFT'd) times the surface-normal receptance H_yy(k w_T) give
y(t) = sum_k H_yy(k w_T) F_k exp(i k w_T t) (eq. 5), the forced response with regeneration
neglected. The surface at slice j's height is generated when its edge leaves the cut (phi = pi,
down milling) or enters it (phi = 0, up milling); SLE is y at those instants averaged over the
slices, positive = the tool stood off the wall = undercut, plus an optional robot path offset
(seed 001 Table 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError, check_choice, check_finite, check_non_negative, check_positive
from posedyn.stability.sdm import exponentials
from dataclasses import replace


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

    def __post_init__(self):
        if not isinstance(self.teeth, (int, np.integer)) or self.teeth < 1:
            raise InputError("an integer number of teeth >= 1", got=self.teeth, column="teeth")
        for name in ("kt_pa", "tool_diameter_m", "axial_depth_m", "feed_per_tooth_m"):
            check_positive(name, getattr(self, name))
        check_finite("kn_pa", self.kn_pa)
        check_non_negative("helix_rad", self.helix_rad)
        check_choice("milling", self.milling, ("down", "up"))
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
    st, ex = cut.engagement_rad
    db = cut.axial_depth_m / slices
    chi = 2.0 * db * math.tan(cut.helix_rad) / cut.tool_diameter_m
    total = np.zeros_like(phi_bottom, dtype=float)
    for i in range(cut.teeth):
        for j in range(slices):
            phi = np.mod(phi_bottom + 2 * math.pi * i / cut.teeth - chi * j, 2 * math.pi)
            engaged = (phi >= st) & (phi <= ex)
            s, c = np.sin(phi), np.cos(phi)
            h = cut.feed_per_tooth_m * s
            total += np.where(engaged, db * h * (cut.kt_pa * s - cut.kn_pa * c), 0.0)
    return total


def _exit_phases(cut: SleCut, slices: int) -> np.ndarray:
    """Bottom-tooth angle at which each slice's edge generates the surface."""
    db = cut.axial_depth_m / slices
    chi = 2.0 * db * math.tan(cut.helix_rad) / cut.tool_diameter_m
    surface = math.pi if cut.milling == "down" else 0.0
    return surface + chi * np.arange(slices)


def sle_m(dyn: ToolTipDynamics, cut: SleCut, rpm, slices: int = 20, harmonics: int = 200, offset_m: float = 0.0) -> np.ndarray:
    """SLE (m, + = undercut) at each spindle speed, frequency domain."""
    rpm = np.atleast_1d(np.asarray(rpm, dtype=float))
    if np.any(~np.isfinite(rpm) | (rpm <= 0)):
        raise InputError("spindle speeds > 0 rpm", got=rpm.tolist()[:3], column="rpm")
    coeff = _force_series(cut, slices, harmonics)
    k = np.arange(min(harmonics, len(coeff) - 1) + 1)
    weights = np.where(k == 0, 1.0, 2.0)
    exit_phase = _exit_phases(cut, slices)  # bottom-tooth angle at each slice's surface instant
    out = np.empty(len(rpm))
    for n, speed in enumerate(rpm):
        omega_t = 2 * math.pi * speed / 60.0 * cut.teeth  # tooth-passing frequency, rad/s
        H = dyn.frf(k * omega_t)[:, 1, 1]
        # y(t) at bottom-tooth angle phi: sum_k Re(w_k H_k F_k exp(i k N phi)), N phi = w_T t
        phase = np.exp(1j * np.outer(exit_phase * cut.teeth, k))
        y = (phase * (weights * H * coeff[k])).real.sum(axis=1)
        out[n] = y.mean()
    return out + offset_m


@lru_cache(maxsize=16)
def _force_series(cut: SleCut, slices: int, harmonics: int) -> np.ndarray:
    """Fourier coefficients F_k of the surface-normal force over one tooth period (k = 0..samples/2);
    they depend on the cut only, so a pose sweep computes them once."""
    samples = max(8 * harmonics, 4096)
    phi = np.arange(samples) * (2 * math.pi / cut.teeth) / samples
    coeff = np.fft.rfft(normal_force(cut, phi, slices)) / samples
    coeff.flags.writeable = False
    return coeff


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
    return float(np.mean(np.interp(exits, np.arange(n + 1), y)))


def sle_quasi_static_m(dyn: ToolTipDynamics, cut: SleCut, slices: int = 20) -> float:
    """Low-speed limit: the deflection under the instantaneous force, y = G_yy(0) F_y(t), at the
    surface instants."""
    compliance = float(dyn.frf(np.array([0.0]))[0, 1, 1].real)
    return float(np.mean(normal_force(cut, _exit_phases(cut, slices), slices)) * compliance)


def compensate(dyn: ToolTipDynamics, cut: SleCut, rpm: float, tolerance_m: float = 2e-6, max_iterations: int = 20, slices: int = 20, offset_m: float = 0.0):
    """Seed 001 section 2.3: command the radial depth a_(k+1) = a_0 + SLE(a_k) until the part error
    a_0 - (a_k - SLE(a_k)) is below the tolerance. Returns [(radial_depth_m, sle_m, part_error_m)]."""
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
