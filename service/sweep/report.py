"""The sweep report: one self-contained HTML file (plots embedded as PNG data URIs, no scripts,
no external resources), readable offline.

Maps are drawn over the tool-tip x-y plane. Where several poses share an (x, y) (orientations,
heights), each map shows the pose with the smallest critical depth there (the worst orientation),
and says so; unreachable positions are grey crosses.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from posedyn.io.atomic import write_text_atomic
from service import html

MAPS = (
    ("lowest_fn_hz", "Lowest natural frequency (x-y)", "Hz", "viridis"),
    ("critical_depth_mm", "Critical depth without absorber", "mm", "RdYlGn"),
    ("critical_depth_with_absorber_mm", "Critical depth with the scheduled absorber", "mm", "RdYlGn"),
    ("critical_depth_p95_mm", "Guaranteed critical depth without absorber (95 % lower bound)", "mm", "RdYlGn"),
    ("critical_depth_with_absorber_p95_mm", "Guaranteed critical depth with the robust or nominal absorber setting", "mm", "RdYlGn"),
    ("dominant_chatter_hz", "Dominant chatter frequency", "Hz", "plasma"),
    ("field_mt", "Required absorber field", "mT", "magma"),
    ("dvf_gain_ns_per_m", "DVF controller gain", "N s/m", "cividis"),
    ("lowest_fn_std_hz", "Prediction uncertainty (1 std of the lowest frequency)", "Hz", "Oranges"),
    ("sle_um", "Surface location error (+ = undercut)", "um", "coolwarm"),
)
WORST_COLUMNS = ("pose_id", "x_mm", "y_mm", "z_mm", "beta_deg", "critical_depth_mm", "dominant_chatter_hz", "field_mt", "critical_depth_with_absorber_mm", "dvf_gain_ns_per_m", "sle_um", "flags")
ROBUST_WORST_COLUMNS = ("critical_depth_p95_mm", "robust_tuning", "robust_field_mt", "critical_depth_with_absorber_p95_mm")


def write_report(path: Path, rows: list[dict], lobes: list[dict], provenance: dict, title: str = "Pose sweep") -> None:
    """Render and write the report atomically."""
    write_text_atomic(path, render(rows, lobes, provenance, title))


def render(rows: list[dict], lobes: list[dict], provenance: dict, title: str) -> str:
    import matplotlib  # heavy (about 0.3 s): only when a figure is drawn

    matplotlib.use("Agg")
    reachable = [r for r in rows if r.get("reachable")]
    worst = _worst_per_position(rows)
    parts = [f"<h1>{html.escape(title)}</h1>", _summary(rows, reachable, provenance)]
    parts.append("<h2>Workspace maps</h2>")
    if len(worst) < len(rows):
        parts.append("<p class='note'>Several poses share each (x, y): every map shows, at each position, the pose with the smallest critical depth (the worst orientation or height).</p>")
    figures = []
    for column, label, unit, cmap in MAPS:
        values = [r.get(column) for r in worst]
        if not any(v is not None for v in values):
            continue
        if column == "lowest_fn_std_hz" and not any(v for v in values if v is not None):
            figures.append(f"<figure><figcaption>{html.escape(label)}: the twin gives no prediction uncertainty (a trained model does).</figcaption></figure>")
            continue
        figures.append(html.figure(_map_png(worst, column, f"{label} ({unit})", cmap), f"{label} ({unit})"))
    parts.append("<div class='grid'>" + "".join(figures) + "</div>")
    if lobes:
        parts.append("<h2>Stability lobes at representative poses</h2>")
        parts.append(html.figure(_lobes_png(lobes), "Stability lobes without and with the scheduled absorber"))
    parts.append("<h2>Worst poses (smallest critical depth)</h2>")
    robust = any(r.get("robust_tuning") for r in reachable)
    columns = WORST_COLUMNS[:-1] + (ROBUST_WORST_COLUMNS if robust else ()) + WORST_COLUMNS[-1:]
    parts.append(html.table(sorted(reachable, key=lambda r: r["critical_depth_mm"] if r.get("critical_depth_mm") is not None else math.inf)[:10], columns))
    flagged = {}
    for r in rows:
        for flag in filter(None, (r.get("flags") or "").split(";")):
            flagged[flag] = flagged.get(flag, 0) + 1
    parts.append("<h2>Flags</h2>")
    parts.append("<p>No pose is flagged.</p>" if not flagged else "<ul>" + "".join(f"<li>{html.escape(k)}: {v} poses</li>" for k, v in sorted(flagged.items())) + "</ul>")
    parts.append("<h2>Provenance</h2>" + html.definition_list(provenance))
    body = "\n".join(parts)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>
body {{ font-family: system-ui, sans-serif; margin: 2em; color: #222; max-width: 1400px; }}
h1 {{ margin-bottom: 0.2em; }} .note {{ color: #555; }}
.grid {{ display: grid; grid-template-columns: repeat(auto-fill, minmax(420px, 1fr)); gap: 1em; }}
figure {{ margin: 0; }} figure img {{ width: 100%; height: auto; }} figcaption {{ font-size: 0.9em; color: #444; }}
table {{ border-collapse: collapse; font-size: 0.85em; }} td, th {{ border: 1px solid #ccc; padding: 0.2em 0.5em; text-align: right; }}
th {{ background: #f0f0f0; }} td:first-child, th:first-child {{ text-align: left; }}
dl {{ display: grid; grid-template-columns: max-content 1fr; gap: 0.2em 1em; }} dt {{ font-weight: 600; }} dd {{ margin: 0; word-break: break-all; }}
</style></head>
<body>
{body}
</body></html>
"""


