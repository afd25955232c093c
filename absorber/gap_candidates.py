"""The gap workflow's absorber effects through the absorber model (issue 18): the MRF storage
modulus falling with temperature, G1(B, T) = G1(B) exp(-a (T - T_ref)), acts on the fluid's
shear stiffness only, so the absorber frequency moves as seed 004 eq. 15 says, f_a =
sqrt((G1 A1 / h1 + G2 A2 / h2) / m_a) / 2 pi, with the elastomer's part unchanged (the library's
surrogate scales all of f_a by exp(-a (T - T_ref) / 2), too much at low field where the elastomer
carries most of the stiffness). The law it fits is the one `posedyn gap --out` writes into the
absorber file (`[drive] modulus_tempco_per_k, modulus_reference_c`), the one the coil's thermal
model (`absorber.coil_dynamics.absorber_frequency`) uses."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from absorber.coil_dynamics import CoilDrive
from absorber.mrf import MRFAbsorber
from posedyn.gap import LIBRARY, CandidateEffect, Measurements


def absorber_candidates(absorber: MRFAbsorber, drive: CoilDrive | None = None) -> dict[str, CandidateEffect]:
    """`mrf_temperature_drift` through `absorber` (same name and parameters as the library's:
    modulus_drop_per_mk, i.e. a in 1e-3 / K, and reference_c), on top of the temperature law of
    `drive` where the model already has one (None: G1(B) holds at every temperature)."""

    def temperature(y, m: Measurements, t):
        rows = (m.quantity == "absorber_fn_hz") & np.isfinite(m.column("field_mt")) & np.isfinite(m.column("temperature_c"))
        if not rows.any():
            return y
        temperature_c = m.column("temperature_c")[rows]
        g1 = absorber.storage_modulus(np.maximum(m.column("field_mt")[rows] * 1e-3, 0.0))
        if drive is not None:
            g1 = g1 * np.exp(-drive.modulus_tempco_per_k * (temperature_c - drive.modulus_reference_c))
        factor = np.exp(-t[0] * 1e-3 * (temperature_c - t[1]))
        out = y.copy()
        out[rows] = y[rows] * absorber.frequency_for_modulus(g1 * factor) / absorber.frequency_for_modulus(g1)
        return out

    surrogate = LIBRARY["mrf_temperature_drift"]
    return {"mrf_temperature_drift": replace(surrogate, description=surrogate.description + " (its shear stiffness only: the elastomer's is unchanged)",
                                             apply=temperature)}
