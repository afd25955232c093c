"""`posedyn absorber tune|field` and `posedyn schedule` (the per-pose chain, `absorber.chain`)."""

from __future__ import annotations

import json
import math
import sys
from enum import Enum
from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.table import Table

from absorber.chain import ScheduleConfig, schedule_entries, schedule_poses
from absorber.files import read_absorber, read_actuator, read_host
from absorber.robust import METHODS, cutting_force_harmonics, monte_carlo_limits, robust_tuning
from absorber.tuning import BOUNDS, Host, absolute_limit_m, min_real_part, tune_sims, uncontrolled_min_real_part
from posedyn.errors import InputError
from posedyn.io.tool_file import read_tool
from posedyn.tool_change import tool_changed_table
from posedyn.io.atomic import write_text_atomic
from posedyn.io.cut import read_cut
from posedyn.io import read_pose_table
from posedyn.stability import Cut, mean_force_matrix
from service.cli.common import Milling, console, finite_or_none, flag_errors, output_file, print_json, resolve_cut
from service.cli.inputs import modal_input_for, twin_modes_at

app = typer.Typer(help="MRF absorber: optimal tuning, field for a target frequency.", no_args_is_help=True)


class Layout(str, Enum):
    tmd = "tmd"
    c3 = "idva-c3"
    c4 = "idva-c4"
    c5 = "idva-c5"
    c6 = "idva-c6"


#: The library's fields as the absorber commands' flags name them (`flag_errors`).
ABSORBER_FLAGS = {"fn_hz": ("--host-fn-hz", None), "zeta": ("--host-zeta", None), "k_n_per_m": ("--host-k-n-per-m", None),
              "mass_ratio": ("--mass-ratio", None), "target_hz": ("--target-hz", None)}


class Policy(str, Enum):
    match = "match"
    sims = "sims"
    depth = "depth"


@app.command("tune")
def tune(
    host_fn_hz: float = typer.Option(..., "--host-fn-hz"),
    host_k_n_per_m: float = typer.Option(..., "--host-k-n-per-m"),
    host_zeta: float = typer.Option(..., "--host-zeta"),
    mass_ratio: float = typer.Option(..., "--mass-ratio"),
    layout: Layout = typer.Option(..., "--layout"),
    teeth: int = typer.Option(..., "--teeth"),
    kt_mpa: float = typer.Option(..., "--kt-mpa"),
    kn_mpa: float = typer.Option(..., "--kn-mpa"),
    radial_immersion: float = typer.Option(..., "--radial-immersion"),
    milling: Milling = typer.Option(Milling.down, "--milling"),
    seed: int = typer.Option(0, "--seed"),
    as_json: bool = typer.Option(False, "--json"),
):
    """Optimal absorber on a host mode (seed 002 eq. 18) and the absolute stability limits."""
    with flag_errors(ABSORBER_FLAGS):
        host = Host(host_fn_hz, host_k_n_per_m, host_zeta)
        cut = Cut(teeth=teeth, kt_pa=kt_mpa * 1e6, kn_pa=kn_mpa * 1e6, radial_immersion=radial_immersion, milling=milling.value)
        h = mean_force_matrix(cut)[1, 1]  # the host mode is the flexible direction y, x rigid (seed 002)
        if h <= 0:
            raise InputError("a cut whose mean y directional coefficient is positive (seed 002's case)", got=h, column="--radial-immersion")
        tuned = tune_sims(layout.value, mass_ratio, host_zeta, seed=seed)
    out = {
        "layout": layout.value,
        "gamma": float(tuned.gamma),
        "zeta_a": float(tuned.zeta_a),
        "delta": None if tuned.delta is None else float(tuned.delta),
        "eta": None if tuned.eta is None else float(tuned.eta),
        "absolute_limit_mm": finite_or_none(absolute_limit_m(min_real_part(tuned, host_zeta), host, h) * 1e3),
        "uncontrolled_limit_mm": finite_or_none(absolute_limit_m(uncontrolled_min_real_part(host_zeta), host, h) * 1e3),
    }
    # an optimum on the edge of the range searched is no optimum (a new user's mass ratio 50 gave gamma = 0.5 without a word)
    out["at_search_bound"] = [k for k, (lo, hi) in BOUNDS.items() if out.get(k) is not None and (math.isclose(out[k], lo, rel_tol=1e-6) or math.isclose(out[k], hi, rel_tol=1e-6))]
    if out["at_search_bound"]:
        print(f"warning: {', '.join(out['at_search_bound'])} at the edge of the range searched ({', '.join(f'{k} {BOUNDS[k][0]:g}-{BOUNDS[k][1]:g}' for k in out['at_search_bound'])}): "
              f"the optimum lies beyond it (mass ratio {mass_ratio:g}; absorbers are about 0.005-0.2)", file=sys.stderr)
    if as_json:
        print_json(out)
        return
    for key, value in out.items():
        console.print(f"{key:24s} {value}")


