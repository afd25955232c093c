"""Tool files (TOML, `kind = "tool"`): `[tool] name, youngs_modulus_gpa, density_kg_m3, poisson,
zeta, sections = [[length_mm, diameter_mm], ...]` from the tip to the holder face (the overhang;
a fluted part as its equivalent diameter), `elements_per_section` optional; `[connection]`
the holder-tool joint: `translational_n_per_m, rotational_nm_per_rad` and optional
`translational_damping_ns_per_m, rotational_damping_nms_per_rad` (as
datasets/seeds/seed003_reference_tool.toml). The one place a tool file becomes a Tool."""

from __future__ import annotations

import os

from posedyn.io.params import check_numbers, read_params, reading
from posedyn.rcsa import Connection
from posedyn.tool import Section, Tool


def read_tool(path: str | os.PathLike) -> tuple[Tool, Connection]:
    p = read_params(path, kind="tool")
    check_numbers(p, path, text=("tool.name",))
    with reading(path, "tool file"):
        t, c = p["tool"], p["connection"]
        sections = tuple(Section(float(length) * 1e-3, float(diameter) * 1e-3) for length, diameter in t["sections"])
        tool = Tool(sections, youngs_modulus_pa=float(t["youngs_modulus_gpa"]) * 1e9, density_kg_m3=float(t["density_kg_m3"]),
                    poisson=float(t.get("poisson", 0.25)), zeta=float(t.get("zeta", 0.001)),
                    elements_per_section=int(t.get("elements_per_section", 8)), name=str(t.get("name", "tool")))
        connection = Connection(float(c["translational_n_per_m"]), float(c["rotational_nm_per_rad"]),
                                float(c.get("translational_damping_ns_per_m", 0.0)), float(c.get("rotational_damping_nms_per_rad", 0.0)))
        return tool, connection
