"""`posedyn data`: validate and summarise modal-test tables, measurement campaigns and parameter files."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from posedyn.errors import InputError
from posedyn.io import flatten, read_modal_table, read_params
from posedyn.io.cut import read_cut, read_sle_cut
from posedyn.io.measurements import read_measurements
from posedyn.io.shipped import DATASETS
from posedyn.io.tool_file import read_tool
from posedyn.io.twin_file import read_twin
from absorber.files import read_absorber, read_actuator, read_host
from service.cli.common import console, print_json, soft_mode_warnings

app = typer.Typer(help="Validate and summarise modal-test tables and parameter files.", no_args_is_help=True)
out = console


MODAL_COLUMNS = ("rows", "poses", "directions", "modes", "fn_hz", "zeta", "k_n_per_m")


def _modal_summary_table(title: str, summaries: dict[str, dict]) -> Table:
    """One row per table: counts and parameter ranges."""
    table = Table(title=title, title_justify="left")
    table.add_column("file", no_wrap=True)
    for column in MODAL_COLUMNS:
        table.add_column(column, justify="right" if column in ("rows", "poses") else "left")
    span = lambda lo_hi, fmt: f"{lo_hi[0]:{fmt}} .. {lo_hi[1]:{fmt}}"  # noqa: E731
    for name, s in summaries.items():
        r = s["ranges"]
        table.add_row(
            name,
            str(s["rows"]),
            str(s["poses"]),
            ",".join(s["directions"]),
            ", ".join(f"{d}: {n}" for d, n in s["modes"].items()),
            span(r["fn_hz"], ".4g"),
            span(r["zeta"], ".3g"),
            span(r["k_n_per_m"], ".3g"),
        )
    return table


@app.command("check")
def data_check(
    file: Path = typer.Argument(..., help="Modal-test table (CSV)."),
    as_json: bool = typer.Option(False, "--json", help="Print {rows, poses, directions, modes, warnings} as JSON."),
):
    """Validate a modal-test table and summarise it. Exit 0 when valid, 2 when not."""
    table = read_modal_table(file)
    summary = table.summary()
    warnings = soft_mode_warnings(table, file)
    for line in warnings:
        print(f"warning: {line}", file=sys.stderr)
    if as_json:
        print_json({**{k: summary[k] for k in ("rows", "poses", "directions", "modes")}, "warnings": warnings})
    else:
        out.print(_modal_summary_table("valid modal-test table", {str(file): summary}))


@app.command("summary")
def data_summary(
    folder: Path = typer.Argument(DATASETS, help="Folder to walk (CSV modal tables and TOML parameter files; default: the shipped data)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object per file."),
):
    """Validate every modal table and measurement campaign (*.csv) and parameter file (*.toml) under a folder."""
    if not folder.is_dir():
        raise InputError("a folder", got=str(folder))
    files = sorted(p for p in folder.rglob("*") if p.suffix in (".csv", ".toml") and not p.is_dir())  # (a folder named x.csv stopped the walk)
    if not files:
        raise InputError("at least one .csv or .toml file", got="none", file=str(folder))
    report, errors = [], []
    for path in files:
        try:
            report.append(_file_summary(path))
        except InputError as exc:  # every file is checked: one bad file does not hide the next
            errors.append(str(exc.located(file=str(path))))
            report.append({"file": str(path), "kind": "invalid", "error": errors[-1]})
    if as_json:
        print_json(report)
    else:
        _print_summary(folder, report, len(files) - len(errors))
    for error in errors:
        print(f"error: {error}", file=sys.stderr)
    if errors:
        raise typer.Exit(2)


#: The reader each kind of parameter file is used with, run on it by `data summary` (its checks of
#: ranges, keys and types are what "valid" means).
FULL_READERS = {
    "cut": lambda path: (read_cut(path), read_sle_cut(path)),
    "mrf_absorber": read_absorber,
    "active_damping": read_actuator,
    "host_and_cut": read_host,
    "robot_twin": read_twin,
    "tool": read_tool,
}


def _file_summary(path: Path) -> dict:
    """One file's entry of `data summary` (InputError where it is not valid)."""
    try:
        header = path.read_text(encoding="utf-8-sig").partition("\n")[0]
    except UnicodeDecodeError as exc:
        raise InputError("a UTF-8 text file", got=f"byte {exc.object[exc.start]:#04x} at offset {exc.start}", file=str(path)) from None
    except OSError as exc:  # unreadable (permissions, a broken link): listed as invalid, the walk goes on
        raise InputError("a readable file", got=exc.strerror, file=str(path)) from None
    if path.suffix == ".csv" and "quantity" in header.split(","):
        m = read_measurements(path)  # a measurement campaign for `posedyn gap` (README: Measurement campaigns)
        quantities = {str(q): int(n) for q, n in zip(*np.unique(m.quantity, return_counts=True))}
        return {"file": str(path), "kind": "measurement_campaign", "rows": len(m), "poses": len(set(m.pose_id)), "quantities": quantities}
    if path.suffix == ".csv":
        return {"file": str(path), "kind": "modal_table", **read_modal_table(path).summary()}
    params = read_params(path)
    reader = FULL_READERS.get(params["meta"]["kind"])
    if reader is not None:  # valid only where the command that uses the file takes it (a cut with 0 teeth is no cut)
        reader(path)
    values = {k: v for k, v in flatten(params).items() if not k.startswith("meta.")}
    return {"file": str(path), "kind": params["meta"]["kind"], "source": params["meta"]["source"], "values": values}


def _print_summary(folder: Path, report: list, valid: int) -> None:
    """`data summary` as tables (the invalid files are said on stderr)."""
    out.print(f"[bold]{valid} of {len(report)} files under {folder}/ are valid[/bold]")
    tables = {item["file"]: item for item in report if item["kind"] == "modal_table"}
    if tables:
        out.print(_modal_summary_table("Modal-test tables (one row per pose x direction x mode)", tables))
    for item in report:
        if item["kind"] == "measurement_campaign":
            out.print(f"{item['file']} (measurement campaign): {item['rows']} rows at {item['poses']} poses, "
                      + ", ".join(f"{n} {q}" for q, n in item["quantities"].items()))
        elif item["kind"] not in ("modal_table", "invalid"):
            table = Table(title=f"{item['file']} ({item['kind']})", caption=item["source"], title_justify="left")
            table.add_column("parameter")
            table.add_column("value", justify="right")
            for key, value in item["values"].items():
                table.add_row(key, f"{value:g}" if isinstance(value, float) else str(value))
            out.print(table)
