"""The absorber package's parameter files: the MRF absorber (`kind = "mrf_absorber"`, as
datasets/seeds/hou2023_mrf_absorber.toml) and the active-damping actuator (`kind =
"active_damping"`, as datasets/seeds/sahu2024_active_damping.toml), a host mode with its cut and
uncertainty (`kind = "host_and_cut"`, as datasets/seeds/dogan2024_host_milling.toml). None gives
the defaults (seed 004's absorber, seed 000's actuator). An absorber file may also hold `[mrf]
zeta_per_tesla` (measured extra damping) and a `[drive]` table overriding `CoilDrive`'s assumed
drive and thermal values (e.g. the modulus temperature law); `posedyn gap --out` writes both."""

from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass, fields
from pathlib import Path

from absorber.active_damping import Actuator, ControlConfig
from absorber.coil_dynamics import CoilDrive
from absorber.mrf import MRFAbsorber
from absorber.robust import HostUncertainty
from absorber.tuning import Host, known_tunings, remember_tunings
from posedyn.errors import InputError, check_non_negative, check_positive
from posedyn.io.atomic import write_text_atomic
from posedyn.io.params import check_numbers, named_as, read_params, reading
from posedyn.stability.cutting import Cut


#: The keys of an absorber file's tables that `read_absorber` reads (others there are refused: a
#: misspelt optional key would silently keep its default), and MRFAbsorber's fields as the file
#: names them (with the factor to the file's unit).
ABSORBER_KEYS = {
    "absorber": ("mass_kg", "r1_m", "r2_m", "l1_m", "w1_m", "h1_m", "h2_m", "elastomer_shear_modulus_pa", "loss_factor_elastomer"),
    "mrf": ("model", "density_kg_per_m3", "g0_pa", "ginf_pa", "a1", "a2", "loss_factor_mrf", "zeta_per_tesla"),
    "field": ("min_mt", "max_mt"),
}
ABSORBER_FILE_NAMES = {"g2_pa": ("absorber.elastomer_shear_modulus_pa", None), "field_min_t": ("field.min_mt", 1e3), "field_max_t": ("field.max_mt", 1e3),
                       **{k: (f"absorber.{k}", None) for k in ("mass_kg", "r1_m", "r2_m", "l1_m", "w1_m", "h1_m", "h2_m", "loss_factor_elastomer")},
                       **{k: (f"mrf.{k}", None) for k in ("g0_pa", "ginf_pa", "a1", "a2", "loss_factor_mrf", "zeta_per_tesla")}}


def read_absorber(path: str | os.PathLike | None) -> MRFAbsorber:
    """The `[absorber]`, `[mrf]`, `[field]` tables of an absorber parameter file."""
    if path is None:
        return MRFAbsorber()
    p = read_params(path, kind="mrf_absorber")
    check_numbers(p, path, text=("mrf.model",))
    for table, allowed in ABSORBER_KEYS.items():
        for key in p.get(table, {}):
            if key not in allowed:
                raise InputError(f"one of the keys {', '.join(allowed)} in [{table}]", got=key, file=str(Path(path)), column=f"{table}.{key}")
    with reading(path, "absorber file"), named_as(ABSORBER_FILE_NAMES, in_expected=True):
        a, m, f = p["absorber"], p["mrf"], p["field"]
        if "density_kg_per_m3" in m:  # documentation of the fluid (no model uses it), but never a wrong one
            check_positive("mrf.density_kg_per_m3", m["density_kg_per_m3"])
        return MRFAbsorber(
            mass_kg=a["mass_kg"], r1_m=a["r1_m"], r2_m=a["r2_m"], l1_m=a["l1_m"], w1_m=a["w1_m"], h1_m=a["h1_m"], h2_m=a["h2_m"],
            g2_pa=a["elastomer_shear_modulus_pa"], g0_pa=m["g0_pa"], ginf_pa=m["ginf_pa"], a1=m["a1"], a2=m["a2"],
            field_min_t=f["min_mt"] * 1e-3, field_max_t=f["max_mt"] * 1e-3,
            **{k: m[k] for k in ("loss_factor_mrf", "zeta_per_tesla") if k in m},
            **{k: a[k] for k in ("loss_factor_elastomer",) if k in a},
        )


def read_drive(path: str | os.PathLike | None) -> CoilDrive:
    """The coil drive of an absorber file: `CoilDrive`'s assumed defaults, with the values of an
    optional `[drive]` table (its field names, e.g. the fluid's modulus temperature law
    `modulus_tempco_per_k`, `modulus_reference_c` as `posedyn gap` measures them)."""
    if path is None:
        return CoilDrive()
    p = read_params(path, kind="mrf_absorber")
    check_numbers(p, path, text=("mrf.model",))
    table = p.get("drive", {})
    known = {f.name for f in fields(CoilDrive)}
    for key in table:
        if key not in known:
            raise InputError("a [drive] key among " + ", ".join(sorted(known)), got=key, file=str(Path(path)), column=f"drive.{key}")
    with reading(path, "absorber file"):
        return CoilDrive(**{k: float(v) for k, v in table.items()})


