"""JSON has no inf or NaN: the one conversion every JSON writer of the project uses."""

from __future__ import annotations

import math


def json_ready(value):
    """Non-finite floats become null, recursively through dicts, lists and tuples (the producer
    states why a value is undefined next to it where that is not obvious)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    return value