@app.command("robust")
def robust(
    host_file: Path = typer.Option(..., "--host", help="Host file: \\[host], \\[cut], optional \\[uncertainty] and \\[absorber] mass_ratio (as datasets/seeds/dogan2024_host_milling.toml)."),
    layout: Optional[Layout] = typer.Option(None, "--layout", help="Absorber tuned (seed 002 eq. 18) for the nominal host; none: the bare host."),
    mass_ratio: Optional[float] = typer.Option(None, "--mass-ratio", help="Absorber mass / host modal mass (default: the host file's)."),
    rpm_min: float = typer.Option(..., "--rpm-min"),
    rpm_max: float = typer.Option(..., "--rpm-max"),
    rpm_steps: int = typer.Option(..., "--rpm-steps", min=1),
    samples: int = typer.Option(500, "--samples", min=10),
    seed: int = typer.Option(0, "--seed"),
    method: str = typer.Option("auto", "--method", help="auto: per speed the cheapest of the zeroth order and the semi-discretization that gives the nominal limit within 2 % of the converged engine, else the engine; zoa: seed 002's eq. 12 everywhere; engine: the converged engine everywhere."),
    robust_tuning_: bool = typer.Option(False, "--robust-tuning", help="Also tune the absorber for the best 95 % lower bound over the speeds and print its rows beside the nominal tuning's."),
    as_json: bool = typer.Option(False, "--json"),
):
    """Stability limit under the host's uncertainty per speed: Latin-hypercube Monte Carlo (seed 002 section 4)."""
    case = read_host(host_file)
    uncertainty, cut = case.uncertainty, case.cut
    if not 0 < rpm_min <= rpm_max:
        raise InputError("0 < --rpm-min <= --rpm-max", got=f"{rpm_min}, {rpm_max}", column="--rpm-min")
    if rpm_steps == 1 and rpm_max != rpm_min:  # one speed is --rpm-min: --rpm-max would be ignored
        raise InputError("--rpm-steps 2 or more for a range (one speed: --rpm-max equal to --rpm-min)", got=rpm_steps, column="--rpm-steps")
    mu = mass_ratio if mass_ratio is not None else case.mass_ratio
    if layout is not None and mu is None:
        raise InputError("--mass-ratio or [absorber] mass_ratio in the host file", got="neither", file=str(host_file), column="--mass-ratio")
    if robust_tuning_ and layout is None:
        raise InputError("--layout with --robust-tuning", got="no layout", column="--robust-tuning")
    if method not in METHODS:
        raise InputError("--method " + ", ".join(METHODS), got=method, column="--method")
    speeds = np.linspace(rpm_min, rpm_max, rpm_steps)
    harmonics = None if case.feed_per_tooth_m is None else cutting_force_harmonics(cut, case.feed_per_tooth_m)
    with flag_errors(ABSORBER_FLAGS if mass_ratio is not None else None):  # (the host file's mass ratio is named by the file)
        tunings = {"nominal": None if layout is None else tune_sims(layout.value, mu, uncertainty.nominal.zeta)}
    if robust_tuning_:  # tuned on other samples than it is judged on
        tunings["robust"] = robust_tuning(uncertainty, tunings["nominal"], cut, speeds, seed=seed + 1, force_harmonics=harmonics, force_limit_n=case.force_limit_n)
    out = {}
    for name, tuning in tunings.items():
        stats = monte_carlo_limits(uncertainty, tuning, cut, speeds, samples, seed, force_harmonics=harmonics, method=method)
        out[name] = [
            {"rpm": float(r), "mean_mm": finite_or_none(m * 1e3), "std_mm": finite_or_none(s * 1e3), "cv_pct": finite_or_none(100 * cv),
             "p95_lower_mm": finite_or_none(lo * 1e3), "q05_mm": finite_or_none(q * 1e3), "nominal_mm": finite_or_none(n * 1e3),
             "actuator_force_p95_n": finite_or_none(f), "actuator_force_ratio": finite_or_none(ratio),
             "actuator_saturates": None if case.force_limit_n is None or not math.isfinite(f) else bool(f > case.force_limit_n),
             "method": used, "zoa_deviation_pct": finite_or_none(100 * dev)}
            for r, m, s, cv, lo, q, n, f, ratio, used, dev in zip(stats.rpm, stats.mean_m, stats.std_m, stats.cv, stats.lower95_m, stats.q05_m, stats.nominal_m,
                                                                   stats.force_upper95_n, stats.force_ratio, stats.method, stats.zoa_deviation)
        ]
    if as_json:
        print_json(out["nominal"] if not robust_tuning_ else {name: {"tuning": _tuning_json(tunings[name]), "rows": rows} for name, rows in out.items()})
        return
    for name, rows in out.items():
        title = f"{layout.value if layout else 'no absorber'} ({name} tuning {_tuning_json(tunings[name])}), {samples} samples" if layout else f"no absorber, {samples} samples"
        table = Table("rpm", "mean mm", "std mm", "cv %", "95 % lower mm", "5 % quantile mm", "nominal mm", "actuator force 95 % N", "force / ideal", "saturates",
                      "method", "zoa vs engine %", title=title)
        for row in rows:
            table.add_row(*(_fmt(v) for v in row.values()))
        console.print(table)


