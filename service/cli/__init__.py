"""The `posedyn` command line, the one CLI of the project (`posedyn ...` and `python -m service
...` run this `main`): each module here parses one family of commands' flags, calls the
library, and prints a table or `--json`. No library module imports this package.

Bad input anywhere ends in one line on stderr (`error: <file>, row <r> (line <l>), column
'<c>': expected ...`) and exit status 2, never a traceback.
"""

from __future__ import annotations

import sys
from typing import Optional

import typer

from absorber.files import load_tuning_cache, save_tuning_cache
from absorber.tuning import known_tunings
from posedyn import __version__
from posedyn.errors import InputError
from service.cli import absorber, control, data, fit, gap, plan, posemodel, serve, sle, stability, sweep, tool, twin
from service.heap import keep_freed_memory

app = typer.Typer(
    help="Pose-dependent tool-tip dynamics, chatter prediction and absorber/controller schedules for robotic milling.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)
app.add_typer(data.app, name="data")
app.add_typer(twin.app, name="twin")
app.add_typer(absorber.app, name="absorber")
app.add_typer(control.app, name="control")
app.command("schedule")(absorber.schedule)
app.command("fit")(fit.fit)
app.command("train")(posemodel.train)
app.command("predict")(posemodel.predict)
app.command("chatter")(stability.chatter)
app.command("lobes")(stability.lobes)
app.command("sle")(sle.sle)
app.command("sweep")(sweep.sweep)
app.command("serve")(serve.serve)
app.command("query")(serve.query)
app.command("gap")(gap.gap)
app.command("gap-campaign")(gap.gap_campaign)
app.command("tool-change")(tool.tool_change)
app.command("plan")(plan.plan)


def _version(value: bool):
    if value:
        print(f"posedyn {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Print the version and exit."),
):
    pass


def main(argv: Optional[list[str]] = None) -> None:
    keep_freed_memory()  # the stability engine's temporaries reuse the heap (service.heap)
    load_tuning_cache()  # absorber optima of earlier runs (seconds each to recompute)
    known = len(known_tunings())
    try:
        app(args=argv, prog_name="posedyn")
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    except OSError as exc:  # what the system refused past the early checks (permissions, a full disk, a path gone meanwhile)
        print(f"error: {exc.filename if exc.filename is not None else 'a file'}: {exc.strerror or exc}", file=sys.stderr)
        sys.exit(2)
    finally:
        if len(known_tunings()) > known:
            save_tuning_cache()
