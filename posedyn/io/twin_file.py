"""Robot-twin parameter files (TOML, `kind = "robot_twin"`): `[robot] urdf, payload_kg`;
`[joints] stiffness_nm_per_rad = [six values]`, optional `gravity_softening_per_knm` (joint
stiffness k / (1 + c |gravity torque| / 1 kN m)); `[modes] zeta, robot_modes_per_direction`;
optional `[flange] mass_kg, offset_m = [x, y, z]` (a device on the flange, e.g. written by the
gap workflow) and `[tool_tip] mass_kg` (a sensor at the tool tip); `[[spindle_modes]] direction, fn_hz, k_n_per_m, zeta`. The one place a twin file
becomes a Robot and its TwinParameters, and the one place one is written (`write_twin`)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from posedyn.io.atomic import write_text_atomic
from posedyn.io.params import check_numbers, read_params, reading, toml_value
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
    p = read_params(path, kind="robot_twin")
    check_numbers(p, path, text=("robot.urdf", "spindle_modes.direction"))
    with reading(path, "twin file"):
        robot = p["robot"]
        urdf = (path.parent / robot["urdf"]).resolve()
        spindle = {}
        for item in p.get("spindle_modes", []):
            mode = Mode(float(item["fn_hz"]), float(item["zeta"]), float(item["k_n_per_m"]))
            spindle.setdefault(item["direction"], []).append(mode)
        flange = p.get("flange", {})
        params = TwinParameters(
            joint_stiffness_nm_per_rad=tuple(float(k) for k in p["joints"]["stiffness_nm_per_rad"]),
            zeta=float(p["modes"]["zeta"]),
            robot_modes_per_direction=int(p["modes"]["robot_modes_per_direction"]),
            spindle_modes={d: tuple(m) for d, m in spindle.items()},
            flange_mass_kg=float(flange.get("mass_kg", 0.0)),
            flange_mass_offset_m=tuple(float(v) for v in flange.get("offset_m", TwinParameters().flange_mass_offset_m)),
            gravity_softening_per_knm=float(p["joints"].get("gravity_softening_per_knm", 0.0)),
            tip_mass_kg=float(p.get("tool_tip", {}).get("mass_kg", 0.0)),
        )
        return TwinSpec(urdf=urdf, payload_kg=float(robot["payload_kg"]), params=params)


def write_twin(path: str | os.PathLike, spec: TwinSpec, source: str, comment: str = "") -> None:
    """A twin file for `spec` (the URDF referenced relative to the new file), atomically."""
    path = Path(path)
    p = spec.params
    urdf = Path(os.path.relpath(spec.urdf, path.parent.resolve())).as_posix()
    lines = [f"# {line}" for line in comment.splitlines()] + [
        "", "[meta]", 'kind = "robot_twin"', f"source = {toml_value(source)}", "",
        "[robot]", f"urdf = {toml_value(urdf)}", f"payload_kg = {spec.payload_kg!r}", "",
        "[joints]", f"stiffness_nm_per_rad = [{', '.join(repr(float(k)) for k in p.joint_stiffness_nm_per_rad)}]",
        f"gravity_softening_per_knm = {float(p.gravity_softening_per_knm)!r}", "",
        "[modes]", f"zeta = {p.zeta!r}", f"robot_modes_per_direction = {p.robot_modes_per_direction}", "",
        "[flange]", f"mass_kg = {float(p.flange_mass_kg)!r}", f"offset_m = [{', '.join(repr(float(v)) for v in p.flange_mass_offset_m)}]", "",
        "[tool_tip]", f"mass_kg = {float(p.tip_mass_kg)!r}", "",
    ]
    for d, modes in p.spindle_modes.items():
        for m in modes:
            lines += ["[[spindle_modes]]", f"direction = {toml_value(d)}", f"fn_hz = {float(m.fn_hz)!r}", f"k_n_per_m = {float(m.k_n_per_m)!r}", f"zeta = {float(m.zeta)!r}", ""]
    write_text_atomic(path, "\n".join(lines))


def load_twin(path: str | os.PathLike | None = None, payload_kg: float | None = None) -> tuple[Robot, TwinParameters]:
    """The robot (URDF with the file's payload, or `payload_kg`) and the twin parameters of a
    twin file; the shipped KR R2700-class twin when `path` is None."""
    spec = read_twin(path if path is not None else SHIPPED_TWIN)
    return Robot.from_urdf(spec.urdf, payload_kg=spec.payload_kg if payload_kg is None else payload_kg), spec.params