def _tuning_json(tuning) -> dict | None:
    if tuning is None:
        return None
    return {k: None if getattr(tuning, k) is None else float(getattr(tuning, k)) for k in ("gamma", "zeta_a", "delta", "eta")}


@app.command("field")
def field_cmd(
    target_hz: float = typer.Option(..., "--target-hz"),
    absorber: Optional[Path] = typer.Option(None, "--absorber", help="Absorber file (default: seed 004's design)."),
    as_json: bool = typer.Option(False, "--json"),
):
    """The coil field that tunes the MRF absorber to a frequency."""
    a = read_absorber(absorber)
    with flag_errors(ABSORBER_FLAGS):
        setting = a.field_for_frequency(target_hz, clamp=True)
    out = {
        "target_hz": target_hz,
        "field_mt": setting.field_t * 1e3,
        "storage_modulus_pa": a.storage_modulus_pa(setting.field_t),
        "feasible": setting.feasible,
        "range_hz": list(a.range_hz),
    }
    if as_json:
        print_json(out)
        return
    state = "" if setting.feasible else f" (outside {a.range_hz[0]:.2f}-{a.range_hz[1]:.2f} Hz: clamped)"
    console.print(f"{target_hz:g} Hz -> {out['field_mt']:.2f} mT, G1 = {out['storage_modulus_pa']:.4g} Pa{state}")


