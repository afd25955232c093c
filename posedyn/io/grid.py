"""Pose grids (TOML).

A grid file:

    [meta]
    kind = "pose_grid"
    source = "..."
    twin = "../robots/kr_r2700_twin.toml"     # optional, relative to this file

    [grid]                                    # the product of these lists (mm, deg) ...
    x_mm = [1300, 1500]
    y_mm = [-300, 300]
    z_mm = [600]
    beta_deg = [-60, 0, 60]                   # or a_deg, b_deg, c_deg lists

    [[poses]]                                 # ... and/or single poses
    x_mm = 1400
    y_mm = 0
    z_mm = 600
    beta_deg = 10

    [[effects]]                               # optional named effects (posedyn.robot.twin_effects)
    name = "device_mass"
    mass_kg = 8

Twin files are read by `posedyn.io.twin_file`.
"""

from __future__ import annotations

import itertools
import math
import os
from dataclasses import dataclass
from pathlib import Path

from posedyn.errors import InputError
from posedyn.io.params import read_params, reading
from posedyn.robot import ToolPose
from posedyn.robot.campaign import GridPose
from posedyn.robot.twin_effects import Effect, make_effect


@dataclass(frozen=True)
class Grid:
    poses: tuple[GridPose, ...]
    effects: tuple[Effect, ...]
    twin: Path | None
    source: str


def read_grid(path: str | os.PathLike) -> Grid:
    path = Path(path)
    p = read_params(path, kind="pose_grid")
    where = dict(file=str(path))
    poses: list[GridPose] = []
    with reading(path, "grid file"):
        if "grid" in p:
            poses += _product(p["grid"])
        for i, item in enumerate(p.get("poses", []), 1):
            try:
                poses += _product({k: [v] for k, v in item.items() if k != "label"}, label=item.get("label"))
            except InputError as exc:
                raise exc.located(row=i) from None
        effects = tuple(make_effect(e["name"], **{k: v for k, v in e.items() if k != "name"}) for e in p.get("effects", []))
    where = dict(file=str(path))
    if not poses:
        raise InputError("a [grid] table or [[poses]] entries", got="none", **where)
    labels = [g.label for g in poses]
    if len(set(labels)) != len(labels):
        raise InputError("distinct poses (labels repeat)", got=sorted({x for x in labels if labels.count(x) > 1})[:3], **where)
    twin = p["meta"].get("twin")
    twin_path = (path.parent / twin).resolve() if twin else None
    if twin_path is not None and not twin_path.is_file():  # named here: the grid said it, not the user
        raise InputError(f"a twin file (relative to the grid) at {twin_path}", got="missing", file=str(path), column="meta.twin")
    return Grid(tuple(poses), effects, twin_path, p["meta"]["source"])


def _numbers(table: dict, key: str) -> list[float]:
    values = table[key]
    values = values if isinstance(values, list) else [values]
    if not values or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values):
        raise InputError("a non-empty list of finite numbers", got=values, column=key)
    return [float(v) for v in values]


def _product(table: dict, label: str | None = None) -> list[GridPose]:
    xs, ys, zs = _numbers(table, "x_mm"), _numbers(table, "y_mm"), _numbers(table, "z_mm")
    has_beta = "beta_deg" in table
    has_abc = any(k in table for k in ("a_deg", "b_deg", "c_deg"))
    if has_beta == has_abc:
        raise InputError("either beta_deg or a_deg, b_deg, c_deg", got=sorted(table), column="beta_deg")
    out = []
    if has_beta:
        for x, y, z, b in itertools.product(xs, ys, zs, _numbers(table, "beta_deg")):
            name = label or f"x{x:g}_y{y:g}_z{z:g}_b{b:g}"
            out.append(GridPose(name, ToolPose.from_beta(x / 1e3, y / 1e3, z / 1e3, math.radians(b), name), beta_deg=b))
    else:
        for x, y, z, a, b, c in itertools.product(xs, ys, zs, _numbers(table, "a_deg"), _numbers(table, "b_deg"), _numbers(table, "c_deg")):
            name = label or f"x{x:g}_y{y:g}_z{z:g}_a{a:g}_b{b:g}_c{c:g}"
            out.append(GridPose(name, ToolPose.from_abc(x / 1e3, y / 1e3, z / 1e3, math.radians(a), math.radians(b), math.radians(c), name)))
    return out
