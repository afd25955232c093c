"""The modes at the poses a command asks for: rows of a modal table, a model's predictions (with
their distributions) or the robot twin's own modes."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Optional

from absorber.chain import PoseModes, twin_pose_modes
from posedyn.errors import InputError
from posedyn.io import read_modal_table, read_pose_table
from posedyn.io.model_dir import load_model, model_robot
from posedyn.io.twin_file import load_twin
from posedyn.robot import reachable_joints, with_joints
from posedyn.table import PoseSet
from posedyn.uncertainty import distributions_from_table


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
    found = reachable_joints(model_robot(model), pose_set)
    if len(found) < len(pose_set):  # (README, Defaults: the model's twin, else the shipped one, decides)
        far = [pose_set.pose_id[i] for i in range(len(pose_set)) if i not in found]
        raise InputError("poses the robot reaches (the model's twin, else the shipped KR R2700 twin; no inverse kinematics for these)", got=far[:3],
                         file=None if isinstance(poses, PoseSet) else str(poses), column="pose_id")
    warn_outside_workspace(model, pose_set)
    pose_set = with_joints(pose_set, found)  # (a physics prior's inverse kinematics once, here)
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
