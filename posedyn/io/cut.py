"""Cut parameter files (TOML, `kind = "cut"`): `[cut] rpm, teeth, kt_mpa, kn_mpa,
radial_immersion, milling, feed_angle_deg` and optional `[stability] steps`."""

from __future__ import annotations

import os
from pathlib import Path

from posedyn.errors import InputError
from posedyn.io.params import read_params, reading
from posedyn.stability import Cut


def read_cut(path: str | os.PathLike) -> tuple[Cut, float, int]:
    """(Cut, rpm, steps) from a cut file."""
    p = read_params(path)
    with reading(path, "cut file"):
        c = p["cut"]
        cut = Cut(
            teeth=int(c["teeth"]),
            kt_pa=float(c["kt_mpa"]) * 1e6,
            kn_pa=float(c["kn_mpa"]) * 1e6,
            radial_immersion=float(c["radial_immersion"]),
            milling=c.get("milling", "down"),
            feed_angle_deg=float(c.get("feed_angle_deg", 0.0)),
        )
        rpm = float(c["rpm"])
        steps = int(p.get("stability", {}).get("steps", 40))
    if not rpm > 0:
        raise InputError("rpm > 0", got=rpm, column="rpm", file=str(Path(path)))
    return cut, rpm, steps
