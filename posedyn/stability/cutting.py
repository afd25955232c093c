"""The cut and the regenerative cutting-force matrix of milling.

Feed along x, the tool turning clockwise seen from the spindle, tooth angle phi measured from
+y (Altintas' convention; seed 004 eq. 6 in the same form). The dynamic force is

    F(t) = a_p H(t) (U(t - tau) - U(t)),   tau = 60 / (N rpm)

    H(t) = sum_j g(phi_j) [[ s (Kt c + Kn s),  c (Kt c + Kn s)],
                           [ s (-Kt s + Kn c), c (-Kt s + Kn c)]],   s = sin phi_j, c = cos phi_j

with g = 1 while tooth j is in the cut: phi in (0, phi_ex) for up milling and (phi_st, pi) for
down milling, cos phi_ex = 1 - 2 a_e / D, cos phi_st = 2 a_e / D - 1. H = -(Kt / 2) A(t) with
seed 004's A; it is Insperger and Stepan's H for the same geometry. Straight flutes: the helix
is not modelled (it smooths H(t) but leaves its mean, which sets the zeroth-order limit,
unchanged).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from posedyn.errors import InputError, check_choice, check_finite, check_positive


#: Physical ranges of a cut, the same wherever a cut comes from (a cut file, a flag, a service
#: request): specific cutting-force coefficients from soft aluminium (~100 MPa) to hardened steel
#: and nickel alloys (~6 GPa) with margin (a coefficient in N/m^2 written into an MPa key is
#: 1e6 times too large, 7.96e8 MPa, and gave a 5.7e-7 mm depth), milling cutters up to 32 teeth,
#: the spindle speeds of milling spindles.
MAX_COEFFICIENT_PA = 2e10
MAX_TEETH = 32
RPM_RANGE = (100.0, 100_000.0)


def check_rpm(rpm: float, column: str = "rpm") -> float:
    """A spindle speed within RPM_RANGE (rpm), else InputError."""
    if isinstance(rpm, bool) or not isinstance(rpm, (int, float, np.floating, np.integer)) or not RPM_RANGE[0] <= rpm <= RPM_RANGE[1]:
        raise InputError(f"a spindle speed from {RPM_RANGE[0]:g} to {RPM_RANGE[1]:g} rpm", got=rpm, column=column)
    return float(rpm)


@dataclass(frozen=True)
class Cut:
    """Tool, material and engagement of a milling cut (speed and depth are separate arguments).

    kt_pa, kn_pa: tangential and normal specific cutting-force coefficients (N/m^2);
    radial_immersion: a_e / D in (0, 1]; feed_angle_deg turns the feed direction from the x axis
    of the modal data towards y.
    """

    teeth: int
    kt_pa: float
    kn_pa: float
    radial_immersion: float
    milling: Literal["down", "up"] = "down"
    feed_angle_deg: float = 0.0

    def __post_init__(self):
        if not isinstance(self.teeth, (int, np.integer)) or isinstance(self.teeth, bool) or not 1 <= self.teeth <= MAX_TEETH:
            raise InputError(f"an integer number of teeth from 1 to {MAX_TEETH}", got=self.teeth, column="teeth")
        if not 0.0 < check_positive("kt_pa", self.kt_pa) <= MAX_COEFFICIENT_PA:
            raise InputError(f"a tangential cutting coefficient up to {MAX_COEFFICIENT_PA * 1e-9:g} GPa", got=self.kt_pa, column="kt_pa")
        if not 0.0 <= check_finite("kn_pa", self.kn_pa) <= MAX_COEFFICIENT_PA:
            raise InputError(f"a normal cutting coefficient from 0 to {MAX_COEFFICIENT_PA * 1e-9:g} GPa", got=self.kn_pa, column="kn_pa")
        check_finite("radial_immersion", self.radial_immersion)
        if not 0.0 < self.radial_immersion <= 1.0:
            raise InputError("a radial immersion a_e / D in (0, 1]", got=self.radial_immersion, column="radial_immersion")
        check_choice("milling", self.milling, ("down", "up"))
        check_finite("feed_angle_deg", self.feed_angle_deg)

    @property
    def engagement_rad(self) -> tuple[float, float]:
        """(phi_start, phi_exit) of one tooth."""
        r = self.radial_immersion
        if self.milling == "up":
            return 0.0, float(np.arccos(1.0 - 2.0 * r))
        return float(np.arccos(2.0 * r - 1.0)), float(np.pi)

    def tooth_period_s(self, rpm) -> np.ndarray:
        """tau = 60 / (N rpm), the regenerative delay (equal tooth pitch)."""
        return 60.0 / (self.teeth * np.asarray(rpm, dtype=float))


def _h_antiderivative(cut: Cut, phi: np.ndarray) -> np.ndarray:
    """Integral of one tooth's H(phi) d phi from 0, shape (..., 2, 2)."""
    sc = np.sin(phi) ** 2 / 2.0  # int sin cos
    ss = phi / 2.0 - np.sin(2.0 * phi) / 4.0  # int sin^2
    cc = phi / 2.0 + np.sin(2.0 * phi) / 4.0  # int cos^2
    kt, kn = cut.kt_pa, cut.kn_pa
    return np.stack(
        [np.stack([kt * sc + kn * ss, kt * cc + kn * sc], -1), np.stack([-kt * ss + kn * sc, -kt * sc + kn * cc], -1)],
        -2,
    )


