"""The robot and its elastodynamic twin (seed 003): kinematics on Pinocchio (`kinematics`),
pose rows to tool poses (`poses`), joint stiffness to tool-tip modes (`twin`), synthetic
modal-test campaigns (`campaign`) and the named effects they can hide (`twin_effects`)."""

from posedyn.robot.campaign import GridPose, Noise, direction_rows, generate_campaign, pose_modes
from posedyn.robot.kinematics import Robot, ToolPose, abc_from_rotation, rotation_from_abc, rotation_from_beta
from posedyn.robot.poses import pose_rotation, pose_set, reachable_joints, tool_pose, with_joints
from posedyn.robot.twin import TwinModes, TwinParameters, twin_modes

__all__ = [
    "GridPose", "Noise", "Robot", "ToolPose", "TwinModes", "TwinParameters", "abc_from_rotation", "direction_rows",
    "generate_campaign", "pose_modes", "pose_rotation", "pose_set", "reachable_joints", "rotation_from_abc", "rotation_from_beta", "tool_pose", "twin_modes",
    "with_joints",
]
