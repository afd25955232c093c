"""`posedyn twin`: the robot twin's modes and synthetic modal-test campaigns."""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from posedyn.errors import InputError
from posedyn.io import write_modal_table
from posedyn.io.grid import read_grid
from posedyn.io.twin_file import load_twin
from posedyn.robot import ToolPose
from posedyn.robot.campaign import GridPose, Noise, generate_campaign, least_kept_compliance, pose_modes
from posedyn.robot.twin_effects import parse_effect
from service.cli.common import console, flag_errors, output_file, print_json

app = typer.Typer(help="The robot twin: modes at a pose, synthetic modal-test campaigns.", no_args_is_help=True)
EFFECT = typer.Option(None, "--effect", help="Hide a named effect, e.g. device_mass:mass_kg=8 (repeatable).")



#: A mode whose tool-tip stiffness in a direction is above this many times its lowest is shown as
#: not seen there (a new user read 1.48e+36 N/m as a number).
UNSEEN = 1e6

#: `twin campaign` warns when its tables keep less of the tool tip's static robot compliance than
#: this at some pose (`least_kept_compliance`).
KEPT_COMPLIANCE_WARN = 0.9

@app.command("campaign")
def campaign(
    grid: Path = typer.Option(..., "--grid", help="Pose grid (TOML)."),
    out: Path = typer.Option(..., "--out", help="Modal table to write (CSV)."),
    noise_fn_pct: float = typer.Option(0.5, "--noise-fn-pct", help="Relative noise on fn (1 sigma, %)."),
    noise_zeta_pct: float = typer.Option(10.0, "--noise-zeta-pct", help="Relative noise on zeta (1 sigma, %)."),
    noise_k_pct: float = typer.Option(5.0, "--noise-k-pct", help="Relative noise on modal stiffness (1 sigma, %)."),
    seed: int = typer.Option(0, "--seed", help="Random seed (same seed, same file)."),
    twin: Optional[Path] = typer.Option(None, "--twin", help="Twin parameter file (default: the grid's, else the shipped KR R2700 twin)."),
    payload_kg: Optional[float] = typer.Option(None, "--payload-kg", help="Override the spindle payload mass."),
    effect: Optional[list[str]] = EFFECT,
    as_json: bool = typer.Option(False, "--json", help="Print a JSON summary."),
):
    """Generate a modal-test campaign (the modal-table format) over a pose grid."""
    output_file(out, "--out")
    g = read_grid(grid)
    robot, params = load_twin(twin or g.twin, payload_kg)
    effects = g.effects + tuple(parse_effect(e) for e in effect or ())
    with flag_errors({"fn_pct": ("--noise-fn-pct", None), "zeta_pct": ("--noise-zeta-pct", None), "k_pct": ("--noise-k-pct", None)}):
        noise = Noise(noise_fn_pct, noise_zeta_pct, noise_k_pct)
    label = f"twin {robot.name} seed {seed}" + ("; effects " + ", ".join(e.name for e in effects) if effects else "")
    table = generate_campaign(robot, list(g.poses), params, noise, seed, effects, source=label)
    write_modal_table(table, out)
    share, at_pose, direction = least_kept_compliance(robot, list(g.poses), params, effects)
    summary = {"out": str(out), "poses": len(table.poses), "rows": len(table), "seed": seed, "effects": [e.name for e in effects],
               "least_kept_compliance": share}
    if as_json:
        print_json(summary)
    else:
        console.print(f"wrote {out}: {summary['rows']} rows, {summary['poses']} poses (seed {seed}; effects: {', '.join(summary['effects']) or 'none'})")
    if share < KEPT_COMPLIANCE_WARN:
        print(f"warning: robot_modes_per_direction = {params.robot_modes_per_direction} keeps only {100 * share:.0f} % of the tool tip's "
              f"static robot compliance in {direction} at pose {at_pose}; a mode left out can be the one that chatters "
              "(6 in the twin file keeps every robot mode)", file=sys.stderr)


@app.command("modes")
def modes(
    x_mm: float = typer.Option(..., "--x-mm"),
    y_mm: float = typer.Option(..., "--y-mm"),
    z_mm: float = typer.Option(..., "--z-mm"),
    beta_deg: Optional[float] = typer.Option(None, "--beta-deg", help="Redundant angle (tool along base -z)."),
    a_deg: Optional[float] = typer.Option(None, "--a-deg"),
    b_deg: Optional[float] = typer.Option(None, "--b-deg"),
    c_deg: Optional[float] = typer.Option(None, "--c-deg"),
    twin: Optional[Path] = typer.Option(None, "--twin", help="Twin parameter file (default: the shipped KR R2700 twin)."),
    payload_kg: Optional[float] = typer.Option(None, "--payload-kg"),
    effect: Optional[list[str]] = EFFECT,
    as_json: bool = typer.Option(False, "--json"),
):
    """Joint angles and robot modes of the twin at one tool pose."""
    if (beta_deg is None) == (a_deg is None or b_deg is None or c_deg is None):
        raise InputError("either --beta-deg or all of --a-deg --b-deg --c-deg", column="--beta-deg")
    given = {"--x-mm": x_mm, "--y-mm": y_mm, "--z-mm": z_mm, "--beta-deg": beta_deg, "--a-deg": a_deg, "--b-deg": b_deg, "--c-deg": c_deg}
    for flag, value in given.items():
        if value is not None and not math.isfinite(value):
            raise InputError("a finite number", got=value, column=flag)
    if beta_deg is not None:
        pose = GridPose("pose", ToolPose.from_beta(x_mm / 1e3, y_mm / 1e3, z_mm / 1e3, math.radians(beta_deg)), beta_deg)
    else:
        pose = GridPose("pose", ToolPose.from_abc(x_mm / 1e3, y_mm / 1e3, z_mm / 1e3, *map(math.radians, (a_deg, b_deg, c_deg))))
    robot, params = load_twin(twin, payload_kg)
    q, m = pose_modes(robot, pose, params, tuple(parse_effect(e) for e in effect or ()))
    rows = [
        {"mode": r + 1, "fn_hz": float(m.fn_hz[r]), "zeta": float(m.zeta[r]), **{f"k{d}_n_per_m": float(m.stiffness(d)[r]) for d in "xyz"}}
        for r in range(len(m.fn_hz))
    ]
    if as_json:
        print_json({"joints_deg": [math.degrees(v) for v in q], "modes": rows})
        return
    console.print("joints (deg): " + ", ".join(f"A{j + 1} {math.degrees(v):.2f}" for j, v in enumerate(q)))
    table = Table(title="robot modes at the tool tip", title_justify="left",
                  caption=f"-: the mode hardly moves the tool tip that way (its stiffness there above {UNSEEN:.0e} x its lowest; --json has the number)")
    for column in ("mode", "fn_hz", "zeta", "kx_n_per_m", "ky_n_per_m", "kz_n_per_m"):
        table.add_column(column, justify="right")
    for row in rows:
        k = [row[f"k{d}_n_per_m"] for d in "xyz"]
        table.add_row(str(row["mode"]), f"{row['fn_hz']:.2f}", f"{row['zeta']:.3f}", *("-" if v > UNSEEN * min(k) else f"{v:.3g}" for v in k))
    console.print(table)