def engaged_integral(cut: Cut, phi_a: np.ndarray, phi_b: np.ndarray) -> np.ndarray:
    """Sum over teeth of the integral of H over tooth angles [phi_a, phi_b] (phi_b - phi_a < 2 pi),
    counting only the engaged part, for the first tooth's angle range (other teeth offset by 2 pi j / N)."""
    st, ex = cut.engagement_rad
    total = np.zeros(np.shape(phi_a) + (2, 2))
    for j in range(cut.teeth):
        a = np.asarray(phi_a) + 2.0 * np.pi * j / cut.teeth
        b = np.asarray(phi_b) + 2.0 * np.pi * j / cut.teeth
        shift = np.floor(a / (2.0 * np.pi)) * 2.0 * np.pi
        a, b = a - shift, b - shift  # a in [0, 2 pi)
        for offset in (0.0, 2.0 * np.pi):
            lo = np.clip(a, st + offset, ex + offset)
            hi = np.clip(b, st + offset, ex + offset)
            total += _h_antiderivative(cut, hi - offset) - _h_antiderivative(cut, lo - offset)
    return total


def interval_force_matrices(cut: Cut, steps: int) -> np.ndarray:
    """H averaged over each of `steps` equal intervals of one tooth period, shape (steps, 2, 2).

    The averages are exact (closed-form integrals over the engaged angles); they depend on the
    tool angle only, not on the spindle speed.
    """
    dphi = 2.0 * np.pi / (cut.teeth * steps)
    edges = np.arange(steps + 1) * dphi
    return engaged_integral(cut, edges[:-1], edges[1:]) / dphi


def mean_force_matrix(cut: Cut) -> np.ndarray:
    """H0 = (1 / tau) int_0^tau H(t) dt = (N / 2 pi) int_{phi_st}^{phi_ex} H(phi) d phi, the
    zeroth Fourier term used by the zeroth-order approximation (seed 002 eqs. 10-11)."""
    st, ex = cut.engagement_rad
    return cut.teeth / (2.0 * np.pi) * (_h_antiderivative(cut, np.float64(ex)) - _h_antiderivative(cut, np.float64(st)))


def force_matrix(cut: Cut, phi_rad: np.ndarray) -> np.ndarray:
    """Instantaneous H at tool angle phi (of tooth 0), shape (..., 2, 2); for time-domain simulation."""
    st, ex = cut.engagement_rad
    total = np.zeros(np.shape(phi_rad) + (2, 2))
    kt, kn = cut.kt_pa, cut.kn_pa
    for j in range(cut.teeth):
        phi = np.mod(np.asarray(phi_rad) + 2.0 * np.pi * j / cut.teeth, 2.0 * np.pi)
        g = ((phi >= st) & (phi <= ex)).astype(float)
        s, c = np.sin(phi), np.cos(phi)
        total += g[..., None, None] * np.stack(
            [np.stack([s * (kt * c + kn * s), c * (kt * c + kn * s)], -1), np.stack([s * (-kt * s + kn * c), c * (-kt * s + kn * c)], -1)],
            -2,
        )
    return total
