"""`posedyn control schedule`: active-damping gains per pose (seed 000) and virtual absorbers
(seed 002)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from posedyn.cli.common import console, print_json

app = typer.Typer(help="Active damping: DVF gain schedules and virtual absorbers.", no_args_is_help=True)


def read_actuator(path: Optional[Path]):
    """An actuator file (`kind = "active_damping"`, as datasets/seeds/sahu2024_active_damping.toml)."""
    from absorber.active import Actuator, ControlConfig
    from posedyn.io.params import read_params, reading

    if path is None:
        return ControlConfig()
    p = read_params(path)
    with reading(path, "actuator file"):
        a = p["actuator"]
        actuator = Actuator(
            transducer_n_per_v=a["horizontal"]["transducer_constant_n_per_v"],
            zeta=a["horizontal"]["zeta"],
            fn_horizontal_hz=a["horizontal"]["fn_hz"],
            fn_vertical_hz=a["vertical"]["fn_hz"],
            delay_s=a["horizontal"]["delay_ms"] * 1e-3,
            force_limit_n=a["force_limit_n"],
        )
        control = p.get("control", {})
        return ControlConfig(actuator=actuator, **{k: control[k] for k in ("mount_axis", "disturbance_n", "margin_db", "virtual_layout", "virtual_mass_ratio") if k in control})


@app.command("schedule")
def schedule(
    model_dir: Optional[Path] = typer.Argument(None, help="Model directory (or give --modes)."),
    modes: Optional[Path] = typer.Option(None, "--modes", help="Modal table instead of a model."),
    poses: Path = typer.Option(..., "--poses", help="Poses (CSV with the pose columns)."),
    actuator: Optional[Path] = typer.Option(None, "--actuator", help="Actuator file (default: seed 000's actuator)."),
    as_json: bool = typer.Option(False, "--json"),
):
    """DVF gain (>= 6 dB gain margin, force within the limit) and virtual-absorber parameters per pose."""
    from posedyn.cli.absorber import modal_table_for

    config = read_actuator(actuator)
    table = modal_table_for(model_dir, modes, poses)
    from absorber.active import control_entries

    entries = control_entries(table, config)
    if as_json:
        print_json(entries)
        return
    t = Table(title="active damping schedule", title_justify="left")
    for c in ("pose", "actuator Hz", "gain Ns/m", "margin dB", "stiffness +%", "force N", "virtual absorber"):
        t.add_column(c, justify="right")
    for e in entries:
        v = e["virtual_absorber"]
        t.add_row(e["pose_id"], f"{e['actuator_fn_hz']:.2f}", f"{e['dvf_gain_ns_per_m']:.0f}", f"{e['gain_margin_db']:.1f}", f"{e['dynamic_stiffness_gain_pct']:.0f}", f"{e['max_force_n']:.1f}", f"{v['layout']} {v['virtual_mass_kg']:.2f} kg")
    console.print(t)
