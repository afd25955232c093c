"""Named physical effects that the twin can add on top of its nominal model.

Each effect is a frozen dataclass with a one-line physical description and a source, and acts
through two hooks: `twin_parameters` (change the twin before its modes are computed: masses,
stiffnesses) and `modes` (change the modes after: add, shift, split). The campaign generator
applies them in order, so generated data can hide any combination of them; the discrepancy
workflow names them back.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import ClassVar

from posedyn.errors import InputError


@dataclass(frozen=True)
class Effect:
    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    source: ClassVar[str] = ""

    def twin_parameters(self, params, pose):
        return params

    def modes(self, modes, pose):
        return modes


@dataclass(frozen=True)
class DeviceMass(Effect):
    """A device (absorber, actuator) fixed to the spindle housing: a point mass at the flange
    that lowers the robot modes and splits close pairs."""

    mass_kg: float = 8.0
    offset_x_m: float = 0.15
    offset_y_m: float = 0.0
    offset_z_m: float = 0.12

    name: ClassVar[str] = "device_mass"
    description: ClassVar[str] = "added device mass on the spindle housing lowers and splits the robot modes"
    source: ClassVar[str] = "seed 000 section 2 and Fig. 2 (actuator mass lowers and splits the 20 Hz mode)"

    def __post_init__(self):
        if not self.mass_kg >= 0:
            raise InputError("a device mass >= 0 kg", got=self.mass_kg, column="mass_kg")

    def twin_parameters(self, params, pose):
        total = params.flange_mass_kg + self.mass_kg
        return replace(params, flange_mass_kg=total, flange_mass_offset_m=(self.offset_x_m, self.offset_y_m, self.offset_z_m))


EFFECTS: dict[str, type[Effect]] = {cls.name: cls for cls in (DeviceMass,)}


def make_effect(name: str, **parameters) -> Effect:
    """An effect by name with keyword parameters (numbers), with a clear error for unknown ones."""
    if name not in EFFECTS:
        raise InputError("an effect among " + ", ".join(sorted(EFFECTS)), got=name, column="effect")
    cls = EFFECTS[name]
    known = {f.name for f in fields(cls)}
    unknown = set(parameters) - known
    if unknown:
        raise InputError(f"parameters of {name} among " + ", ".join(sorted(known)), got=sorted(unknown), column="effect")
    try:
        return cls(**{k: float(v) for k, v in parameters.items()})
    except (TypeError, ValueError) as exc:
        raise InputError(f"numeric parameters for {name}", got=str(exc), column="effect") from None


def parse_effect(text: str) -> Effect:
    """'device_mass:mass_kg=8,offset_x_m=0.1' -> DeviceMass(mass_kg=8.0, offset_x_m=0.1)."""
    name, _, rest = text.partition(":")
    parameters = {}
    for item in filter(None, (part.strip() for part in rest.split(","))):
        key, sep, value = item.partition("=")
        if not sep:
            raise InputError("NAME:key=value,key=value", got=text, column="effect")
        parameters[key.strip()] = value.strip()
    return make_effect(name.strip(), **parameters)
