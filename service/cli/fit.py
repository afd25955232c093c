"""`posedyn fit`: modal tables from measured FRFs (CSV or UFF)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import numpy as np
import typer

from posedyn.errors import InputError
from posedyn.identify import lscf_poles
from posedyn.io import write_modal_table
from posedyn.io.frf import FRFSet, read_frf
from posedyn.modal_fit import fit_misses, fit_table, fitted_frfs
from service.cli.common import console, output_file, print_json


def fit(
    files: list[Path] = typer.Argument(..., help="FRF files (CSV or .uff/.unv), one pose each (files with the same pose_id are merged)."),
    out: Path = typer.Option(..., "--out", help="Modal table to write (CSV)."),
    fmin_hz: Optional[float] = typer.Option(None, "--fmin-hz", min=0.0),
    fmax_hz: Optional[float] = typer.Option(None, "--fmax-hz"),
    modes: Optional[int] = typer.Option(None, "--modes", min=1, help="Keep at most this many modes per direction (lowest first)."),
    max_order: int = typer.Option(40, "--max-order", min=2, help="Highest model order of the stabilization diagram."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Folder for stabilization diagrams and measured-versus-fitted FRF plots."),
    as_json: bool = typer.Option(False, "--json"),
):
    """Identify modes (fn, zeta, k with their stds; the cross-coupling, without std, from an x-y FRF matrix) and write a modal table."""
    output_file(out, "--out")
    if fmax_hz is not None and not (math.isfinite(fmax_hz) and fmax_hz > (fmin_hz or 0.0)):  # (0 read as "not given")
        raise InputError(f"--fmax-hz above {fmin_hz or 0:g} Hz (--fmin-hz)", got=fmax_hz, column="--fmax-hz")
    if plot is not None and plot.exists() and not plot.is_dir():
        raise InputError("a folder for the plots", got="an existing file", file=str(plot), column="--plot")
    merged: dict[str, FRFSet] = {}
    for path in files:
        frf = read_frf(path)
        if frf.pose_id in merged:
            base = merged[frf.pose_id]
            if not np.array_equal(base.frequency_hz, frf.frequency_hz):
                raise InputError("the same frequencies as the other files of this pose", file=str(path), column="frequency_hz")
            for key in set(base.frf) & set(frf.frf):
                raise InputError(f"each FRF of pose {frf.pose_id} in one file (also in {base.source})", got=key, file=str(path), column=key)
            for key in set(base.pose) & set(frf.pose):
                if base.pose[key] != frf.pose[key]:
                    raise InputError(f"the pose of {frf.pose_id} as in {base.source} ({key} = {base.pose[key]:g})", got=frf.pose[key], file=str(path), column=key)
            frf = FRFSet(base.frequency_hz, {**base.frf, **frf.frf}, {**base.coherence, **frf.coherence}, frf.pose_id, {**base.pose, **frf.pose}, frf.source)
        merged[frf.pose_id] = frf
    frfs = list(merged.values())
    table, fits = fit_table(frfs, fmin_hz, fmax_hz, max_order, modes)
    write_modal_table(table, out)
    fitted = [fitted_frfs(frf, found) for frf, found in zip(frfs, fits)]  # for the plots and the check
    if plot is not None:
        _plots(plot, frfs, fitted, max_order)
    summary = table.summary()
    warnings = fit_misses(frfs, fitted, fmin_hz, fmax_hz)
    warnings += [f"{line}: is the file's quantity (receptance, mobility, accelerance) right?" for line in table.soft_modes()]
    if not any(f.pose for f in frfs):  # (a new user's table came out at 0, 0, 0, 0 without a word)
        warnings.append("no file gives its pose: the table's poses are all at x = y = z = 0 (by pose_id only), which `train` cannot learn from; "
                        "give `# x_mm = ...`, `# y_mm`, `# z_mm` and `# beta_deg` (or a/b/c_deg) in each FRF file's header")
    if as_json:
        print_json({"out": str(out), "poses": summary["poses"], "modes": summary["modes"], "coupled": bool(table.cross), "warnings": warnings})
    else:
        console.print(f"wrote {out}: {summary['rows']} modes at {summary['poses']} poses ({', '.join(f'{d}: {n}' for d, n in summary['modes'].items())})")
        for line in warnings:
            console.print(f"warning: {line}")


def _plots(folder: Path, frfs, fitted, max_order):
    import matplotlib  # heavy (about 0.3 s): only when a figure is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # heavy (about 0.3 s): only when a figure is drawn


    folder.mkdir(parents=True, exist_ok=True)
    for frf, fits in zip(frfs, fitted):
        f = frf.frequency_hz
        fig, axes = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
        for name, h in sorted(frf.frf.items()):
            axes[0].semilogy(f, np.abs(h), lw=0.8, label=f"{name} measured")
        for name, h in fits.items():
            axes[0].semilogy(f, np.abs(h), "--", lw=1, label=f"{name} fitted")
        axes[0].set_ylabel("|H| (m/N)")
        axes[0].legend(fontsize=7)
        name = next(iter(sorted(frf.frf)))
        step = max(1, len(f) // 2000)
        for order in range(2, max_order + 1, 2):
            lam = lscf_poles(f[::step], frf.frf[name][::step], order)
            axes[1].plot(np.abs(lam) / (2 * math.pi), np.full(len(lam), order), "k.", ms=2)
        axes[1].set_ylabel("model order")
        axes[1].set_xlabel("frequency (Hz)")
        axes[1].set_xscale("log")
        fig.suptitle(f"pose {frf.pose_id}: FRFs and stabilization diagram ({name})")
        fig.tight_layout()
        fig.savefig(folder / f"{frf.pose_id}.png", dpi=110)
        plt.close(fig)
