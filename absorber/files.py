"""The absorber package's parameter files: the MRF absorber (`kind = "mrf_absorber"`, as
datasets/seeds/hou2023_mrf_absorber.toml) and the active-damping actuator (`kind =
"active_damping"`, as datasets/seeds/sahu2024_active_damping.toml). None gives the defaults
(seed 004's absorber, seed 000's actuator)."""

from __future__ import annotations

import os

from absorber.active_damping import Actuator, ControlConfig
from absorber.mrf import MRFAbsorber
from posedyn.io.params import read_params, reading


def read_absorber(path: str | os.PathLike | None) -> MRFAbsorber:
    """The `[absorber]`, `[mrf]`, `[field]` tables of an absorber parameter file."""
    if path is None:
        return MRFAbsorber()
    p = read_params(path)
    with reading(path, "absorber file"):
        a, m, f = p["absorber"], p["mrf"], p["field"]
        return MRFAbsorber(
            mass_kg=a["mass_kg"], r1_m=a["r1_m"], r2_m=a["r2_m"], l1_m=a["l1_m"], w1_m=a["w1_m"], h1_m=a["h1_m"], h2_m=a["h2_m"],
            g2_pa=a["elastomer_shear_modulus_pa"], g0_pa=m["g0_pa"], ginf_pa=m["ginf_pa"], a1=m["a1"], a2=m["a2"],
            field_min_t=f["min_mt"] * 1e-3, field_max_t=f["max_mt"] * 1e-3,
            **{k: m[k] for k in ("loss_factor_mrf",) if k in m},
            **{k: a[k] for k in ("loss_factor_elastomer",) if k in a},
        )


def read_actuator(path: str | os.PathLike | None) -> ControlConfig:
    """The actuator and control settings of an active-damping file."""
    if path is None:
        return ControlConfig()
    p = read_params(path)
    with reading(path, "actuator file"):
        a = p["actuator"]
        actuator = Actuator(
            transducer_n_per_v=a["horizontal"]["transducer_constant_n_per_v"],
            zeta=a["horizontal"]["zeta"],
            fn_horizontal_hz=a["horizontal"]["fn_hz"],
            fn_vertical_hz=a["vertical"]["fn_hz"],
            delay_s=a["horizontal"]["delay_ms"] * 1e-3,
            force_limit_n=a["force_limit_n"],
        )
        control = p.get("control", {})
        return ControlConfig(actuator=actuator, **{k: control[k] for k in ("mount_axis", "disturbance_n", "margin_db", "virtual_layout", "virtual_mass_ratio") if k in control})
