"""Model directories: `model.json` (schema version, method, features, hyperparameters,
training-data hash, twin parameters) plus `arrays.npz` (training inputs and standardised
targets) and, for the physics method, `robot.urdf`. No pickle: loading rebuilds every object
from these plain files, and refuses a schema version it does not know."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from posedyn import __version__
from posedyn.errors import InputError
from posedyn.io.twin_file import load_twin
from posedyn.posemodel import GP
from posedyn.posemodel import PhysicsPrior, PoseModel
from posedyn.posemodel import CROSS, parse_target
from posedyn.robot import Robot
from posedyn.robot.twin import TwinParameters
from posedyn.table import Mode

SCHEMA_VERSION = 1
#: What a model directory holds (`cut.toml`: the default cut `posedyn train --cut` adds).
MODEL_FILES = frozenset({"model.json", "arrays.npz", "robot.urdf", "cut.toml"})


def check_model_target(folder: str | os.PathLike) -> Path:
    """`folder` where `save_model` may write: a new path, an empty directory, or a model directory
    (model.json and nothing but MODEL_FILES), which is replaced. Anything else is refused: it
    would be deleted with the directory it replaces."""
    folder = Path(folder)
    if not folder.exists():
        return folder
    expected = "a new path, an empty directory or a model directory to replace (model.json, arrays.npz, robot.urdf, cut.toml only)"
    if not folder.is_dir():
        raise InputError(expected, got="an existing file", file=str(folder))
    entries = {p.name for p in folder.iterdir()}
    others = sorted(entries - MODEL_FILES)
    if others:
        raise InputError(expected, got="a directory that also holds " + ", ".join(others[:3]) + (", ..." if len(others) > 3 else ""), file=str(folder))
    if entries and "model.json" not in entries:
        raise InputError(expected, got="a directory without model.json", file=str(folder))
    return folder


def save_model(model: PoseModel, folder: str | os.PathLike) -> None:
    """Write the model directory atomically (a temporary folder renamed into place); a folder
    that is there already must be one `check_model_target` accepts."""
    folder = check_model_target(folder).resolve()  # resolved: "." has no name to rename
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=folder.parent, prefix=f".{folder.name}."))
    try:
        doc = {
            "schema_version": SCHEMA_VERSION,
            "created_by": f"posedyn {__version__}",
            "method": model.method,
            "features": model.features_,
            "fixed_pose": model.fixed_pose_,
            "x_mean": model.x_mean_.tolist(),
            "x_scale": model.x_scale_.tolist(),
            "targets": model.targets_,
            "y_mean": model.y_mean_.tolist(),
            "y_scale": model.y_scale_.tolist(),
            "groups": model.groups_,
            "gps": [
                {
                    "theta": gp.theta.tolist(),
                    "length_scales": gp.length_scales.tolist(),
                    "task_covariance": gp.task_covariance.tolist(),
                    "noise_variances": gp.noise_variances.tolist(),
                }
                for gp in model.gps_
            ],
            "n_poses": model.n_poses_,
            "training_data_hash": model.training_hash_,
            "physics": None,
        }
        if model.physics_ is not None:
            physics = dict(model.physics_)
            if physics.get("used"):
                prior = model.prior_model_
                params = prior.params
                physics.update(
                    robot_urdf="robot.urdf",
                    robot_name=prior.robot.name,
                    prior_targets=[bool(v) for v in model.prior_targets_],
                    twin={
                        "joint_stiffness_nm_per_rad": list(params.joint_stiffness_nm_per_rad),
                        "zeta": params.zeta,
                        "robot_modes_per_direction": params.robot_modes_per_direction,
                        "flange_mass_kg": params.flange_mass_kg,
                        "flange_mass_offset_m": list(params.flange_mass_offset_m),
                        "gravity_softening_per_knm": params.gravity_softening_per_knm,
                        "tip_mass_kg": params.tip_mass_kg,
                        "spindle_modes": {d: [[m.fn_hz, m.zeta, m.k_n_per_m] for m in ms] for d, ms in params.spindle_modes.items()},
                    },
                )
                (tmp / "robot.urdf").write_text(prior.robot.urdf_xml, encoding="utf-8")
            doc["physics"] = physics
        (tmp / "model.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
        np.savez(tmp / "arrays.npz", X_train=model.X_train_, Z_train=model.Z_train_)
        old = None
        if folder.exists():
            old = Path(tempfile.mkdtemp(dir=folder.parent, prefix=f".{folder.name}.old."))
            os.replace(folder, old / "model")
        os.replace(tmp, folder)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def model_robot(model: PoseModel, twin: str | os.PathLike | None = None) -> Robot:
    """The robot that decides which poses a model can be asked about (README, Defaults): the
    model's own twin (physics models carry it), else the twin file `twin`, else the shipped one."""
    return model.twin[0] if model.twin is not None else load_twin(twin)[0]


