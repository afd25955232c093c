"""`posedyn control schedule`: active-damping gains per pose (seed 000) and virtual absorbers
(seed 002)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from absorber.active_damping import control_entries
from absorber.files import read_actuator
from service.cli.common import console, print_json
from service.cli.inputs import modal_table_for

app = typer.Typer(help="Active damping: DVF gain schedules and virtual absorbers.", no_args_is_help=True)


@app.command("schedule")
def schedule(
    model_dir: Optional[Path] = typer.Argument(None, help="Model directory (or give --modes)."),
    modes: Optional[Path] = typer.Option(None, "--modes", help="Modal table instead of a model."),
    poses: Path = typer.Option(..., "--poses", help="Poses (CSV with the pose columns)."),
    actuator: Optional[Path] = typer.Option(None, "--actuator", help="Actuator file (default: seed 000's actuator)."),
    as_json: bool = typer.Option(False, "--json"),
):
    """DVF gain (>= 6 dB gain margin, force within the limit) and virtual-absorber parameters per pose."""
    config = read_actuator(actuator)
    table = modal_table_for(model_dir, modes, poses)
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
