"""What the commands share: output helpers and the cut's file. Light on purpose: every command
imports it, so it imports nothing heavy (the modes at requested poses, which need a model or the
robot twin, are `service.cli.inputs`)."""

from __future__ import annotations

import contextlib
import json
import math
import os
import sys
from enum import Enum

from pathlib import Path
from typing import Optional

from rich.console import Console

from posedyn.errors import InputError
from posedyn.io.json_values import json_ready

console = Console(width=None if sys.stdout.isatty() else 140)


def output_file(path: Path | None, option: str) -> Path | None:
    """An output file checked before any work (a wrong path used to end in a traceback after the
    whole computation): not a directory, in a folder that exists and can be written."""
    if path is None:
        return None
    if path.is_dir():
        raise InputError("a file to write, not a directory", got=str(path), file=str(path), column=option)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise InputError("a file in an existing folder", got=f"no folder {folder}", file=str(path), column=option)
    if not os.access(folder, os.W_OK):
        raise InputError("a file in a folder this user can write", got=f"folder {folder} is read-only", file=str(path), column=option)
    return path


def output_folder(path: Path, option: str) -> Path:
    """An output folder checked before any work: a folder (made later if missing) whose nearest
    existing ancestor is a folder this user can write ('afile: File exists' after the whole
    computation, for a file given as the folder)."""
    if path.exists() and not path.is_dir():
        raise InputError("a folder to write into, not a file", got=str(path), file=str(path), column=option)
    existing = path
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir() or not os.access(existing, os.W_OK):
        raise InputError("a folder this user can write (or a new one in such a folder)", got=str(existing), file=str(path), column=option)
    return path


#: Library field -> (the command-line flag that gives it, factor from SI to the flag's unit).
FLAGS = {
    "teeth": ("--teeth", None), "kt_pa": ("--kt-mpa", 1e-6), "kn_pa": ("--kn-mpa", 1e-6), "radial_immersion": ("--radial-immersion", None),
    "milling": ("--milling", None), "feed_angle_deg": ("--feed-angle-deg", None), "tool_diameter_m": ("--tool-diameter-mm", 1e3),
    "radial_depth_m": ("--radial-depth-mm", 1e3), "axial_depth_m": ("--axial-depth-mm", 1e3), "feed_per_tooth_m": ("--feed-per-tooth-mm", 1e3),
    "helix_rad": ("--helix-deg", 180.0 / math.pi),
}


@contextlib.contextmanager
def flag_errors(extra: dict | None = None):
    """An InputError about a value that came from a flag names the flag and gives the value in
    the flag's unit (not the library's field in SI: 'column kt_pa ... got -700000000.0');
    `extra`: a command's own fields and flags, as FLAGS ('fn_hz' is --host-fn-hz in one command)."""
    try:
        yield
    except InputError as exc:
        if exc.file is not None:  # a file's value: named by the file
            raise
        raise exc.renamed(FLAGS | (extra or {})) from None


def soft_mode_warnings(table, file) -> list[str]:
    """`ModalTable.soft_modes` as warnings on `file` (N/mm written as N/m makes every depth 1000
    times too small): what `data check` and the stability commands print."""
    return [f"{file}: {line}: is the unit N/m (not N/mm)?" for line in table.soft_modes()]


def finite_or_none(value: float):
    """JSON has no inf or NaN: a depth that never chatters is null."""
    return float(value) if math.isfinite(value) else None


def print_json(value) -> None:
    print(json.dumps(json_ready(value), indent=2, allow_nan=False))


class Milling(str, Enum):
    down = "down"
    up = "up"


def resolve_cut(cut: Optional[Path], model_dir: Optional[Path]) -> Path:
    """The one rule for the cut of every command: `--cut`, else the model directory's cut.toml
    (`posedyn train --cut` stores it), else an error naming both."""
    if cut is not None:
        return cut
    if model_dir is not None and (Path(model_dir) / "cut.toml").exists():
        return Path(model_dir) / "cut.toml"
    raise InputError("--cut CUT.toml, or a model directory trained with --cut (MODEL_DIR/cut.toml)", got="neither", column="--cut")