def load_model(folder: str | os.PathLike) -> PoseModel:
    folder = Path(folder)
    path = folder / "model.json"
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError("a model directory with model.json", got=exc.strerror, file=str(path)) from None
    except json.JSONDecodeError as exc:
        raise InputError("valid JSON", got=str(exc), file=str(path), line=exc.lineno) from None
    except UnicodeDecodeError as exc:
        raise InputError("UTF-8 text", got=f"byte offset {exc.start}", file=str(path)) from None
    if not isinstance(doc, dict):
        raise InputError("a JSON object", got=type(doc).__name__, file=str(path))
    version = doc.get("schema_version")
    if version != SCHEMA_VERSION:
        raise InputError(f"schema_version {SCHEMA_VERSION} (this posedyn reads only that)", got=version, file=str(path), column="schema_version")
    try:
        with np.load(folder / "arrays.npz", allow_pickle=False) as arrays:
            X, Z = arrays["X_train"], arrays["Z_train"]
    except (OSError, KeyError, ValueError, zipfile.BadZipFile, EOFError) as exc:  # (a truncated or foreign file: BadZipFile)
        raise InputError("arrays.npz with X_train and Z_train", got=f"{type(exc).__name__}: {exc}", file=str(folder / "arrays.npz")) from None
    try:
        model = PoseModel(method=doc["method"], features=doc["features"])
        model.features_ = list(doc["features"])
        model.fixed_pose_ = {str(k): float(v) for k, v in doc.get("fixed_pose", {}).items()}  # (absent before 2026-12-04: none known)
        model.x_mean_, model.x_scale_ = np.array(doc["x_mean"]), np.array(doc["x_scale"])
        model.targets_ = list(doc["targets"])

        model.cross_ = np.array([parse_target(t)[2] in CROSS for t in model.targets_], dtype=bool)
        model.y_mean_, model.y_scale_ = np.array(doc["y_mean"]), np.array(doc["y_scale"])
        model.groups_ = [list(g) for g in doc["groups"]]
        model.X_train_, model.Z_train_ = X, Z
        model.gps_ = [GP(theta=np.array(g["theta"]), X=X, Y=Z[:, group]) for g, group in zip(doc["gps"], model.groups_)]
        model.n_poses_ = doc["n_poses"]
        model.training_hash_ = doc["training_data_hash"]
        model.physics_ = doc["physics"]
        if model.physics_ and model.physics_.get("used"):
            twin = model.physics_["twin"]
            params = TwinParameters(
                joint_stiffness_nm_per_rad=tuple(twin["joint_stiffness_nm_per_rad"]),
                zeta=twin["zeta"],
                robot_modes_per_direction=twin["robot_modes_per_direction"],
                flange_mass_kg=twin["flange_mass_kg"],
                flange_mass_offset_m=tuple(twin["flange_mass_offset_m"]),
                gravity_softening_per_knm=twin.get("gravity_softening_per_knm", 0.0),
                tip_mass_kg=twin.get("tip_mass_kg", 0.0),
                spindle_modes={d: tuple(Mode(*m) for m in ms) for d, ms in twin["spindle_modes"].items()},
            )
            robot = Robot.from_xml((folder / model.physics_["robot_urdf"]).read_text(encoding="utf-8"), model.physics_.get("robot_name", ""))
            model.prior_model_ = PhysicsPrior(robot, params, np.array(model.physics_["stiffness_scales"]), params.robot_modes_per_direction,
                                              model.physics_.get("mode_map"))  # (absent before 2026-12-04: mode m was the twin's row m)
            model.prior_targets_ = np.array(model.physics_["prior_targets"])
            model.twin = (robot, params)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        raise InputError("a complete model.json", got=f"{type(exc).__name__}: {exc}", file=str(path)) from None
    except OSError as exc:  # the robot file a physics model names
        raise InputError("the robot file model.json names", got=exc.strerror, file=str(exc.filename or path)) from None
    return model