def _summary(rows, reachable, provenance) -> str:
    depths = np.array([r["critical_depth_mm"] for r in reachable if r.get("critical_depth_mm") is not None])
    with_abs = np.array([r["critical_depth_with_absorber_mm"] for r in reachable if r.get("critical_depth_with_absorber_mm") is not None])
    feasible = sum(1 for r in reachable if r.get("absorber_feasible"))
    items = [f"{len(rows)} poses, {len(reachable)} reachable"]
    cut = provenance.get("cut", {})
    if cut:
        items.append(f"cut: {cut.get('rpm', '?')} rpm, {cut.get('teeth', '?')} teeth, a<sub>e</sub>/D {cut.get('radial_immersion', '?')}, {cut.get('milling', '?')} milling")
    if len(depths):
        items.append(f"critical depth without absorber: {depths.min():.3g}-{depths.max():.3g} mm (median {np.median(depths):.3g})")
    if len(with_abs):
        items.append(f"with the scheduled absorber: {with_abs.min():.3g}-{with_abs.max():.3g} mm (median {np.median(with_abs):.3g})")
    guaranteed = [r for r in reachable if r.get("critical_depth_with_absorber_p95_mm") is not None]
    if guaranteed:
        changed = [r for r in guaranteed if r.get("robust_tuning") == "robust"]
        items.append(f"guaranteed depth (95 % lower bound) with the absorber: {min(r['critical_depth_with_absorber_p95_mm'] for r in guaranteed):.3g} mm at the worst pose; "
                     f"the robust setting differs from the nominal one at {len(changed)} of {len(guaranteed)} poses")
    if reachable:
        items.append(f"absorber within its field and current range at {feasible} of {len(reachable)} reachable poses")
    return "<ul>" + "".join(f"<li>{i}</li>" for i in items) + "</ul>"


def _worst_per_position(rows: list[dict]) -> list[dict]:
    best: dict = {}
    for r in rows:
        key = (round(r["x_mm"], 6), round(r["y_mm"], 6))
        depth = r.get("critical_depth_mm")
        score = -math.inf if not r.get("reachable") else (depth if depth is not None else math.inf)
        current = best.get(key)
        if current is None:
            best[key] = (score, r)
            continue
        # a reachable pose beats an unreachable one; among reachable, the smaller depth wins
        if (current[0] == -math.inf and score != -math.inf) or (score != -math.inf and score < current[0]):
            best[key] = (score, r)
    return [r for _, r in best.values()]


def _map_png(rows: list[dict], column: str, label: str, cmap: str) -> bytes:
    import matplotlib.pyplot as plt  # heavy (about 0.3 s): only when a figure is drawn

    fig, ax = plt.subplots(figsize=(5.2, 4.2), dpi=90)
    ok = [r for r in rows if r.get(column) is not None]
    missing = [r for r in rows if r.get(column) is None]
    if ok:
        x, y, v = (np.array([r[k] for r in ok]) for k in ("x_mm", "y_mm", column))
        size = max(12, min(300, 30000 / max(len(rows), 1)))
        art = ax.scatter(x, y, c=v, cmap=cmap, s=size, marker="s", edgecolors="none")
        fig.colorbar(art, ax=ax, label=label)
    if missing:
        ax.scatter([r["x_mm"] for r in missing], [r["y_mm"] for r in missing], marker="x", color="0.6", label="unreachable / none")
        ax.legend(loc="upper right", fontsize=7)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(label, fontsize=9)
    return html.png(fig)


def _lobes_png(lobes: list[dict]) -> bytes:
    import matplotlib.pyplot as plt  # heavy (about 0.3 s): only when a figure is drawn

    fig, ax = plt.subplots(figsize=(9, 4.5), dpi=90)
    for entry, color in zip(lobes, ("tab:red", "tab:blue", "tab:green", "tab:purple")):
        rpm = np.array(entry["rpm"])
        ax.plot(rpm, np.array(entry["depth_mm"], dtype=float), color=color, label=f"{entry['label']}: {entry['pose_id']}")
        ax.plot(rpm, np.array(entry["depth_with_absorber_mm"], dtype=float), color=color, linestyle="--", label=f"{entry['pose_id']} with absorber ({entry['field_mt']:.0f} mT)")
        ax.axvline(entry["cut_rpm"], color="0.5", linewidth=0.8)
    ax.set_xlabel("spindle speed (rpm)")
    ax.set_ylabel("critical depth (mm)")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("Semi-discretization lobes; the vertical line is the cut's speed", fontsize=9)
    return html.png(fig)


