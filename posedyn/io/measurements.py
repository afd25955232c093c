"""Measurement-campaign files (CSV) for the gap workflow.

Columns: `pose_id`, the pose columns (`x_mm, y_mm, z_mm` and `beta_deg` or `a_deg, b_deg,
c_deg`), `quantity` (one of QUANTITIES), `direction` (x, y or z for modal quantities, else
empty), `mode` (1, 2, ... for modal quantities, else empty), `value`, optional `std` (default
from DEFAULT_STD), and any number of numeric condition columns (empty where a row does not have
the condition): e.g. `rpm`, `field_mt`, `temperature_c`, `absorber_angle_deg`, `device` (0/1),
`moving` (0/1), `fixture` (0/1), `force_n`. Surface location error rows (`sle_um`, + = undercut,
`direction` = the surface normal x or y, `std` required) need `rpm`, `teeth`, `tool_diameter_mm`,
`radial_depth_mm`, `axial_depth_mm`, `feed_per_tooth_mm`, optional `up_milling` (0/1),
`helix_deg`, `kt_mpa`, `kn_mpa`, `feed_mm_per_min`.
"""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path

import numpy as np

from posedyn.errors import InputError
from posedyn.gap import Measurements

QUANTITIES = ("fn_hz", "k_n_per_m", "k_xy_n_per_m", "critical_depth_mm", "absorber_fn_hz", "absorber_zeta", "sle_um")
#: Relative std used when a row has none (k_xy and sle_um: relative to nothing, so it must be given).
DEFAULT_STD = {"fn_hz": 0.003, "k_n_per_m": 0.03, "critical_depth_mm": 0.03, "absorber_fn_hz": 0.005, "absorber_zeta": 0.05}
TEXT = ("pose_id", "quantity", "direction")
#: Quantities that are positive by nature (k_xy and sle_um are signed).
POSITIVE = ("fn_hz", "k_n_per_m", "critical_depth_mm", "absorber_fn_hz", "absorber_zeta")
REQUIRED = ("pose_id", "x_mm", "y_mm", "z_mm", "quantity", "value")


def read_measurements(path: str | os.PathLike) -> Measurements:
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8") as f:
            reader = csv.DictReader(f)
            header = reader.fieldnames or []
            rows = list(reader)
    except OSError as exc:
        raise InputError("a readable measurement file", got=exc.strerror, file=str(path)) from None
    where = dict(file=str(path))
    missing = [c for c in REQUIRED if c not in header]
    if missing:
        raise InputError("the measurement columns " + ", ".join(REQUIRED), got=f"missing {missing}", column=missing[0], **where)
    if not rows:
        raise InputError("at least one measurement row", got=0, **where)
    numeric = [c for c in header if c not in TEXT]
    columns = {c: np.full(len(rows), np.nan) for c in numeric}
    seen = {}
    for i, row in enumerate(rows, 1):
        line = i + 1
        key = tuple((row.get(c) or "").strip() for c in header)
        if key in seen:  # a pasted copy would count as a second measurement
            raise InputError(f"each measurement once (row {i} repeats row {seen[key]})", got=row.get("quantity"), row=i, line=line, column="value", **where)
        seen[key] = i
        q = row["quantity"]
        if q not in QUANTITIES:
            raise InputError("a quantity among " + ", ".join(QUANTITIES), got=q, row=i, line=line, column="quantity", **where)
        for c in numeric:
            text = (row.get(c) or "").strip()
            if text == "":
                continue
            try:
                value = float(text)
            except ValueError:
                raise InputError("a number", got=text, row=i, line=line, column=c, **where) from None
            if not math.isfinite(value):
                raise InputError("a finite number", got=text, row=i, line=line, column=c, **where)
            columns[c][i - 1] = value
        for c in ("x_mm", "y_mm", "z_mm", "value"):
            if not np.isfinite(columns[c][i - 1]):
                raise InputError("a number", got=row.get(c), row=i, line=line, column=c, **where)
        if q in POSITIVE and not columns["value"][i - 1] > 0:
            raise InputError(f"a {q} > 0", got=row.get("value"), row=i, line=line, column="value", **where)
        if q in ("fn_hz", "k_n_per_m") and (row.get("direction") not in ("x", "y", "z") or not np.isfinite(columns.get("mode", np.array([np.nan] * len(rows)))[i - 1])):
            raise InputError("direction x|y|z and a mode number for a modal quantity", got=(row.get("direction"), row.get("mode")), row=i, line=line, column="direction", **where)
        if q == "sle_um" and row.get("direction") not in ("x", "y"):
            raise InputError("direction x or y (the surface normal) for an sle_um row", got=row.get("direction"), row=i, line=line, column="direction", **where)
        std = columns.get("std")
        if std is not None and np.isfinite(std[i - 1]) and std[i - 1] <= 0:
            raise InputError("std > 0", got=std[i - 1], row=i, line=line, column="std", **where)
    value = columns.pop("value")
    std = columns.pop("std", np.full(len(rows), np.nan))
    quantity = np.array([r["quantity"] for r in rows])
    default = np.array([DEFAULT_STD.get(q, np.nan) for q in quantity]) * np.abs(value)
    std = np.where(np.isfinite(std), std, default)
    bad = np.flatnonzero(~(np.isfinite(std) & (std > 0)))
    if len(bad):
        raise InputError("a std > 0 (give the std column for this quantity)", got=quantity[bad[0]], row=int(bad[0]) + 1, line=int(bad[0]) + 2, column="std", **where)
    mode = columns.pop("mode", np.full(len(rows), np.nan))
    return Measurements(
        quantity=quantity,
        value=value,
        std=std,
        pose_id=np.array([r["pose_id"] for r in rows]),
        direction=np.array([r.get("direction") or "" for r in rows]),
        mode=mode,
        conditions=columns,
    )


def format_measurements(m: Measurements, condition_order=None) -> str:
    names = list(condition_order or m.conditions)
    pose = [c for c in ("x_mm", "y_mm", "z_mm", "beta_deg", "a_deg", "b_deg", "c_deg") if c in names]
    rest = [c for c in names if c not in pose]
    header = ["pose_id"] + pose + ["quantity", "direction", "mode", "value", "std"] + rest
    lines = [",".join(header)]
    for i in range(len(m)):
        cells = [str(m.pose_id[i])] + [_num(m.conditions[c][i]) for c in pose]
        cells += [str(m.quantity[i]), str(m.direction[i]), "" if not np.isfinite(m.mode[i]) else str(int(m.mode[i])), repr(float(m.value[i])), repr(float(m.std[i]))]
        cells += [_num(m.conditions[c][i]) for c in rest]
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"


def _num(v) -> str:
    return "" if not np.isfinite(v) else repr(float(v))
