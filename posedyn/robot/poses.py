"""Pose rows to tool poses: the one conversion from a PoseSet's position and orientation
columns (A/B/C or seed 003's beta) to the tool pose the robot model takes, and back."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from posedyn.errors import InputError
from posedyn.robot.kinematics import Robot, ToolPose, abc_from_rotation, rotation_from_abc, rotation_from_beta
from posedyn.table import PoseSet


def pose_rotation(poses: PoseSet, i: int) -> np.ndarray:
    """The tool rotation (base frame) of pose i: R = Ry(pi/2) Rx(pi + beta) (seed 003) or the
    KUKA A/B/C (ZYX Euler) rotation."""
    if poses.orientation == "beta":
        return rotation_from_beta(math.radians(poses.orientation_deg[i, 0]))
    return rotation_from_abc(*np.radians(poses.orientation_deg[i]))


def tool_pose(poses: PoseSet, i: int) -> ToolPose:
    """Pose i of a PoseSet as a ToolPose (position in m, rotation, pose_id as label)."""
    return ToolPose(poses.position_m[i].copy(), pose_rotation(poses, i), poses.pose_id[i])


def pose_set(tool_poses: list[ToolPose], beta_deg: list[float | None] | None = None) -> PoseSet:
    """ToolPoses as a PoseSet: with beta columns when every pose has a beta, A/B/C otherwise."""
    beta = beta_deg is not None and all(b is not None for b in beta_deg)
    angles = [[b] for b in beta_deg] if beta else [np.degrees(abc_from_rotation(t.rotation)) for t in tool_poses]
    return PoseSet(
        pose_id=tuple(t.label for t in tool_poses),
        position_mm=np.array([np.asarray(t.position_m) * 1e3 for t in tool_poses]),
        orientation="beta" if beta else "abc",
        orientation_deg=np.array(angles, dtype=float),
    )


def reachable_joints(robot: Robot, poses: PoseSet, index=None) -> dict:
    """{pose index: joint angles (deg)} of the poses among `index` (all) that the robot reaches
    (inverse kinematics within the joint limits); the others are left out."""
    data = robot.model.createData()
    found = {}
    for i in range(len(poses)) if index is None else index:
        try:
            found[i] = np.degrees(robot.inverse(tool_pose(poses, i), data))
        except InputError:
            continue
    return found


def with_joints(poses: PoseSet, found: dict) -> PoseSet:
    """`poses` with the joint angles that `reachable_joints` found for every one of them ({pose
    index: deg}), or as they are where they carry joint columns (`pose_joints` takes those
    first): a model's prediction then does not solve the same inverse kinematics again."""
    if poses.joints_deg is not None:
        return poses
    return dataclasses.replace(poses, joints_deg=np.array([found[i] for i in range(len(poses))]))
