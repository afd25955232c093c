"""Pose models: Gaussian processes from robot pose to modal parameters (seed 003), single-task,
coregionalized multi-task, and with the twin as a physics prior (`model`), on the GP core in
`_gp` (kernels, likelihoods and their gradients)."""

from posedyn.posemodel._gp import GP, fit_gp, fit_gps
from posedyn.posemodel.model import (
    CROSS, METHODS, PARAMS, PhysicsPrior, PoseModel, check_folds, cross_validate, feature_matrix, parse_target, pose_joints,
    r2_score, select_features, suspect_measurements, table_targets, target_name, training_hash,
)

__all__ = [
    "CROSS", "GP", "METHODS", "PARAMS", "PhysicsPrior", "PoseModel", "check_folds", "cross_validate", "feature_matrix", "fit_gp", "fit_gps",
    "parse_target", "pose_joints", "r2_score", "select_features", "suspect_measurements", "table_targets", "target_name", "training_hash",
]
