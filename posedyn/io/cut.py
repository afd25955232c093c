"""Cut parameter files (TOML, `kind = "cut"`): `[cut] rpm, teeth, kt_mpa, kn_mpa,
radial_immersion, milling, feed_angle_deg` and optional `[stability] steps`."""

from __future__ import annotations

import os
from pathlib import Path

from posedyn.errors import InputError
from posedyn.io.params import read_params
from posedyn.stability import Cut


def read_cut(path: str | os.PathLike) -> tuple[Cut, float, int]:
    """(Cut, rpm, steps) from a cut file."""
    p = read_params(path)
    where = dict(file=str(Path(path)))
    try:
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
    except KeyError as exc:
        raise InputError("this key in the cut file", got="missing", column=str(exc.args[0]), **where) from None
    except (TypeError, ValueError) as exc:
        raise InputError("numbers in the cut file", got=str(exc), **where) from None
    except InputError as exc:
        raise exc.located(**where) from None
    if not rpm > 0:
        raise InputError("rpm > 0", got=rpm, column="rpm", **where)
    return cut, rpm, steps
