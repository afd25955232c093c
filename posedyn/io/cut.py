"""Cut parameter files (TOML, `kind = "cut"`): `[cut] rpm, teeth, kt_mpa, kn_mpa,
radial_immersion, milling, feed_angle_deg, tool_diameter_mm`, optional `[stability] steps` (an
expert override: semi-discretization with that many steps instead of the converged engine) and
optional `[sle] helix_deg, axial_depth_mm, feed_per_tooth_mm` and `offset_um` (the surface
location error of this cut; the radial depth is radial_immersion x tool_diameter_mm; the offset,
default 0, is added to the SLE: a robot path offset, a tool radius error, as `posedyn gap`
writes them)."""

from __future__ import annotations

import math
import os

from posedyn.io.params import check_keys, check_numbers, named_as, number, read_params, reading, whole_number
from posedyn.sle import SleCut
from posedyn.stability import Cut
from posedyn.stability.cutting import check_rpm


#: The tables and keys of a cut file (anything else is refused: a typo would take a default).
CUT_KEYS = {
    "cut": ("rpm", "teeth", "kt_mpa", "kn_mpa", "radial_immersion", "milling", "feed_angle_deg", "tool_diameter_mm"),
    "stability": ("steps",),
    "sle": ("helix_deg", "axial_depth_mm", "feed_per_tooth_mm", "offset_um", "engagement"),
}


def _read(path: str | os.PathLike) -> dict:
    p = read_params(path, kind="cut")
    check_keys(p, CUT_KEYS, path, "cut file")
    check_numbers(p, path, text=("cut.milling", "sle.engagement"))
    return p


def read_cut(path: str | os.PathLike) -> tuple[Cut, float, int | None]:
    """(Cut, rpm, steps) from a cut file; steps None unless the file overrides the engine."""
    p = _read(path)
    with reading(path, "cut file"):
        c = p["cut"]
        with named_as(FILE_KEYS):
            cut = Cut(
                teeth=whole_number(c["teeth"], "cut.teeth"),
                kt_pa=number(c["kt_mpa"], "cut.kt_mpa") * 1e6,
                kn_pa=number(c["kn_mpa"], "cut.kn_mpa") * 1e6,
                radial_immersion=number(c["radial_immersion"], "cut.radial_immersion"),
                milling=c.get("milling", "down"),
                feed_angle_deg=number(c.get("feed_angle_deg", 0.0), "cut.feed_angle_deg"),
            )
        rpm = check_rpm(number(c["rpm"], "cut.rpm"), "cut.rpm")
        steps = p.get("stability", {}).get("steps")
        steps = None if steps is None else whole_number(steps, "stability.steps")
    return cut, rpm, steps


#: Cut's fields as a cut file names them, with the factor to the file's unit.
FILE_KEYS = {"kt_pa": ("cut.kt_mpa", 1e-6), "kn_pa": ("cut.kn_mpa", 1e-6), "teeth": ("cut.teeth", None), "radial_immersion": ("cut.radial_immersion", None),
             "milling": ("cut.milling", None), "feed_angle_deg": ("cut.feed_angle_deg", None)}


def read_sle_cut(path: str | os.PathLike) -> tuple[SleCut, float] | None:
    """(SLE cut, offset in m added to the SLE) of a cut file's `[sle]` section (None when the file
    has none); `[sle] engagement` "nominal" (default, seed 001's fixed angles) or "geometric"."""
    p = _read(path)
    if "sle" not in p:
        return None
    with reading(path, "cut file"):
        c, s = p["cut"], p["sle"]
        diameter = number(c["tool_diameter_mm"], "cut.tool_diameter_mm") * 1e-3
        offset_m = number(s.get("offset_um", 0.0), "sle.offset_um") * 1e-6
        return SleCut(
            teeth=whole_number(c["teeth"], "cut.teeth"),
            kt_pa=number(c["kt_mpa"], "cut.kt_mpa") * 1e6,
            kn_pa=number(c["kn_mpa"], "cut.kn_mpa") * 1e6,
            tool_diameter_m=diameter,
            helix_rad=math.radians(number(s["helix_deg"], "sle.helix_deg")),
            radial_depth_m=number(c["radial_immersion"], "cut.radial_immersion") * diameter,
            axial_depth_m=number(s["axial_depth_mm"], "sle.axial_depth_mm") * 1e-3,
            feed_per_tooth_m=number(s["feed_per_tooth_mm"], "sle.feed_per_tooth_mm") * 1e-3,
            milling=c.get("milling", "down"),
            engagement=s.get("engagement", "nominal"),
        ), offset_m
