"""What a sweep is: its inputs (`SweepSpec`, with a fingerprint over settings and file bytes),
the columns it writes and the poses it reads (a grid or a pose list / tool path)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from absorber.chain import POLICIES
from posedyn.errors import InputError, check_choice
from posedyn.io import read_pose_table
from posedyn.io.grid import read_grid
from posedyn.robot import pose_set

#: Columns of results.csv, in order (the pose columns and the per-mode columns come first).
RESULT_COLUMNS = (
    "reachable",
    "lowest_fn_hz",
    "lowest_fn_std_hz",
    "critical_depth_mm",
    "no_growth_depth_mm",
    "dominant_chatter_hz",
    "target_hz",
    "field_mt",
    "current_a",
    "absorber_feasible",
    "critical_depth_with_absorber_mm",
    "critical_depth_p95_mm",
    "critical_depth_cv_pct",
    "robust_tuning",
    "robust_target_hz",
    "robust_field_mt",
    "critical_depth_with_absorber_p95_mm",
    "robust_dvf_gain_ns_per_m",
    "actuator_direction",
    "dvf_gain_ns_per_m",
    "gain_margin_db",
    "controller_force_n",
    "dynamic_stiffness_gain_pct",
    "sle_um",
    "stability_method",
    "stability_rel_error",
    "flags",
)


#: Poses per chunk by default: the unit of work, of writing and of resuming. Continuation runs
#: within a chunk (every chunk's path starts from the seeds), so longer chunks cost less a pose:
#: 2026-12-07, poses 2000-2999 in one process, chunks of 250 / 500 / 1000: 55.2-57.2 / 53.3 /
#: 51.4 ms a pose; 5000-5499: 82.2 / 77.6. 500 keeps 20 chunks for two workers in a
#: 10,000-pose sweep (the last ones to land decide its end).
DEFAULT_CHUNK_SIZE = 500


@dataclass(frozen=True)
class SweepSpec:
    """The inputs of a sweep: file paths (absolute; every worker reads them itself) and settings.

    `model` (a model directory) or `twin` (a robot-twin file) gives the modes; `poses` is a grid
    (TOML) or a pose list (CSV); `cut` a cut file, optionally with an `[sle]` section;
    `steps` overrides the converged stability engine with the semi-discretization (expert use;
    its error is not estimated); None (default) or the cut file's `[stability] steps`;
    `robust_samples` > 0 adds the guaranteed depths over that many samples of each pose's modes
    (a model's predictive distribution; none for a twin, whose modes carry no uncertainty)."""

    poses: str
    cut: str
    model: str | None = None
    twin: str | None = None
    absorber: str | None = None
    actuator: str | None = None
    policy: str = "match"
    steps: int | None = None
    chunk_size: int = DEFAULT_CHUNK_SIZE
    robust_samples: int = 0  # > 0: the guaranteed depths (absorber.chain.robust_entries) of every pose

    def __post_init__(self):
        if (self.model is None) == (self.twin is None):
            raise InputError("either a model directory or a twin file", got={"model": self.model, "twin": self.twin}, column="model")
        check_choice("policy", self.policy, POLICIES)
        if self.steps is not None and (not isinstance(self.steps, int) or self.steps < 4):
            raise InputError("an integer number of steps >= 4 (or none: the converged engine)", got=self.steps, column="steps")
        if not isinstance(self.chunk_size, int) or self.chunk_size < 1:
            raise InputError("a chunk size >= 1", got=self.chunk_size, column="chunk_size")
        if not isinstance(self.robust_samples, int) or not (self.robust_samples == 0 or 8 <= self.robust_samples <= 2000):
            raise InputError("robust samples 0 (off) or 8-2000", got=self.robust_samples, column="robust_samples")
        if self.robust_samples and self.model is None:
            raise InputError("a model directory for robust samples (a twin's modes carry no uncertainty)", got=self.twin, column="robust_samples")

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    def input_files(self) -> dict[str, str]:
        """Every file the sweep reads, by role (model directories as their two files)."""
        files = {"poses": self.poses, "cut": self.cut}
        for role in ("twin", "absorber", "actuator"):
            if getattr(self, role):
                files[role] = getattr(self, role)
        if self.model:
            files["model.json"] = str(Path(self.model) / "model.json")
            files["arrays.npz"] = str(Path(self.model) / "arrays.npz")
        return files

    def fingerprint(self) -> str:
        """SHA-256 over the settings and the bytes of every input file: a resumed sweep must
        see the same fingerprint as the one that wrote the chunks."""
        h = hashlib.sha256(self.to_json().encode())
        for role, path in sorted(self.input_files().items()):
            h.update(role.encode())
            h.update(_file_bytes(path))
        return h.hexdigest()


def _file_bytes(path: str) -> bytes:
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise InputError("a readable file", got=exc.strerror, file=path) from None


# --- poses ---------------------------------------------------------------------------------


def read_sweep_poses(path: str):
    """The poses of a sweep as a PoseSet, and the twin file a grid names (or None): a grid
    (TOML, `posedyn.io.grid`) or a pose list (CSV with the pose columns, e.g. a tool path)."""
    if Path(path).suffix.lower() == ".toml":
        grid = read_grid(path)
        poses = pose_set([replace(g.pose, label=g.label) for g in grid.poses], [g.beta_deg for g in grid.poses])
        return poses, (str(grid.twin) if grid.twin else None)
    return read_pose_table(path), None
