"""Robot-twin parameter files (TOML, `kind = "robot_twin"`): `[robot] urdf, payload_kg`;
`[joints] stiffness_nm_per_rad = [six values]`; `[modes] zeta, robot_modes_per_direction`;
`[[spindle_modes]] direction, fn_hz, k_n_per_m, zeta`. The one place a twin file becomes a
Robot and its TwinParameters."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from posedyn.io.params import read_params, reading
from posedyn.io.shipped import SHIPPED_TWIN
from posedyn.robot import Robot, TwinParameters
from posedyn.table import Mode


@dataclass(frozen=True)
class TwinSpec:
    urdf: Path
    payload_kg: float
    params: TwinParameters


def read_twin(path: str | os.PathLike) -> TwinSpec:
    path = Path(path)
    p = read_params(path)
    with reading(path, "twin file"):
        robot = p["robot"]
        urdf = (path.parent / robot["urdf"]).resolve()
        spindle = {}
        for item in p.get("spindle_modes", []):
            mode = Mode(float(item["fn_hz"]), float(item["zeta"]), float(item["k_n_per_m"]))
            spindle.setdefault(item["direction"], []).append(mode)
        params = TwinParameters(
            joint_stiffness_nm_per_rad=tuple(float(k) for k in p["joints"]["stiffness_nm_per_rad"]),
            zeta=float(p["modes"]["zeta"]),
            robot_modes_per_direction=int(p["modes"]["robot_modes_per_direction"]),
            spindle_modes={d: tuple(m) for d, m in spindle.items()},
        )
        return TwinSpec(urdf=urdf, payload_kg=float(robot["payload_kg"]), params=params)


def load_twin(path: str | os.PathLike | None = None, payload_kg: float | None = None) -> tuple[Robot, TwinParameters]:
    """The robot (URDF with the file's payload, or `payload_kg`) and the twin parameters of a
    twin file; the shipped KR R2700-class twin when `path` is None."""
    spec = read_twin(path if path is not None else SHIPPED_TWIN)
    return Robot.from_urdf(spec.urdf, payload_kg=spec.payload_kg if payload_kg is None else payload_kg), spec.params
