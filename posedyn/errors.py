"""One error type for every bad input, and the `check_*` family that raises it.

The CLI and the service turn an `InputError` into the same one-line message: where the
problem is (file, row, line, column) and what was expected there.
"""

from __future__ import annotations

import math
from typing import Any, Iterable


class InputError(ValueError):
    """A value, file or message that does not meet the documented format.

    `row` counts data rows from 1 (the header is not a row); `line` is the physical line in
    the file (the header is line 1). Either may be None when it does not apply.
    """

    def __init__(
        self,
        expected: str,
        *,
        got: Any = None,
        file: str | None = None,
        row: int | None = None,
        line: int | None = None,
        column: str | None = None,
    ):
        self.expected = expected
        self.got = got
        self.file = file
        self.row = row
        self.line = line
        self.column = column
        super().__init__(self._message())

    def _message(self) -> str:
        where = []
        if self.file is not None:
            where.append(str(self.file))
        if self.row is not None:
            where.append(f"row {self.row}" + (f" (line {self.line})" if self.line is not None else ""))
        elif self.line is not None:
            where.append(f"line {self.line}")
        if self.column is not None:  # a command-line flag is an option, not a column
            where.append(f"option '{self.column}'" if str(self.column).startswith("--") else f"column '{self.column}'")
        text = f"expected {self.expected}"
        if self.got is not None:
            text += f", got {_plain(self.got)!r}"
        return (", ".join(where) + ": " if where else "") + text

    def located(self, **where: Any) -> "InputError":
        """The same error with location fields filled in where they were unknown."""
        fields = dict(file=self.file, row=self.row, line=self.line, column=self.column)
        for key, value in where.items():
            if fields.get(key) is None:
                fields[key] = value
        return InputError(self.expected, got=self.got, **fields)

    def renamed(self, names: dict, in_expected: bool = False) -> "InputError":
        """The same error about a field named as the file or flag that gave it: `names` maps
        field -> (that name, factor from the field's unit to its unit, or None); the value (a
        number or a tuple of numbers) scaled, with `in_expected` also the field names in the
        expected text ('field.max_mt > field.min_mt', not 'field_max_t > field_min_t'). The error
        itself where its column is not in `names`."""
        if self.column not in names:
            return self
        name, factor = names[self.column]
        got = self.got
        if factor is not None:  # (to 12 digits: -30 deg is not -29.999999999999996 after radians and back)
            got = tuple(_round12(v * factor) for v in got) if isinstance(got, tuple) else _round12(got * factor) if isinstance(got, (int, float)) else got
        expected = self.expected
        for field, (other, _) in names.items() if in_expected else ():
            expected = expected.replace(field, other)
        return InputError(expected, got=got, file=self.file, row=self.row, line=self.line, column=name)


def _round12(value):
    return float(f"{value:.12g}") if isinstance(value, float) else value


def _plain(value: Any) -> Any:
    """A value as the user wrote it: numpy scalars (and those inside tuples and lists) as Python
    numbers, so a message reads "got -1.3", not "got np.float64(-1.3)"."""
    if isinstance(value, (tuple, list)):
        return type(value)(_plain(v) for v in value)
    item = getattr(value, "item", None)
    if callable(item) and getattr(value, "shape", None) == ():
        return item()
    return value


def check_finite(name: str, value: float) -> float:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
        raise InputError("a finite number", got=value, column=name)
    return float(value)


def check_positive(name: str, value: float) -> float:
    value = check_finite(name, value)
    if value <= 0.0:
        raise InputError("a number > 0", got=value, column=name)
    return value


def check_non_negative(name: str, value: float) -> float:
    value = check_finite(name, value)
    if value < 0.0:
        raise InputError("a number >= 0", got=value, column=name)
    return value


def check_open_interval(name: str, value: float, low: float, high: float) -> float:
    value = check_finite(name, value)
    if not low < value < high:
        raise InputError(f"a number in ({low:g}, {high:g})", got=value, column=name)
    return value


def check_choice(name: str, value: Any, choices: Iterable[Any]) -> Any:
    choices = tuple(choices)
    if value not in choices:
        raise InputError("one of " + ", ".join(map(str, choices)), got=value, column=name)
    return value
