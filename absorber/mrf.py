"""Magnetorheological-fluid (MRF) absorber: field -> storage modulus -> natural frequency, and back.

Seed 004 section 3, eqs. 14-15 (B in tesla, the constants of GH-MRF-250, Table 4):

    G1(B) = G0 + (Ginf - G0) (1 - exp(-a1 B^a2))
    f_a(B) = (1 / 2 pi) sqrt(G1(B) A1 / (m_a h1) + G2 A2 / (m_a h2)),   A1 = 4 l1 w1,  A2 = pi (r2^2 - r1^2)
    k_a = m_a (2 pi f_a)^2

Both are monotonic in B, so the inverse is closed form:

    G1 = (m_a (2 pi f)^2 - G2 A2 / h2) h1 / A1,   B = (-ln(1 - (G1 - G0) / (Ginf - G0)) / a1)^(1 / a2)

Damping (a modelling assumption: seed 004 ignores it). In the pre-yield region MR fluids are
viscoelastic with a loss modulus of the order of 10-30 % of the storage modulus (Li, Du and Guo,
"Viscoelastic properties of MR fluids", Smart Mater. Struct. 12 (2003); Yang et al. 2019 for the
GH-MRF class); soft elastomers have loss factors of about 0.1-0.2. With loss factors eta1 (fluid)
and eta2 (elastomer) the structural damping is hysteretic and, at resonance, equivalent to

    zeta_a = (eta1 G1 A1 / h1 + eta2 G2 A2 / h2) / (2 (G1 A1 / h1 + G2 A2 / h2)).

Defaults eta1 = 0.15, eta2 = 0.12 are mid-range literature values, not measurements of this absorber.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from posedyn.errors import InputError, check_finite, check_non_negative, check_positive


@dataclass(frozen=True)
class MRFAbsorber:
    """Geometry (m), masses (kg), moduli (Pa) and field limits (T); defaults are seed 004's design."""

    mass_kg: float = 3.0
    r1_m: float = 0.1
    r2_m: float = 0.15
    l1_m: float = 0.04
    w1_m: float = 0.018
    h1_m: float = 0.02
    h2_m: float = 0.05
    g2_pa: float = 1.0e4
    g0_pa: float = 2.51e3
    ginf_pa: float = 3.5e6
    a1: float = 6.8339
    a2: float = 1.8248
    field_min_t: float = 0.0
    field_max_t: float = 0.6
    loss_factor_mrf: float = 0.15
    loss_factor_elastomer: float = 0.12
    zeta_per_tesla: float = 0.0  # damping the loss factors miss, growing with the field (as `posedyn gap` measures it: mrf_loss_modulus)

    def __post_init__(self):
        for name in ("mass_kg", "r2_m", "l1_m", "w1_m", "h1_m", "h2_m", "g2_pa", "g0_pa", "ginf_pa", "a1", "a2"):
            check_positive(name, getattr(self, name))
        for name in ("r1_m", "field_min_t", "loss_factor_mrf", "loss_factor_elastomer"):
            check_non_negative(name, getattr(self, name))
        check_finite("zeta_per_tesla", self.zeta_per_tesla)
        if not self.r2_m > self.r1_m:
            raise InputError("r2_m > r1_m", got=(self.r1_m, self.r2_m), column="r2_m")
        if not self.ginf_pa > self.g0_pa:
            raise InputError("ginf_pa > g0_pa", got=(self.g0_pa, self.ginf_pa), column="ginf_pa")
        if not self.field_max_t > self.field_min_t:
            raise InputError("field_max_t > field_min_t", got=(self.field_min_t, self.field_max_t), column="field_max_t")

    @property
    def a1_m2(self) -> float:
        """A1 = 4 l1 w1, the MRF shear area (seed 004 eq. 15)."""
        return 4.0 * self.l1_m * self.w1_m

    @property
    def a2_m2(self) -> float:
        """A2 = pi (r2^2 - r1^2), the elastomer shear area."""
        return math.pi * (self.r2_m**2 - self.r1_m**2)

    def storage_modulus_pa(self, field_t: float) -> float:
        """G1(B) = G0 + (Ginf - G0)(1 - exp(-a1 B^a2))."""
        b = float(field_t)
        if not (math.isfinite(b) and b >= 0):
            raise InputError("a field >= 0 T", got=field_t, column="field_t")
        return float(self.storage_modulus(b))

    def storage_modulus(self, field_t, xp=np):
        """G1(B) unchecked, `xp` numpy or casadi (the coil's dynamics and planner)."""
        return self.g0_pa + (self.ginf_pa - self.g0_pa) * (1.0 - xp.exp(-self.a1 * field_t**self.a2))

    def frequency_for_modulus(self, g1_pa, xp=np):
        """f_a = sqrt((G1 A1 / h1 + G2 A2 / h2) / m_a) / (2 pi) for a storage modulus G1."""
        return xp.sqrt((g1_pa * self.a1_m2 / self.h1_m + self.elastomer_stiffness_n_per_m) / self.mass_kg) / (2.0 * math.pi)

    def _mrf_stiffness(self, g1_pa: float) -> float:
        return g1_pa * self.a1_m2 / self.h1_m

    @property
    def elastomer_stiffness_n_per_m(self) -> float:
        return self.g2_pa * self.a2_m2 / self.h2_m

    def stiffness_n_per_m(self, field_t: float) -> float:
        """k_a = G1 A1 / h1 + G2 A2 / h2 = m_a (2 pi f_a)^2 (seed 004 eq. 14)."""
        return self._mrf_stiffness(self.storage_modulus_pa(field_t)) + self.elastomer_stiffness_n_per_m

    def natural_frequency_hz(self, field_t: float) -> float:
        """f_a(B) (seed 004 eq. 15)."""
        return float(self.frequency_for_modulus(self.storage_modulus_pa(field_t)))

    def damping_ratio(self, field_t: float) -> float:
        """Equivalent viscous damping ratio from the loss factors (assumption; see the module),
        plus a measured zeta_per_tesla x B."""
        k1 = self._mrf_stiffness(self.storage_modulus_pa(field_t))
        k2 = self.elastomer_stiffness_n_per_m
        return (self.loss_factor_mrf * k1 + self.loss_factor_elastomer * k2) / (2.0 * (k1 + k2)) + self.zeta_per_tesla * field_t

    @property
    def range_hz(self) -> tuple[float, float]:
        return self.natural_frequency_hz(self.field_min_t), self.natural_frequency_hz(self.field_max_t)

    def field_for_frequency(self, target_hz: float, clamp: bool = False) -> "FieldSetting":
        """The field that tunes the absorber to `target_hz` (closed form). Outside the tunable
        range: an InputError, or with `clamp` the nearest limit and `feasible = False`."""
        f = float(target_hz)
        if not (math.isfinite(f) and f > 0):
            raise InputError("a target frequency > 0 Hz", got=target_hz, column="target_hz")
        lo, hi = self.range_hz
        if not lo <= f <= hi:
            if not clamp:
                raise InputError(f"a target frequency within the absorber's range {lo:.3f}-{hi:.3f} Hz", got=f, column="target_hz")
            b = self.field_min_t if f < lo else self.field_max_t
            return FieldSetting(field_t=b, frequency_hz=self.natural_frequency_hz(b), feasible=False)
        g1 = (self.mass_kg * (2.0 * math.pi * f) ** 2 - self.elastomer_stiffness_n_per_m) * self.h1_m / self.a1_m2
        x = (g1 - self.g0_pa) / (self.ginf_pa - self.g0_pa)
        b = (-math.log1p(-x) / self.a1) ** (1.0 / self.a2) if x > 0 else 0.0
        b = min(max(b, self.field_min_t), self.field_max_t)
        return FieldSetting(field_t=b, frequency_hz=f, feasible=True)


@dataclass(frozen=True)
class FieldSetting:
    field_t: float
    frequency_hz: float
    feasible: bool