def schedule(
    model_dir: Optional[Path] = typer.Argument(None, help="Model directory (or give --modes or --twin)."),
    modes: Optional[Path] = typer.Option(None, "--modes", help="Modal table instead of a model."),
    twin: Optional[Path] = typer.Option(None, "--twin", help="Robot twin file (e.g. one `posedyn gap --out` wrote): its own modes at the poses (3-D mode shapes) instead of a model."),
    poses: Path = typer.Option(..., "--poses", help="Poses to schedule (CSV with the pose columns)."),
    cut: Optional[Path] = typer.Option(None, "--cut", help="Cut file (TOML; default: MODEL_DIR/cut.toml)."),
    absorber: Optional[Path] = typer.Option(None, "--absorber", help="Absorber file (default: seed 004's design)."),
    policy: Policy = typer.Option(Policy.match, "--policy"),
    actuator: Optional[Path] = typer.Option(None, "--actuator", help="Actuator file for the controller field (default: seed 000's)."),
    reference_tool: Optional[Path] = typer.Option(None, "--reference-tool", help="The tool the modes were measured with (tool file; with --target-tool)."),
    target_tool: Optional[Path] = typer.Option(None, "--target-tool", help="Schedule for this tool: its modes from the reference tool's by receptance coupling (as `posedyn tool-change`)."),
    pivot_mm: float = typer.Option(150.0, "--pivot-mm", help="With --target-tool: where the holder side turns, behind the holder face."),
    robust: bool = typer.Option(False, "--robust", help="Also the depth a cell can count on: the 95 % lower bound over samples of each pose's modes (the model's predictive distribution, or the table's std columns), bare and with the nominal or robust absorber setting."),
    robust_samples: Optional[int] = typer.Option(None, "--robust-samples", min=8, max=2000, help="Latin-hypercube samples per pose for --robust (32; given alone, it turns --robust on, as in sweep and serve)."),
    seed: int = typer.Option(0, "--seed", help="Sampling seed for --robust."),
    out: Optional[Path] = typer.Option(None, "--out", help="Write the schedule (JSON)."),
    as_json: bool = typer.Option(False, "--json"),
):
    """Per-pose absorber schedule: chatter, target frequency, field, current, depths."""
    output_file(out, "--out")
    robust = robust or robust_samples is not None  # (the flag alone was ignored here where sweep and serve took it)
    robust_samples = 32 if robust_samples is None else robust_samples
    the_cut, rpm, steps = read_cut(resolve_cut(cut, model_dir))
    config = ScheduleConfig(the_cut, rpm, read_absorber(absorber), control=read_actuator(actuator), policy=policy.value, steps=steps,
                            robust_samples=robust_samples if robust else 0, robust_seed=seed)
    if (reference_tool is None) != (target_tool is None):
        raise InputError("--reference-tool and --target-tool together", got="one of them", column="--target-tool")
    if target_tool is not None and robust:
        raise InputError("--robust without --target-tool (the coupled modes carry no predictive distribution yet)", got="both", column="--robust")
    if twin is not None:
        if model_dir is not None or modes is not None or target_tool is not None or robust:
            raise InputError("--twin alone as the mode source (no MODEL_DIR, --modes, --target-tool or --robust)", got="more", column="--twin")
        entries = [s.to_json() for s in schedule_poses(twin_modes_at(twin, read_pose_table(poses), poses), config)]
    else:
        table, distributions = modal_input_for(model_dir, modes, poses, distributions=robust)
        if target_tool is not None:
            table = tool_changed_table(table, read_tool(reference_tool), read_tool(target_tool), pivot_mm * 1e-3)
        entries = schedule_entries(table, config, distributions)
    if out is not None:
        _write_json(out, entries)
    if as_json:
        print_json(entries)
        return
    t = Table(title=f"absorber schedule ({policy.value}) at {rpm:g} rpm", title_justify="left")
    for c in ("pose", "critical mm", "chatter Hz", "target Hz", "field mT", "current A", "feasible", "with absorber mm", "depths within"):
        t.add_column(c, justify="right")
    for e in entries:
        a = e["absorber"]
        t.add_row(
            e["pose_id"], _fmt(e["critical_depth_mm"]), f"{e['dominant_chatter_hz']:.2f}", f"{a['target_hz']:.2f}", f"{a['field_mt']:.1f}",
            _fmt(a["current_a"]), "yes" if a["feasible"] else "NO", _fmt(e["critical_depth_with_absorber_mm"]),
            _accuracy(e["stability"], e["stability_with_absorber"]),
        )
    console.print(t)
    if robust:
        t = Table(title=f"guaranteed depths (95 % lower bounds, {robust_samples} samples per pose)", title_justify="left")
        for c in ("pose", "critical mm", "cv %", "tuning", "target Hz", "field mT", "with absorber mm", "nominal setting mm"):
            t.add_column(c, justify="right")
        for e in entries:
            r = e.get("robust")
            if r is None:
                t.add_row(e["pose_id"], *["-"] * 7)
                continue
            t.add_row(e["pose_id"], _fmt(r["critical_depth_p95_mm"]), _fmt(r["critical_depth_cv_pct"]), r["tuning"], f"{r['absorber']['target_hz']:.2f}",
                      f"{r['absorber']['field_mt']:.1f}", _fmt(r["critical_depth_with_absorber_p95_mm"]), _fmt(r["nominal_tuning_with_absorber_p95_mm"]))
        console.print(t)
    if out is not None:
        console.print(f"wrote {out}")


def _accuracy(*stability: dict) -> str:
    """The worse of the depths' accuracies, as `chatter` says it: "0.91 %" (estimated), "NOT
    converged (5 %)", or "not estimated" for the semi-discretization override."""
    if any(s["converged"] is None for s in stability):
        return f"not estimated ({stability[0]['method']})"
    worst = max((s["rel_error_estimate"] for s in stability if s["rel_error_estimate"] is not None), default=math.inf)
    shown = "inf" if not math.isfinite(worst) else f"{100 * worst:.2g}"
    return f"{shown} %" if all(s["converged"] for s in stability) else f"NOT converged ({shown} %)"


def _fmt(value):
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, str):
        return value
    return "-" if value is None else f"{value:.4g}"


def _write_json(path: Path, value) -> None:
    write_text_atomic(path, json.dumps(value, indent=2, allow_nan=False) + "\n")