def read_actuator(path: str | os.PathLike | None) -> ControlConfig:
    """The actuator and control settings of an active-damping file."""
    if path is None:
        return ControlConfig()
    p = read_params(path, kind="active_damping")
    check_numbers(p, path, text=("control.mount_axis", "control.virtual_layout"))
    with reading(path, "actuator file"):
        a = p["actuator"]
        check_non_negative("actuator.horizontal.delay_ms", a["horizontal"]["delay_ms"])
        actuator = Actuator(
            transducer_n_per_v=a["horizontal"]["transducer_constant_n_per_v"],
            zeta=a["horizontal"]["zeta"],
            fn_horizontal_hz=a["horizontal"]["fn_hz"],
            fn_vertical_hz=a["vertical"]["fn_hz"],
            delay_s=a["horizontal"]["delay_ms"] * 1e-3,
            force_limit_n=a["force_limit_n"],
        )
        control = p.get("control", {})
        keys = ("mount_axis", "disturbance_n", "margin_db", "virtual_layout", "virtual_mass_ratio")
        for key in control:
            if key not in keys:
                raise InputError("a [control] key among " + ", ".join(keys), got=key, column=f"control.{key}")
        with named_as({k: (f"control.{k}", None) for k in keys}):
            return ControlConfig(actuator=actuator, source=str(path), **{k: control[k] for k in keys if k in control})


@dataclass(frozen=True)
class HostCase:
    """A host file: the host mode and its uncertainty, the cut, the absorber's mass ratio, the
    feed per tooth and the actuator's force limit (None where the file has none)."""

    uncertainty: HostUncertainty
    cut: Cut
    mass_ratio: float | None = None
    feed_per_tooth_m: float | None = None
    force_limit_n: float | None = None


def read_host(path: str | os.PathLike) -> HostCase:
    """The `[host]` mode, its `[uncertainty]` (relative standard deviations; seed 002 Table 3's
    when absent), the `[cut]` (with its optional feed_per_tooth_mm), `[absorber] mass_ratio` and
    `[actuator] force_limit_n` of a host file."""
    p = read_params(path, kind="host_and_cut")
    check_numbers(p, path, text=("cut.milling",))
    with reading(path, "host file"):
        h, c, u = p["host"], p["cut"], p.get("uncertainty", {})
        host = Host(fn_hz=float(h["fn_hz"]), k_n_per_m=float(h["k_n_per_m"]), zeta=float(h["zeta"]))
        uncertainty = HostUncertainty(host, **{k: float(u[k]) for k in ("k_rel_std", "fn_rel_std", "zeta_rel_std") if k in u})
        cut = Cut(teeth=int(c["teeth"]), kt_pa=float(c["kt_n_per_m2"]), kn_pa=float(c["kr_n_per_m2"]), radial_immersion=float(c["radial_immersion"]), milling=c.get("milling", "down"))
        mass_ratio = p.get("absorber", {}).get("mass_ratio")
        feed = c.get("feed_per_tooth_mm")
        limit = p.get("actuator", {}).get("force_limit_n")
        for name, value in (("feed_per_tooth_mm", feed), ("force_limit_n", limit), ("mass_ratio", mass_ratio)):
            if value is not None:
                check_positive(name, float(value))
        return HostCase(uncertainty, cut, None if mass_ratio is None else float(mass_ratio),
                        None if feed is None else float(feed) * 1e-3, None if limit is None else float(limit))


#: Where absorber optima are kept between runs: $POSEDYN_CACHE_DIR, else ~/.cache/posedyn.
CACHE_ENV = "POSEDYN_CACHE_DIR"
TUNINGS_SCHEMA = 1


def tuning_cache_path() -> Path:
    return Path(os.environ.get(CACHE_ENV) or Path.home() / ".cache" / "posedyn") / "absorber_tunings.json"


def load_tuning_cache(path: Path | None = None) -> int:
    """Remember the optima a previous run kept (each costs a differential evolution of seconds);
    a missing file is nothing, an unreadable one is ignored with a warning (it is a cache)."""
    path = path or tuning_cache_path()
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        if doc.get("schema_version") != TUNINGS_SCHEMA:
            raise ValueError(f"schema_version {doc.get('schema_version')!r}, expected {TUNINGS_SCHEMA}")
        return remember_tunings(doc["tunings"])
    except FileNotFoundError:
        return 0
    except (OSError, ValueError, KeyError, TypeError, AttributeError, InputError) as exc:
        logging.getLogger("posedyn").warning("absorber tuning cache %s ignored: %s", path, exc)
        return 0


def save_tuning_cache(path: Path | None = None) -> None:
    """Keep this process's optima with those already in the file (atomic write; best effort)."""
    path = path or tuning_cache_path()
    load_tuning_cache(path)  # another process may have added some meanwhile
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(path, json.dumps({"schema_version": TUNINGS_SCHEMA, "tunings": known_tunings()}, indent=1) + "\n")
    except OSError as exc:
        logging.getLogger("posedyn").warning("absorber tuning cache %s not written: %s", path, exc)
