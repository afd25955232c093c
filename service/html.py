"""Pieces of the self-contained HTML reports (the sweep's, the gap workflow's): figures as
inline PNG, tables, definition lists, escaping, and the provenance stamps."""

from __future__ import annotations

import base64
import html as _html
import importlib.metadata as md
import io
import platform
import sys
from datetime import datetime, timezone


def png(fig) -> bytes:
    """A matplotlib figure as PNG bytes (the figure is closed)."""
    import matplotlib.pyplot as plt  # heavy (about 0.3 s): only once a report draws a figure

    buffer = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buffer, format="png")
    plt.close(fig)
    return buffer.getvalue()


def figure(png: bytes, caption: str) -> str:
    data = base64.b64encode(png).decode("ascii")
    return f"<figure><img alt='{escape(caption)}' src='data:image/png;base64,{data}'><figcaption>{escape(caption)}</figcaption></figure>"


def table(rows: list[dict], columns) -> str:
    columns = [c for c in columns if any(c in r for r in rows)]
    head = "".join(f"<th>{escape(c)}</th>" for c in columns)
    body = "".join("<tr>" + "".join(f"<td>{escape(fmt(r.get(c)))}</td>" for c in columns) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def definition_list(p: dict) -> str:
    items = []
    for key, value in p.items():
        if isinstance(value, dict):
            value = "; ".join(f"{k}: {v}" for k, v in value.items())
        items.append(f"<dt>{escape(key)}</dt><dd>{escape(str(value))}</dd>")
    return "<dl>" + "".join(items) + "</dl>"


def software_versions() -> dict:
    out = {"python": sys.version.split()[0], "platform": platform.platform()}
    for name in ("posedyn", "numpy", "scipy", "scikit-learn", "pin", "dask", "distributed", "matplotlib"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            pass
    return out


def now_utc() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def fmt(value) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def escape(text: str) -> str:
    return _html.escape(str(text), quote=True)
