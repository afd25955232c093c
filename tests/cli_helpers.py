"""Running `posedyn` commands from the tests: through the console entry point's function
(`service.cli.main`) in the test's own process, where a new interpreter would spend 3 s
importing scipy, scikit-learn and pinocchio before the command runs."""

from __future__ import annotations

import contextlib
import io
import json
import subprocess


def strict_json(text: str):
    """json.loads that refuses NaN and Infinity (not JSON)."""

    def refuse(constant):
        raise ValueError(f"{constant} is not JSON")

    return json.loads(text, parse_constant=refuse)


def cli_in_process(*args) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of `posedyn ARGS` run through `service.cli.main`."""
    from service.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main([*map(str, args)])
            code = 0
        except SystemExit as exc:
            code = exc.code or 0
    return code, out.getvalue(), err.getvalue()


def json_in_process(*args):
    """The strict JSON that `posedyn ARGS --json` prints (asserting it exits with 0)."""
    code, out, err = cli_in_process(*args, "--json")
    assert code == 0, err
    return strict_json(out)


def run_cli(*args, cwd=None) -> subprocess.CompletedProcess:
    """`posedyn ARGS` in this process (`cli_in_process`, from `cwd` if given) as a
    CompletedProcess: returncode, stdout, stderr as text."""
    with contextlib.chdir(cwd) if cwd else contextlib.nullcontext():
        code, out, err = cli_in_process(*args)
    return subprocess.CompletedProcess(["posedyn", *map(str, args)], code, out, err)
