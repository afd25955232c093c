"""Parameter files (TOML, units in the keys): a `[meta]` table with `kind` and `source`, then
named tables of values. Physics code gets plain dicts or dataclasses built from them."""

from __future__ import annotations

import math
import os
import re
import tomllib
from contextlib import contextmanager
from pathlib import Path

from posedyn.errors import InputError
from posedyn.io.atomic import write_text_atomic


def read_params(path: str | os.PathLike, kind: str | tuple[str, ...] | None = None) -> dict:
    """Load a parameter TOML file; the error names the file and the line of a syntax error.
    `kind`: the `meta.kind` (or kinds) the caller reads (another kind is refused: a pose grid
    given as a cut file would otherwise be read for its defaults)."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except OSError as exc:
        raise InputError("a readable file", got=exc.strerror, file=str(path)) from None
    except UnicodeDecodeError as exc:
        raise InputError("UTF-8 text", got=f"byte offset {exc.start}", file=str(path)) from None
    try:
        params = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        match = re.search(r"line (\d+)", str(exc))
        raise InputError("valid TOML", got=str(exc), file=str(path), line=int(match.group(1)) if match else None) from None
    meta = params.get("meta")
    if not isinstance(meta, dict):
        raise InputError("a [meta] table with kind and source", got="missing", file=str(path), column="meta")
    for key in ("kind", "source"):
        if not isinstance(meta.get(key), str) or not meta[key]:
            raise InputError("a non-empty string", got=meta.get(key), file=str(path), column=f"meta.{key}")
    kinds = (kind,) if isinstance(kind, str) else kind
    if kinds is not None and meta["kind"] not in kinds:
        raise InputError(" or ".join(f'kind = "{k}"' for k in kinds), got=meta["kind"], file=str(path), column="meta.kind")
    return params


def check_keys(params: dict, allowed: dict[str, tuple[str, ...]], path: str | os.PathLike, what: str) -> None:
    """Refuse a table or key the file kind does not have (`allowed`: table -> its keys; [meta]
    is free): a misspelt optional key would otherwise be ignored and its default used."""
    for table, values in params.items():
        if table == "meta":
            continue
        if table not in allowed:
            raise InputError(f"only the tables {', '.join('[' + t + ']' for t in allowed)} in a {what}", got=f"[{table}]", file=str(Path(path)), column=table)
        if not isinstance(values, dict):
            raise InputError(f"[{table}] as a table of keys", got=values, file=str(Path(path)), column=table)
        for key in values:
            if key not in allowed[table]:
                raise InputError(f"one of the keys {', '.join(allowed[table])} in [{table}]", got=key, file=str(Path(path)), column=f"{table}.{key}")


def number(value, name: str) -> float:
    """A finite real given as a TOML integer or float, else InputError naming the key (a TOML
    boolean or a quoted number is refused: float(true) would silently be 1)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"a finite number for {name}", got=value, column=name)
    return float(value)


def check_numbers(params: dict, path: str | os.PathLike, text: tuple[str, ...] = ()) -> None:
    """Every value of the file outside [meta] a number (or a list of numbers, a table of them),
    but the keys named in `text` ("table.key", "table.key" of each [[table]] item): a TOML boolean
    or a quoted number is refused with its key and the file (float(true) would silently be 1)."""
    def walk(value, name, key):
        if isinstance(value, dict):
            for k, v in value.items():
                walk(v, f"{name}.{k}", f"{key}.{k}")
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            for i, item in enumerate(value, 1):
                walk(item, f"{name}[{i}]", key)
        elif isinstance(value, list):
            for i, v in enumerate(value):
                walk(v, f"{name}[{i}]", key)
        elif key not in text:
            try:
                number(value, name)
            except InputError as exc:
                raise exc.located(file=str(Path(path))) from None

    for table, values in params.items():
        if table != "meta":
            walk(values, table, table)


def whole_number(value, name: str) -> int:
    """An integer given as a TOML integer (or a float with no fraction), else InputError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not float(value).is_integer():
        raise InputError(f"a whole number for {name}", got=value, column=name)
    return int(value)


def flatten(params: dict, prefix: str = "") -> dict[str, object]:
    """{"a": {"b": 1}, "c": [{"d": 2}]} -> {"a.b": 1, "c[1].d": 2}, for summaries."""
    out: dict[str, object] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(flatten(value, name + "."))
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            for i, item in enumerate(value, 1):
                out.update(flatten(item, f"{name}[{i}]."))
        else:
            out[name] = value
    return out


@contextmanager
def reading(path: str | os.PathLike, what: str):
    """Turn the KeyError / TypeError / ValueError / InputError raised while building objects
    from a parameter file into one InputError that names the file (and the missing key)."""
    where = dict(file=str(Path(path)))
    try:
        yield
    except InputError as exc:  # first: an InputError is a ValueError too
        raise exc.located(**where) from None
    except KeyError as exc:
        raise InputError(f"this key in the {what}", got="missing", column=str(exc.args[0]), **where) from None
    except (TypeError, ValueError) as exc:
        raise InputError(f"numbers in the {what}", got=str(exc), **where) from None


@contextmanager
def named_as(names: dict, in_expected: bool = False):
    """InputErrors about an object's fields named as the file writes them (`InputError.renamed`)."""
    try:
        yield
    except InputError as exc:
        raise exc.renamed(names, in_expected) from None


def write_params(path: str | os.PathLike, params: dict, comment: str = "") -> None:
    """A parameter file from {table: {key: value}} (strings, numbers, booleans and lists of
    numbers; `[meta]` first), `comment` as its leading # lines, atomically; read_params reads it
    back to the same values."""
    lines = [f"# {line}" for line in comment.splitlines()]
    for table in sorted(params, key=lambda t: t != "meta"):
        lines += ["", f"[{table}]"]
        for key, value in params[table].items():
            lines.append(f"{key} = {toml_value(value, f'{table}.{key}')}")
    write_text_atomic(path, "\n".join(lines).lstrip("\n") + "\n")


def toml_value(value, name: str = "value") -> str:
    """A TOML value (string, number, boolean or list of numbers) as written in a parameter file."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(value, list) and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        return "[" + ", ".join(repr(v) for v in value) + "]"
    raise InputError("a string, number, boolean or list of numbers", got=type(value).__name__, column=name)
