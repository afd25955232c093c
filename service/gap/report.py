"""The gap workflow's report: one self-contained HTML file (plots embedded) with the normalised
residuals before and after, the chosen effects with their parameters, and every candidate's
evidence."""

from __future__ import annotations

import numpy as np

from service import html


def render(m, baseline: np.ndarray, result, title: str) -> str:
    import matplotlib  # heavy (about 0.3 s): only when a figure is drawn

    matplotlib.use("Agg")
    doc = result.to_json()
    parts = [f"<h1>{html.escape(title)}</h1>"]
    verdict = "the residual after the named effects is noise (of the noise model below)" if result.explained else "the residual is still structured: no named effect in the library explains it fully"
    parts.append(
        f"<ul><li>{len(m)} measurements; RMS normalised residual {result.rmse_before:.3g} before, {result.rmse_after:.3g} after (noise level 1)</li>"
        f"<li>chi-square p-value {result.noise_p_before:.3g} before, {result.noise_p_after:.3g} after: {verdict}</li>"
        f"<li>noise: {html.escape(result.noise['verdict'])}</li></ul>"
    )
    parts.append("<h2>Named effects</h2>")
    if doc["effects"]:
        rows = [{"effect": e["name"], "what": e["description"], "source": e["source"],
                 "parameters": ", ".join(f"{k} = {v:.4g} +- {e['parameter_std'][k]:.2g}" for k, v in e["parameters"].items()),
                 "evidence (BIC drop)": e["evidence"]} for e in doc["effects"]]
        parts.append(html.table(rows, ("effect", "what", "source", "parameters", "evidence (BIC drop)")))
    else:
        parts.append("<p>None claimed.</p>")
    for a in doc["ambiguous"]:
        parts.append(f"<p><b>Undecided:</b> {html.escape(' and '.join(a['candidates']))} explain the data equally well. To separate them: {html.escape(a['separating_measurement'])}.</p>")
    if doc["residual_correlates"]:
        parts.append("<p><b>The remaining residual depends on:</b> " + html.escape("; ".join(f"{c['variable']} ({c['quantity']} rows, Spearman rho {c['spearman_rho']:.2f}, p {c['p']:.2g})" for c in doc["residual_correlates"])) + "</p>")
    parts.append("<h2>Residuals</h2>")
    parts.append(html.figure(_residual_png(m, (m.value - baseline) / m.std, (m.value - result.prediction_after) / m.std), "Normalised residuals (value - prediction) / std, before and after"))
    if result.discrepancy is not None:
        d = result.discrepancy
        follows = ", ".join(f"{v} ({r:.2g})" for v, r in sorted(zip(d.variables, d.relevance), key=lambda t: -t[1]))
        parts.append("<h2>Where the rest lives</h2>")
        parts.append(f"<p>A Gaussian process map of the {html.escape(d.quantity)} residual after the named effects (its scale {d.signal_std:.3g} stds, "
                     f"leaving {d.noise_std:.3g}); relevance, spread over length scale, per variable: {html.escape(follows)}.</p>")
        parts.append(html.figure(_map_png(d), f"Normalised {d.quantity} residual over {' and '.join(d.axes)} (others at their median)"))
    parts.append("<h2>Every candidate</h2>")
    parts.append(html.table(doc["candidates"], ("name", "eligible", "reason", "delta_bic", "cv_chi2_per_row", "chosen")))
    body = "\n".join(parts)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>body {{ font-family: system-ui, sans-serif; margin: 2em; max-width: 1300px; color: #222; }}
table {{ border-collapse: collapse; font-size: 0.85em; }} td, th {{ border: 1px solid #ccc; padding: 0.2em 0.5em; }} th {{ background: #f0f0f0; }}
figure {{ margin: 0; }} figure img {{ max-width: 100%; }}</style></head>
<body>
{body}
</body></html>
"""


def _residual_png(m, before: np.ndarray, after: np.ndarray) -> bytes:
    import matplotlib.pyplot as plt  # heavy (about 0.3 s): only when a figure is drawn

    quantities = sorted(set(m.quantity))
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2), dpi=90, sharey=True)
    for ax, r, label in zip(axes, (before, after), ("before", "after")):
        for q in quantities:
            rows = np.flatnonzero(m.quantity == q)
            ax.plot(rows, r[rows], ".", label=q, markersize=4)
        ax.axhspan(-2, 2, color="0.9", zorder=0)
        ax.set_title(f"{label}: RMS {np.sqrt(np.mean(r**2)):.3g}", fontsize=10)
        ax.set_xlabel("measurement")
    axes[0].set_ylabel("(value - prediction) / std")
    axes[0].set_yscale("symlog", linthresh=3)
    axes[1].legend(fontsize=7)
    return html.png(fig)


def _map_png(d) -> bytes:
    import matplotlib.pyplot as plt  # heavy (about 0.3 s): only when a figure is drawn

    names = list(d.axes)
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=90)
    if len(names) == 1:
        x = d.axes[names[0]]
        ax.plot(x, d.mean, color="C0")
        ax.fill_between(x, d.mean - 2 * d.std, d.mean + 2 * d.std, color="C0", alpha=0.2, label="+- 2 std")
        ax.set_xlabel(names[0])
        ax.set_ylabel("(value - prediction) / std")
        ax.legend(fontsize=8)
    else:
        mesh = ax.pcolormesh(d.axes[names[0]], d.axes[names[1]], d.mean.T, shading="auto", cmap="RdBu_r",
                             vmin=-np.max(np.abs(d.mean)), vmax=np.max(np.abs(d.mean)))
        fig.colorbar(mesh, ax=ax, label="(value - prediction) / std")
        ax.set_xlabel(names[0])
        ax.set_ylabel(names[1])
    return html.png(fig)
