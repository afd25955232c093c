"""`posedyn gap` and `posedyn gap-campaign`: the simulation-versus-measurement gap workflow."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Optional

import typer
from rich.markup import escape

from absorber.coil_dynamics import CoilDrive
from posedyn.errors import InputError
from posedyn.gap import LIBRARY, analyse
from posedyn.gap.twin_candidates import MEASUREMENT_CHAIN, TWIN_EFFECTS, updated_pose_model, updated_twin
from posedyn.io.atomic import write_text_atomic
from posedyn.io.json_values import json_ready
from posedyn.io.measurements import format_measurements, read_measurements
from posedyn.io.model_dir import load_model, save_model
from posedyn.io.params import read_params, write_params
from posedyn.io.shipped import SEED004_ABSORBER, SHIPPED_TWIN
from posedyn.io.twin_file import read_twin, write_twin
from service.cli.common import console, output_file, output_folder, resolve_cut
from service.gap.baseline import Baseline, generate_measurements
from service.gap.report import render


def gap(
    measured: Path = typer.Option(..., "--measured", help="Measurement campaign (CSV; README 'Measurement campaigns')."),
    model: Optional[Path] = typer.Option(None, "--model", help="Model directory: its predictions are the baseline."),
    twin: bool = typer.Option(False, "--twin", help="The robot twin is the baseline (--twin-file to choose one)."),
    twin_file: Path = typer.Option(SHIPPED_TWIN, "--twin-file"),
    cut: Optional[Path] = typer.Option(None, "--cut", help="Cut for critical_depth_mm and sle_um rows (default: MODEL_DIR/cut.toml; needed when the campaign has such rows)."),
    absorber: Optional[Path] = typer.Option(None, "--absorber", help="Absorber for absorber_* rows (default: seed 004's)."),
    out: Path = typer.Option(..., "--out", help="Output directory: report.html, gap.json, and the model with the named effects (twin.toml or model/, cut.toml, absorber.toml) where they apply."),
    as_json: bool = typer.Option(False, "--json"),
):
    """Find where the model and the measurements disagree, name the missing effect, add it, show the gap shrink."""
    if (model is None) == (not twin):
        raise InputError("either --model MODEL_DIR or --twin", column="--model")
    output_folder(out, "--out")
    m = read_measurements(measured)
    if cut is None and model is not None and (model / "cut.toml").exists():
        cut = resolve_cut(cut, model)  # the model's cut; without one, only critical_depth_mm and sle_um rows need --cut
    baseline = Baseline(twin_file=None if model else twin_file, model_dir=model, cut_file=cut, absorber_file=absorber)
    try:
        y, m = baseline.predict(m)
    except InputError as exc:  # a campaign row's problem: name the campaign file and its line
        if exc.row is None:
            raise
        raise exc.located(file=str(measured), line=exc.row + 1) from None
    result = analyse(m, y, library=baseline.library())
    doc = json_ready(result.to_json())
    out.mkdir(parents=True, exist_ok=True)
    doc["updated_model"] = _write_updated_model(out, result, None if model else twin_file, model, measured)
    doc["updated_cut"] = _write_updated_cut(out, result, cut, measured)
    doc["updated_absorber"] = _write_updated_absorber(out, result, absorber, measured)
    write_text_atomic(out / "gap.json", json.dumps(doc, indent=2, allow_nan=False) + "\n")
    write_text_atomic(out / "report.html", render(m, y, result, f"Simulation vs measurement: {measured.name}"))
    if as_json:
        print(json.dumps(doc, indent=2, allow_nan=False))
        return
    console.print(f"RMS normalised residual {result.rmse_before:.3g} -> {result.rmse_after:.3g} (stated noise 1); chi-square p {result.noise_p_before:.2g} -> {result.noise_p_after:.2g}")
    console.print(f"noise: {result.noise['verdict']}")
    for e in doc["effects"]:
        pars = ", ".join(f"{k} = {v:.4g} +- {e['parameter_std'][k]:.2g}" for k, v in e["parameters"].items())
        console.print(escape(f"named: {e['name']} ({pars}): {e['description']} [{e['source']}]"))
    for a in doc["ambiguous"]:
        console.print(f"undecided between {' and '.join(a['candidates'])}: {a['separating_measurement']}")
    if not result.explained:
        console.print("no named effect explains the rest; the residual depends on: " + (", ".join(f"{c['variable']} ({c['quantity']})" for c in doc["residual_correlates"]) or "nothing measured"))
        if result.discrepancy is not None:
            d = result.discrepancy
            console.print(f"map of the {d.quantity} residual over {' and '.join(d.axes)}: from {d.mean.min():.3g} to {d.mean.max():.3g} stds (report)")
    if doc["updated_model"]:
        console.print(f"updated {'model' if model else 'twin'} (the named effects added): {doc['updated_model']}")
    if doc["updated_cut"]:
        console.print(f"updated cut (the named cutting and tool effects added): {doc['updated_cut']}")
    if doc["updated_absorber"]:
        console.print(f"updated absorber (the named fluid effects added): {doc['updated_absorber']}")
    console.print(f"report: {out / 'report.html'}")


def _write_updated_model(out: Path, result, twin_file: Optional[Path], model_dir: Optional[Path], measured: Path) -> Optional[str]:
    """The baseline with the named effects that act through the twin (joint stiffnesses scaled,
    a device's fitted mass on the flange, gravity softening; not the measurement chain's sensor
    mass): DIR/twin.toml for a twin baseline (for `posedyn
    schedule/sweep/plan/twin modes --twin`), DIR/model/ for a physics model (its prior twin
    changed, `posedyn.gap.twin_candidates.updated_pose_model`; for every command that takes a
    MODEL_DIR, its cut.toml copied); None when no such effect was named or the model has no twin."""
    through = {e["name"]: e for e in result.effects if e["name"] in TWIN_EFFECTS}
    values = {name: next(iter(e["parameters"].values())) for name, e in through.items() if name not in MEASUREMENT_CHAIN}
    if not values:
        return None
    lines = []
    for name, e in through.items():
        (key, value), = e["parameters"].items()
        std = e["parameter_std"][key]
        if name == "flange_device":
            lines.append(f"flange_device: mass_kg = {value:.4g} +- {std:.2g} (the device as mounted in the campaign's device = 1 rows)")
        elif name == "sensor_mass":
            lines.append(f"sensor_mass: {value:.4g} +- {std:.2g} kg at the tool tip in the impact tests (not added: the machining robot does not carry it)")
        elif name == "gravity_softening":
            lines.append(f"gravity_softening: + {value:.4g} +- {std:.2g} per kN m of gravity torque")
        else:
            lines.append(f"{name}: stiffness x {2.0**value:.4g} (log2 {value:.4g} +- {std:.2g})")
    if model_dir is not None:
        model = load_model(model_dir)
        if not (model.physics_ or {}).get("used"):
            return None
        path = out / "model"
        save_model(updated_pose_model(model, values, f"posedyn gap on {measured.name}: " + "; ".join(lines)), path)
        if (model_dir / "cut.toml").exists():
            write_text_atomic(path / "cut.toml", (model_dir / "cut.toml").read_text(encoding="utf-8"))
        return str(path)
    spec = read_twin(twin_file)
    path = out / "twin.toml"
    write_twin(path, replace(spec, params=updated_twin(spec.params, values)),
               source=f"{twin_file.name} with the gap workflow's named effects from {measured.name}",
               comment="\n".join([f"posedyn gap on {measured}: the twin {twin_file.name} with the named effects"] + lines))
    return str(path)


#: Named effects that a cut file holds (its coefficients, its SLE offset).
CUT_EFFECTS = ("cutting_coefficient_error", "tool_radius_error", "spindle_runout", "path_following_offset")


def _write_updated_cut(out: Path, result, cut_file: Optional[Path], measured: Path) -> Optional[str]:
    """DIR/cut.toml: the cut file with the named cutting and tool effects: k_t and k_n scaled by
    (1 + s), and the SLE offset of the file's own cut (`[sle] offset_um`, which `posedyn sweep`
    adds to its SLE) grown by minus the radius error, minus the runout's reach e (N / pi)
    sin(pi / N) and the path offset at the cut's feed speed; None when no such effect was named.
    (`load_compliance` belongs to the structure, not the cut: not written.)"""
    named = {e["name"]: next(iter(e["parameters"].values())) for e in result.effects if e["name"] in CUT_EFFECTS}
    if cut_file is None or not named:
        return None
    params = read_params(cut_file)
    c = dict(params["cut"])
    lines = [f"posedyn gap on {measured}: the cut {cut_file.name} with the named effects"]
    if "cutting_coefficient_error" in named:
        factor = 1.0 + named["cutting_coefficient_error"] / 100.0
        c["kt_mpa"], c["kn_mpa"] = float(c["kt_mpa"]) * factor, float(c["kn_mpa"]) * factor
        lines.append(f"cutting_coefficient_error: kt and kn x {factor:.4g}")
    params["cut"] = c
    offset_um = 0.0
    if "sle" in params:
        sle = dict(params["sle"])
        teeth = int(c["teeth"])
        speed_m_min = float(sle["feed_per_tooth_mm"]) * teeth * float(c["rpm"]) / 1000.0
        shifts = {"tool_radius_error": -named.get("tool_radius_error", 0.0),
                  "spindle_runout": -named.get("spindle_runout", 0.0) * teeth / math.pi * math.sin(math.pi / teeth),
                  "path_following_offset": named.get("path_following_offset", 0.0) * speed_m_min}
        for name, shift in shifts.items():
            if name in named:
                lines.append(f"{name}: SLE {shift:+.4g} um at this cut ({speed_m_min:.4g} m/min feed)")
                offset_um += shift
        sle["offset_um"] = float(sle.get("offset_um", 0.0)) + offset_um
        params["sle"] = sle
    meta = dict(params["meta"])
    meta["source"] = f"{cut_file.name} with the gap workflow's named effects from {measured.name}"
    params["meta"] = meta
    path = out / "cut.toml"
    write_params(path, params, comment="\n".join(lines))
    return str(path)


def _write_updated_absorber(out: Path, result, absorber_file: Optional[Path], measured: Path) -> Optional[str]:
    """DIR/absorber.toml: the absorber file (default seed 004's) with the named fluid effects:
    `mrf_temperature_drift` as the drive's modulus temperature law (`[drive]
    modulus_tempco_per_k`, `modulus_reference_c`: what `posedyn plan` and the service's
    trajectories heat the fluid with, and what `posedyn gap` predicts absorber_fn_hz rows at
    their temperature_c with), `mrf_loss_modulus` as `[mrf] zeta_per_tesla` (the absorber's
    damping at every field, in every schedule). None when neither was named.
    (`absorber_gravity_stiffness` depends on the mounting angle, which no command takes: not written.)"""
    named = {e["name"]: e["parameters"] for e in result.effects if e["name"] in ("mrf_temperature_drift", "mrf_loss_modulus")}
    if not named:
        return None
    source = absorber_file if absorber_file is not None else SEED004_ABSORBER
    params = {k: dict(v) for k, v in read_params(source).items()}
    lines = [f"posedyn gap on {measured}: the absorber {source.name} with the named effects"]
    if "mrf_temperature_drift" in named:
        law = named["mrf_temperature_drift"]
        a, reference_c = law["modulus_drop_per_mk"] * 1e-3, law["reference_c"]
        lines.append(f"mrf_temperature_drift: G1 x exp(-{a:.4g} (T - {reference_c:.4g} C))")
        drive = params.setdefault("drive", {})
        if "modulus_tempco_per_k" in drive:  # on top of the file's own law: exp(-a1 (T - T1)) exp(-a2 (T - T2)) = exp(-(a1 + a2)(T - T0))
            a1, t1 = float(drive["modulus_tempco_per_k"]), float(drive.get("modulus_reference_c", CoilDrive().modulus_reference_c))
            reference_c = (a1 * t1 + a * reference_c) / (a1 + a) if a1 + a else t1
            a = a1 + a
        drive["modulus_tempco_per_k"], drive["modulus_reference_c"] = a, reference_c
    if "mrf_loss_modulus" in named:
        params["mrf"]["zeta_per_tesla"] = float(params["mrf"].get("zeta_per_tesla", 0.0)) + named["mrf_loss_modulus"]["zeta_per_tesla"]
        lines.append(f"mrf_loss_modulus: damping ratio + {named['mrf_loss_modulus']['zeta_per_tesla']:.4g} x B (T)")
    params["meta"]["source"] = f"{source.name} with the gap workflow's named effects from {measured.name}"
    path = out / "absorber.toml"
    write_params(path, params, comment="\n".join(lines))
    return str(path)


def gap_campaign(
    out: Optional[Path] = typer.Option(None, "--out", help="Measurement campaign to write (CSV)."),
    hide: list[str] = typer.Option([], "--hide", help="An effect to hide, NAME:parameter=value (repeatable); see `posedyn gap-campaign --list`."),
    seed: int = typer.Option(0, "--seed"),
    poses: int = typer.Option(10, "--poses", min=2),
    twin_file: Path = typer.Option(SHIPPED_TWIN, "--twin-file"),
    cut: Optional[Path] = typer.Option(None, "--cut", help="Cut of the critical_depth_mm rows (posedyn gap needs the same one)."),
    list_effects: bool = typer.Option(False, "--list", help="List the library's effects and exit."),
):
    """A synthetic measurement campaign from the twin with named effects hidden in it (for trying and testing `posedyn gap`)."""
    if list_effects:
        for e in LIBRARY.values():
            through = f"through {', '.join(e.depends_on)}" if e.depends_on else "alike at every condition"
            console.print(escape(f"{e.name}: {', '.join(p.name for p in e.parameters)}; acts on {', '.join(e.quantities)} {through}: {e.description} [{e.source}]"))
        return
    if out is None:
        raise InputError("--out FILE.csv", column="--out")
    output_file(out, "--out")
    hidden = {}
    for text in hide:
        name, _, rest = text.partition(":")
        if name not in LIBRARY:
            raise InputError("an effect among " + ", ".join(LIBRARY), got=name, column="--hide")
        if name in hidden:
            raise InputError("each effect hidden once", got=f"{name} twice", column="--hide")
        ranges = {p.name: (p.lower, p.upper) for p in LIBRARY[name].parameters}
        params = {}
        for item in filter(None, rest.split(",")):
            key, sep, value = (part.strip() for part in item.partition("="))
            try:
                number = float(value)
            except ValueError:
                raise InputError("NAME:parameter=number", got=text, column="--hide") from None
            if key in params:
                raise InputError(f"each parameter of {name} once", got=f"{key} twice", column="--hide")
            if key in ranges and not ranges[key][0] <= number <= ranges[key][1]:  # (NaN too): what posedyn gap searches, and physical
                raise InputError(f"{name}:{key} within [{ranges[key][0]:g}, {ranges[key][1]:g}] (the range posedyn gap searches)", got=value, column="--hide")
            params[key] = number
        expected = [p.name for p in LIBRARY[name].parameters]
        if sorted(params) != sorted(expected):
            raise InputError(f"the parameters {expected} for {name}", got=sorted(params), column="--hide")
        hidden[name] = params
    m = generate_measurements(Baseline(twin_file=twin_file, cut_file=resolve_cut(cut, None)), hidden, seed=seed, poses=poses)
    write_text_atomic(out, format_measurements(m, [c for c in m.conditions if not c.startswith("model_")]))
    console.print(f"wrote {len(m)} measurements to {out}" + (f" with {', '.join(hidden)} hidden" if hidden else ""))
