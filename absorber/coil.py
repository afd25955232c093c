"""Coil and magnetic circuit of the MRF absorber: coil current <-> field in the fluid gap.

Ampere's law around one flux loop (flux conserved, leakage neglected):

    N I = H_gap(B) g + H_steel(B_steel) l_steel,   B_steel = B A_gap / A_steel,
    H_gap = B / (mu0 mu_r,MRF)

with the steel's B-H curve a Frohlich-Kennelly saturation law (Jiles, "Introduction to
Magnetism and Magnetic Materials", ch. 2; the form used for low-carbon steel in MR devices):

    B = mu0 mu_i H / (1 + mu0 mu_i |H| / B_sat)   <=>   H = B / (mu0 mu_i (1 - |B| / B_sat)),

so current_for_field is closed form and field_for_current is its monotone inverse (Brent).
Defaults: 1010 steel (mu_i 2000, B_sat 1.6 T: the order of handbook values), MR fluid relative
permeability 5 (typical 3-8 for hydrocarbon-based MR fluids at moderate fields), gap = seed
004's MRF thickness h1 = 20 mm, 1200 turns, a 300 mm steel path, 4 A drive limit. Assumptions,
not a measured circuit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from posedyn.errors import InputError, check_positive

MU0 = 4e-7 * math.pi


@dataclass(frozen=True)
class Coil:
    turns: int = 1200
    gap_m: float = 0.02
    mrf_relative_permeability: float = 5.0
    steel_path_m: float = 0.3
    gap_to_steel_area: float = 1.5
    steel_initial_relative_permeability: float = 2000.0
    steel_saturation_t: float = 1.6
    max_current_a: float = 4.0

    def __post_init__(self):
        for name in ("turns", "gap_m", "mrf_relative_permeability", "steel_path_m", "gap_to_steel_area", "steel_initial_relative_permeability", "steel_saturation_t", "max_current_a"):
            check_positive(name, getattr(self, name))

    def current(self, field_t, xp=np):
        """I(B) = (H_gap g + H_steel l) / N for B >= 0 below saturation, unchecked; `xp` numpy or
        casadi (the coil's dynamics and planner use the same expression)."""
        b_steel = field_t * self.gap_to_steel_area
        h_steel = b_steel / (MU0 * self.steel_initial_relative_permeability * (1.0 - b_steel / self.steel_saturation_t))
        return (field_t / (MU0 * self.mrf_relative_permeability) * self.gap_m + h_steel * self.steel_path_m) / self.turns

    def current_slope(self, field_t, xp=np):
        """dI/dB (A/T): (g / (mu0 mu_r) + a l / (mu0 mu_i (1 - a B / B_sat)^2)) / N."""
        a = self.gap_to_steel_area
        steel = a * self.steel_path_m / (MU0 * self.steel_initial_relative_permeability * (1.0 - a * field_t / self.steel_saturation_t) ** 2)
        return (self.gap_m / (MU0 * self.mrf_relative_permeability) + steel) / self.turns

    @property
    def max_field_t(self) -> float:
        """The field at the current limit."""
        return self.field_for_current(self.max_current_a)

    def current_for_field(self, field_t: float) -> float:
        """I = (H_gap g + H_steel l) / N (closed form). Fields the steel cannot carry are refused."""
        b = float(field_t)
        if not (math.isfinite(b) and b >= 0):
            raise InputError("a field >= 0 T", got=field_t, column="field_t")
        if b * self.gap_to_steel_area >= self.steel_saturation_t:
            raise InputError(f"a field below {self.steel_saturation_t / self.gap_to_steel_area:.3f} T (steel saturation)", got=b, column="field_t")
        return float(self.current(b))

    def field_for_current(self, current_a: float) -> float:
        """The gap field for a coil current (inverse of current_for_field)."""
        i = float(current_a)
        if not (math.isfinite(i) and i >= 0):
            raise InputError("a current >= 0 A", got=current_a, column="current_a")
        if i == 0:
            return 0.0
        top = self.steel_saturation_t / self.gap_to_steel_area * (1 - 1e-12)
        return brentq(lambda b: self.current_for_field(b) - i, 0.0, top, xtol=1e-15, rtol=1e-14)
