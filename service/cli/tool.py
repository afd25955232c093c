"""`posedyn tool-change`: a trained model's (or a modal table's) reference-tool modes to another
tool's, by receptance coupling (posedyn.rcsa, seed 003 section 3)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.table import Table

from posedyn.dynamics import ToolTipDynamics
from posedyn.io import write_modal_table
from posedyn.io.tool_file import read_tool
from posedyn.tool_change import tool_changed_table
from service.cli.common import console, flag_errors, output_file, print_json
from service.cli.inputs import modal_table_for


def tool_change(
    model_dir: Optional[Path] = typer.Argument(None, help="Model directory trained on reference-tool measurements (or give --modes)."),
    modes: Optional[Path] = typer.Option(None, "--modes", help="Modal table of the reference tool instead of a model."),
    reference_tool: Path = typer.Option(..., "--reference-tool", help="The tool the campaign was measured with (tool file, as datasets/seeds/seed003_reference_tool.toml)."),
    target_tool: Path = typer.Option(..., "--target-tool", help="The tool to predict (tool file)."),
    poses: Path = typer.Option(..., "--poses", help="Poses (CSV with the pose columns)."),
    out: Path = typer.Option(..., "--out", help="Modal table of the target tool to write (CSV, with the x-y cross stiffnesses)."),
    pivot_mm: float = typer.Option(150.0, "--pivot-mm", help="Where the holder side turns, behind the holder face (the joint's rotation is not in tip-only data: see the README)."),
    max_order: int = typer.Option(40, "--max-order", min=2, help="Highest model order of the identification's stabilization diagram."),
    as_json: bool = typer.Option(False, "--json"),
):
    """Predict another tool's tip modes from the reference tool's, pose by pose (RCSA with cross terms)."""
    output_file(out, "--out")
    table = modal_table_for(model_dir, modes, poses)
    reference, target = read_tool(reference_tool), read_tool(target_tool)
    with flag_errors({"pivot_m": ("--pivot-mm", 1e3)}):
        predicted = tool_changed_table(table, reference, target, pivot_mm * 1e-3, max_order)
    write_modal_table(predicted, out)
    summary = []
    for p, pose_id in enumerate(table.poses.pose_id):
        row = {"pose_id": pose_id}
        for name, t in (("reference", table), ("target", predicted)):
            dyn = ToolTipDynamics.from_table(t, pose_id)
            flexibility = np.abs(np.einsum("ir,ir->r", dyn.shapes, dyn.force_shapes)) / (2 * dyn.zeta * (2 * math.pi * dyn.fn_hz) ** 2)
            order = np.argsort(-flexibility)[:3]
            row[name] = [{"fn_hz": float(dyn.fn_hz[i]), "zeta": float(dyn.zeta[i]), "peak_compliance_m_per_n": float(flexibility[i])} for i in order]
        summary.append(row)
    if as_json:
        print_json({"out": str(out), "poses": summary})
        return
    t = Table(title=f"dominant modes: {reference[0].name} -> {target[0].name}", title_justify="left")
    for c in ("pose", "reference fn Hz (zeta)", "target fn Hz (zeta)"):
        t.add_column(c)
    for row in summary:
        t.add_row(row["pose_id"], ", ".join(f"{m['fn_hz']:.1f} ({m['zeta']:.3f})" for m in row["reference"]),
                  ", ".join(f"{m['fn_hz']:.1f} ({m['zeta']:.3f})" for m in row["target"]))
    console.print(t)
    console.print(f"wrote {out}")
