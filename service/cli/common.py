"""What the commands share: output helpers and the modes at requested poses (a modal table, a
model's predictions or the robot twin's own modes)."""

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

from absorber.chain import PoseModes, twin_pose_modes
from posedyn.errors import InputError
from posedyn.io import read_modal_table, read_pose_table
from posedyn.io.json_values import json_ready
from posedyn.io.model_dir import load_model
from posedyn.io.twin_file import load_twin
from posedyn.table import PoseSet
from posedyn.uncertainty import distributions_from_table

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


def finite_or_none(value: float):
    """JSON has no inf or NaN: a depth that never chatters is null."""
    return float(value) if math.isfinite(value) else None


def print_json(value) -> None:
    print(json.dumps(json_ready(value), indent=2, allow_nan=False))


class Milling(str, Enum):
    down = "down"
    up = "up"


def modal_table_for(model_dir: Optional[Path], modes: Optional[Path], poses: Path):
    """The modes at the requested poses: rows of a modal table, or a model's predictions."""
    return modal_input_for(model_dir, modes, poses, distributions=False)[0]


def modal_input_for(model_dir: Optional[Path], modes: Optional[Path], poses, distributions: bool):
    """(modal table, the poses' distributions or None) at `poses` (a pose CSV or a PoseSet): with
    `distributions`, a model's predictive ones (correlated), else those of the table's std columns."""
    if (model_dir is None) == (modes is None):
        raise InputError("either MODEL_DIR or --modes MODAL.csv", column="--modes")
    pose_set = poses if isinstance(poses, PoseSet) else read_pose_table(poses)
    if modes is not None:
        table = read_modal_table(modes)
        missing = [p for p in pose_set.pose_id if p not in table.poses.pose_id]
        if missing:
            raise InputError("pose_ids present in the modal table", got=missing[:3], file=str(poses), column="pose_id")
        table = table.select_poses([table.poses.index(p) for p in pose_set.pose_id])
        _same_poses(pose_set, table.poses, None if isinstance(poses, PoseSet) else str(poses), str(modes))
        return table, distributions_from_table(table) if distributions else None
    model = load_model(model_dir)
    warn_outside_workspace(model, pose_set)
    try:
        table = model.predict_table(pose_set)
    except InputError as exc:
        raise exc.located(file=None if isinstance(poses, PoseSet) else str(poses)) from None
    return table, model.predict_distributions(pose_set, table) if distributions else None


def _same_poses(asked: PoseSet, table: PoseSet, file: Optional[str], table_file: str) -> None:
    """The poses asked for by pose_id from a modal table are where the table has them (a pose
    file's P5 at x = 1450 silently got the table's P5 at x = 1400, and `tool-change` wrote 1400)."""
    mine, theirs = asked.numeric_columns(), table.numeric_columns()
    for i in range(len(asked)):
        for column, values in mine.items():
            if column in theirs and not math.isclose(float(values[i]), float(theirs[column][i]), rel_tol=1e-9, abs_tol=1e-6):
                raise InputError(f"pose {asked.pose_id[i]} where {table_file} has it, {column} = {float(theirs[column][i]):g}", got=float(values[i]),
                                 file=file, row=i + 1, line=None if file is None else i + 2, column=column)


def warn_outside_workspace(model, pose_set: PoseSet) -> None:
    """The poses `posedyn serve` would refuse (outside the model's workspace), said on stderr (a
    command's --json output stays strict JSON)."""
    for line in model.outside_workspace(pose_set):
        print(f"warning: {line} (the model's workspace: the training poses' range widened by a quarter, at least 50 mm or 15 deg): "
              "the model has not seen the dynamics there, and `posedyn serve` refuses the pose (outside_workspace)", file=sys.stderr)


def twin_modes_at(twin: Path, poses: PoseSet, poses_file: Path) -> list[PoseModes]:
    """The twin file's own modes (all its robot modes, 3-D shapes) at every pose; every pose must
    be reachable."""
    found = twin_pose_modes(*load_twin(twin), poses)
    missing = [poses.pose_id[i] for i in range(len(poses)) if i not in found]
    if missing:
        raise InputError("poses the twin robot can reach", got=missing[:3], file=str(poses_file), column="pose_id")
    return [found[i] for i in range(len(poses))]


def resolve_cut(cut: Optional[Path], model_dir: Optional[Path]) -> Path:
    """The one rule for the cut of every command: `--cut`, else the model directory's cut.toml
    (`posedyn train --cut` stores it), else an error naming both."""
    if cut is not None:
        return cut
    if model_dir is not None and (Path(model_dir) / "cut.toml").exists():
        return Path(model_dir) / "cut.toml"
    raise InputError("--cut CUT.toml, or a model directory trained with --cut (MODEL_DIR/cut.toml)", got="neither", column="--cut")
