"""The MRF absorber's coil, fluid and heat in time: what limits how fast and how long a field can
be held (issue 21; seed 004 gives the static field model, `absorber.mrf`, `absorber.coil`).

States: the gap field B (T), the field the fluid has followed B_f (T), the lumped temperature of
coil and fluid T (deg C); input: the driver's voltage V. With the magnetic circuit of
`absorber.coil.Coil` the flux linkage is lambda = N A_gap B and the current i(B) is closed form,
so Faraday's law is explicit in B:

    N A_gap dB/dt = V - R(T) i(B),      R(T) = R_ref (1 + alpha (T - T_ref))
    dB_f/dt = (B - B_f) / tau_f                                   (the fluid's first-order lag)
    C dT/dt = R(T) i(B)^2 - (T - T_amb) / R_th                    (lumped heat balance)

The coil's differential inductance L = N A_gap / (di/dB) falls as the steel saturates. The
storage modulus falls with temperature, G1(B, T) = G1(B) exp(-a_T (T - T_G)), and with it the
absorber's natural frequency (seed 004 eq. 15 with that G1).

Every parameter below is an assumption unless marked: no seed gives the coil's resistance,
the driver, the fluid's response time or the thermal path. The expressions take an `xp` module
(numpy, or casadi for the planner) so the optimiser and the check simulate the same equations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from absorber.coil import Coil
from absorber.mrf import MRFAbsorber
from posedyn.errors import check_non_negative, check_positive


@dataclass(frozen=True)
class CoilDrive:
    """Electrical, fluid and thermal parameters of the absorber's drive (assumptions)."""

    resistance_ohm: float = 8.0  # at reference_c (a 1,200-turn coil of about 0.8 mm copper wire)
    resistance_tempco_per_k: float = 0.00393  # copper (handbook)
    reference_c: float = 20.0
    gap_area_m2: float = 2.88e-3  # seed 004: A1 = 4 l1 w1, the fluid's sheared area
    voltage_limit_v: float = 48.0  # an industrial 48 V driver
    fluid_lag_s: float = 0.01  # MR fluids follow the field in milliseconds
    heat_capacity_j_per_k: float = 600.0  # coil, fluid and the housing around them
    thermal_resistance_k_per_w: float = 1.0  # to the ambient air through a closed housing
    ambient_c: float = 20.0
    temperature_limit_c: float = 80.0  # the fluid's carrier oil and the coil's insulation
    modulus_tempco_per_k: float = 0.008  # G1 falls about 0.8 %/K (MR fluids soften as they warm: tens of % over 20-60 C)
    modulus_reference_c: float = 25.0  # where seed 004's G1(B) holds

    def __post_init__(self):
        for name in ("resistance_ohm", "gap_area_m2", "voltage_limit_v", "fluid_lag_s", "heat_capacity_j_per_k", "thermal_resistance_k_per_w"):
            check_positive(name, getattr(self, name))
        for name in ("resistance_tempco_per_k", "modulus_tempco_per_k"):
            check_non_negative(name, getattr(self, name))

    def resistance(self, temperature_c, xp=np):
        return self.resistance_ohm * (1.0 + self.resistance_tempco_per_k * (temperature_c - self.reference_c))


def absorber_frequency(absorber: MRFAbsorber, drive: CoilDrive, fluid_field_t, temperature_c, xp=np):
    """f_a(B_f, T) (Hz): seed 004 eq. 15 with G1(B_f) exp(-a_T (T - T_G))."""
    g1 = absorber.storage_modulus(xp.fmax(fluid_field_t, 1e-12), xp)
    return absorber.frequency_for_modulus(g1 * xp.exp(-drive.modulus_tempco_per_k * (temperature_c - drive.modulus_reference_c)), xp)


def field_rates(coil: Coil, drive: CoilDrive, field_t, fluid_field_t, temperature_c, voltage_v, xp=np):
    """(dB/dt, dB_f/dt, dT/dt) of the module docstring's equations."""
    current = coil.current(field_t, xp)
    resistance = drive.resistance(temperature_c, xp)
    d_field = (voltage_v - resistance * current) / (coil.turns * drive.gap_area_m2)
    d_fluid = (field_t - fluid_field_t) / drive.fluid_lag_s
    d_temperature = (resistance * current**2 - (temperature_c - drive.ambient_c) / drive.thermal_resistance_k_per_w) / drive.heat_capacity_j_per_k
    return d_field, d_fluid, d_temperature


def inductance_h(coil: Coil, drive: CoilDrive, field_t: float) -> float:
    """Differential inductance L = N A_gap / (di/dB) at a field (falls as the steel saturates)."""
    return coil.turns * drive.gap_area_m2 / coil.current_slope(field_t)
