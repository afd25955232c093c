"""The `posedyn` command line, the one CLI of the project (`posedyn ...` and `python -m service
...` run this `main`): each module here parses one family of commands' flags, calls the
library, and prints a table or `--json`. No library module imports this package.

Bad input anywhere ends in one line on stderr (`error: <file>, row <r> (line <l>), column
'<c>': expected ...`) and exit status 2, never a traceback.
"""

from __future__ import annotations

import importlib
import sys
from typing import Optional

import typer

from posedyn import __version__
from posedyn.errors import InputError
from service.heap import keep_freed_memory

#: Every command: name -> (module of this package, function), and the groups: name -> module
#: (its `app`). `main` imports only the module of the command it runs: all of them take 1.5 s
#: (the absorber's optimizers, scikit-learn, scipy.stats), `posedyn chatter`'s 0.8 s.
COMMANDS = {
    "schedule": ("absorber", "schedule"),
    "fit": ("fit", "fit"),
    "train": ("posemodel", "train"),
    "predict": ("posemodel", "predict"),
    "chatter": ("stability", "chatter"),
    "lobes": ("stability", "lobes"),
    "sle": ("sle", "sle"),
    "sweep": ("sweep", "sweep"),
    "serve": ("serve", "serve"),
    "query": ("serve", "query"),
    "gap": ("gap", "gap"),
    "gap-campaign": ("gap", "gap_campaign"),
    "tool-change": ("tool", "tool_change"),
    "plan": ("plan", "plan"),
}
GROUPS = {"data": "data", "twin": "twin", "absorber": "absorber", "control": "control"}


def build_app(command: Optional[str] = None) -> typer.Typer:
    """The Typer app with every command, or with `command` alone where it is one (the others'
    modules are not imported; help, an unknown command and no command get them all). Commands
    are registered in the order of GROUPS, then COMMANDS."""
    app = typer.Typer(
        help="Pose-dependent tool-tip dynamics, chatter prediction and absorber/controller schedules for robotic milling.",
        no_args_is_help=True,
        pretty_exceptions_enable=False,
        add_completion=False,
        context_settings={"help_option_names": ["-h", "--help"]},  # every command's context inherits it
    )
    app.callback()(_root)
    only = command if command in GROUPS or command in COMMANDS else None
    for name, module in GROUPS.items():
        if only in (None, name):
            app.add_typer(_module(module).app, name=name)
    for name, (module, function) in COMMANDS.items():
        if only in (None, name):
            app.command(name)(getattr(_module(module), function))
    return app


def _module(name: str):
    """A command module of this package by name (the CLI's dispatch table, not a lazy import of
    a library: each command module imports its libraries at its top)."""
    return importlib.import_module(f"service.cli.{name}")


def _version(value: bool):
    if value:
        print(f"posedyn {__version__}")
        raise typer.Exit()


def _root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Print the version and exit."),
):
    pass


def main(argv: Optional[list[str]] = None) -> None:
    keep_freed_memory()  # the stability engine's temporaries reuse the heap (service.heap)
    args = sys.argv[1:] if argv is None else list(argv)
    app = build_app(args[0] if args else None)
    # absorber optima of earlier runs (seconds each to recompute): only where the command can tune
    # an absorber, i.e. its module brought in absorber.tuning (`posedyn chatter` does not)
    tuning = sys.modules.get("absorber.tuning")
    files = importlib.import_module("absorber.files") if tuning is not None else None
    if files is not None:
        files.load_tuning_cache()
        known = len(tuning.known_tunings())
    try:
        code = typer.main.get_command(app).main(args=args, prog_name="posedyn", standalone_mode=False)
        if isinstance(code, int) and code:  # a command's own exit status (typer.Exit), returned without standalone mode
            sys.exit(code)
    except typer.Abort:
        print("error: aborted", file=sys.stderr)
        sys.exit(1)
    except typer.TyperException as exc:  # Click's usage errors (an unknown, missing or malformed option): one line, not its box
        ctx = getattr(exc, "ctx", None)
        where = f" ({ctx.command_path} -h for help)" if ctx is not None else ""
        if exc.format_message():  # (none where no arguments printed the help)
            print(f"error: {exc.format_message()}{where}", file=sys.stderr)
        sys.exit(getattr(exc, "exit_code", 2))
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    except OSError as exc:  # what the system refused past the early checks (permissions, a full disk, a path gone meanwhile)
        print(f"error: {exc.filename if exc.filename is not None else 'a file'}: {exc.strerror or exc}", file=sys.stderr)
        sys.exit(2)
    finally:
        if files is not None and len(tuning.known_tunings()) > known:
            files.save_tuning_cache()
