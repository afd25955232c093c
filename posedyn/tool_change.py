"""Another tool's modes from a modal table of the reference tool, pose by pose (seed 003
section 3): each pose's tip receptances, the holder side turning about a pivot
(`rcsa.holder_from_tip`), the target coupled through its joint (`rcsa.target_tip`), the x-y FRF
matrix identified again (`modal_fit.fit_table`). The one tool change every caller runs
(`posedyn tool-change`, `posedyn schedule --target-tool`, the service)."""

from __future__ import annotations

import math

import numpy as np

from posedyn.dynamics import ToolTipDynamics
from posedyn.io.frf import FRFSet
from posedyn.modal_fit import fit_table
from posedyn.rcsa import Connection, target_tip
from posedyn.table import ModalTable
from posedyn.tool import Tool


def frequency_grid(dyn: ToolTipDynamics, points: int = 4000) -> np.ndarray:
    """Frequencies (rad/s) for the coupled FRFs: a log grid from half the lowest mode to three
    times the highest (the target tool's own modes may lie above the reference's)."""
    return 2 * math.pi * np.geomspace(0.5 * dyn.fn_hz.min(), 3.0 * dyn.fn_hz.max(), points)


def tool_changed_table(table: ModalTable, reference: tuple[Tool, Connection], target: tuple[Tool, Connection], pivot_m: float,
                       max_order: int = 40) -> ModalTable:
    """The target tool's modal table (x and y with cross stiffnesses where coupled) at the
    table's poses; z modes are dropped (the coupling is in the x-y plane)."""
    frfs = []
    columns = table.poses.numeric_columns()
    for p, pose_id in enumerate(table.poses.pose_id):
        dyn = ToolTipDynamics.from_table(table, pose_id)
        omega = frequency_grid(dyn)
        H = target_tip(dyn.frf(omega), omega, reference, target, pivot_m)
        names = {"h_xx": H[:, 0, 0], "h_yy": H[:, 1, 1]}
        if np.abs(H[:, 0, 1]).max() > 1e-9 * np.abs(H).max():  # a matrix fit where x and y are coupled (a round tool adds no coupling)
            names.update(h_xy=H[:, 0, 1], h_yx=H[:, 1, 0])
        pose = {name: float(values[p]) for name, values in columns.items()}
        frfs.append(FRFSet(omega / (2 * math.pi), names, pose_id=pose_id, pose=pose, source=f"{target[0].name} at {pose_id}"))
    return fit_table(frfs, max_order=max_order, weighting="absolute")[0]  # computed FRFs: no noise to weigh (`identify.WEIGHTINGS`)
