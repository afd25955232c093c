"""Output helpers shared by the commands."""

from __future__ import annotations

import json
import math
import sys
from enum import Enum

from rich.console import Console

console = Console(width=None if sys.stdout.isatty() else 140)


def finite_or_none(value: float):
    """JSON has no inf or NaN: a depth that never chatters is null."""
    return float(value) if math.isfinite(value) else None


def print_json(value) -> None:
    print(json.dumps(value, indent=2, allow_nan=False))


class Milling(str, Enum):
    down = "down"
    up = "up"
