"""`posedyn chatter` and `posedyn lobes`: stability of a pose's tool-tip modes in a cut."""

from __future__ import annotations

import math
import os
import sys
import tempfile
import time
from enum import Enum
from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.table import Table

from posedyn.dynamics import ToolTipDynamics
from posedyn.errors import InputError
from posedyn.io import read_modal_table
from posedyn.io.atomic import write_text_atomic
from posedyn.stability import (
    Cut, Discretization, StabilityModel, StabilityResult, absolute_limit, critical_lobes, critical_points, free_flight_decay,
    modes_carrying_over, zoa,
)
from posedyn.stability.cutting import check_rpm
from service.cli.common import Milling, console, finite_or_none, flag_errors, output_file, print_json, soft_mode_warnings


class Method(str, Enum):
    floquet = "floquet"
    sdm = "sdm"
    zoa = "zoa"


MODES = typer.Option(..., "--modes", help="Modal table (CSV), e.g. the output of posedyn predict --out.")
POSE = typer.Option(None, "--pose-id", help="Pose to use (required when the table has several).")
TEETH = typer.Option(..., "--teeth", help="Number of teeth.")
KT = typer.Option(..., "--kt-mpa", help="Tangential cutting-force coefficient Kt (MPa = N/mm^2).")
KN = typer.Option(..., "--kn-mpa", help="Normal cutting-force coefficient Kn (MPa).")
IMMERSION = typer.Option(..., "--radial-immersion", help="Radial immersion a_e / D in (0, 1].")
MILLING = typer.Option(Milling.down, "--milling", help="down or up milling.")
FEED_ANGLE = typer.Option(0.0, "--feed-angle-deg", help="Feed direction measured from the table's x axis towards y.")
STEPS = typer.Option(None, "--steps", min=4, help="Expert override: semi-discretization with this many steps per delay instead of the converged engine (its error is not estimated).")
#: Members of the chatter family the table shows (largest first; --json has all).
FAMILY_SHOWN = 8
ORDER = typer.Option(0, "--order", help="With --steps: 0 zeroth order (seed 004, weights 1/2), 1 first order.")
JSON = typer.Option(False, "--json", help="Print JSON.")


def _setup(modes: Path, pose_id, teeth, kt_mpa, kn_mpa, radial_immersion, milling, feed_angle_deg, steps, order):
    if order != 0 and steps is None:  # (it was ignored: the converged engine has no order)
        raise InputError("--order with --steps (the semi-discretization override)", got=f"--order {order} alone", column="--order")
    table = read_modal_table(modes)
    try:
        dyn = ToolTipDynamics.from_table(table, pose_id)
    except InputError as exc:
        raise exc.located(file=str(modes)) from None
    for line in soft_mode_warnings(table.select_poses([table.poses.index(pose_id) if pose_id is not None else 0]), modes):  # (as `data check`)
        print(f"warning: {line}", file=sys.stderr)
    with flag_errors():
        cut = Cut(
            teeth=teeth,
            kt_pa=kt_mpa * 1e6,
            kn_pa=kn_mpa * 1e6,
            radial_immersion=radial_immersion,
            milling=milling.value,
            feed_angle_deg=feed_angle_deg,
        )
        disc = Discretization(steps=steps or 40, order=order)
    pose = pose_id if pose_id is not None else table.poses.pose_id[0]
    return pose, StabilityModel(dyn, cut, disc)


#: Fewest semi-discretization steps per period of the fastest mode before `--steps` is warned about.
STEPS_PER_PERIOD = 4


def warn_unresolved_steps(model: StabilityModel, rpm: float) -> None:
    """On stderr, where `--steps` leaves the fastest mode fewer than STEPS_PER_PERIOD steps per
    vibration period at the tooth period of `rpm` (a new user's 60 steps on a 3 Hz + 10 kHz table
    read 16.2 mm at 8 Hz; the converged engine 3.53 mm at 10.2 kHz)."""
    fn = float(model.dyn.fn_hz.max())
    per_period = model.disc.steps / (fn * float(model.cut.tooth_period_s(rpm)))
    if per_period < STEPS_PER_PERIOD:
        print(f"warning: {model.disc.steps} steps a tooth period leave the {fn:.4g} Hz mode {per_period:.2g} steps per vibration period "
              f"at {rpm:g} rpm (the semi-discretization needs at least {STEPS_PER_PERIOD}): this depth can be far off; without --steps "
              "the converged engine resolves every mode and says how accurate it is", file=sys.stderr)


def chatter(
    modes: Path = MODES,
    pose_id: Optional[str] = POSE,
    rpm: float = typer.Option(..., "--rpm", help="Spindle speed (rpm)."),
    teeth: int = TEETH,
    kt_mpa: float = KT,
    kn_mpa: float = KN,
    radial_immersion: float = IMMERSION,
    milling: Milling = MILLING,
    depth_mm: Optional[float] = typer.Option(None, "--depth-mm", help="Also judge this axial depth (mm)."),
    feed_angle_deg: float = FEED_ANGLE,
    steps: int = STEPS,
    order: int = ORDER,
    as_json: bool = JSON,
):
    """Critical depth and dominant chatter frequency at one spindle speed (converged to 2 %)."""
    pose, model = _setup(modes, pose_id, teeth, kt_mpa, kn_mpa, radial_immersion, milling, feed_angle_deg, steps, order)
    check_rpm(rpm, "--rpm")
    if steps is None:
        result = critical_points([model.dyn], model.cut, rpm)[0]
        family = result.family
    else:
        sdm = model.critical_depths([rpm])
        family = sdm.family[0]
        result = StabilityResult(float(sdm.depth_m[0]), float(sdm.dominant_chatter_hz[0]), "sdm", None, float("nan"), steps,
                                 free_flight_decay_efolds=free_flight_decay(model.dyn, model.cut, rpm, float(sdm.dominant_chatter_hz[0])))
        warn_unresolved_steps(model, rpm)
    out = {
        "pose_id": pose,
        "rpm": rpm,
        "critical_depth_mm": finite_or_none(result.depth_m * 1e3),
        "dominant_chatter_hz": finite_or_none(result.chatter_hz),
        "chatter_family_hz": [f for f, _ in family],
        **result.accuracy_json(),
    }
    if depth_mm is not None:
        if not np.isfinite(depth_mm) or depth_mm < 0:
            raise InputError("a depth >= 0", got=depth_mm, column="--depth-mm")
        if steps is None:
            # the engine verifies that no boundary point lies below the critical depth
            out.update(stable=bool(depth_mm * 1e-3 < result.depth_m))
            if out["no_growth_depth_mm"] is not None:  # (only the surface remembers the last pass)
                out.update(grows_between_passes=bool(depth_mm > out["no_growth_depth_mm"]))
        else:
            rho = float(model.spectral_radius(rpm, depth_mm * 1e-3))
            out.update(spectral_radius=rho, stable=rho < 1.0)
    if as_json:
        print_json(out)
        return
    how = "converged engine" if steps is None else f"semi-discretization, {steps} steps: error not estimated"
    table = Table(title=f"pose {pose} at {rpm:g} rpm ({how})", title_justify="left")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    depth = out["critical_depth_mm"]
    unknown = depth is None and not math.isinf(result.depth_m)
    table.add_row("critical depth", ("could not be computed" if unknown else "never chatters") if depth is None else f"{depth:.4g} mm")
    if out["dominant_chatter_hz"] is not None:
        table.add_row("dominant chatter frequency", f"{out['dominant_chatter_hz']:.4g} Hz")
        shown = family[:FAMILY_SHOWN]  # (at 200 rpm, one tooth, a/D 0.02: 550 members above 5 %)
        table.add_row("chatter family", ", ".join(f"{f:.4g} ({a:.0%})" for f, a in shown) + " Hz"
                      + (f" and {len(family) - len(shown)} more (--json)" if len(family) > len(shown) else ""))
    if steps is None:
        state = f"within {100 * result.rel_error_estimate:.2g} % (estimated)" if result.converged else f"NOT converged (estimated error {100 * result.rel_error_estimate:.2g} %)"
        table.add_row("accuracy", state)
    if out["no_growth_depth_mm"] is not None:
        table.add_row("no-growth depth", f"{out['no_growth_depth_mm']:.4g} mm (no surface perturbation grows from one pass to the next below it)")
    if depth_mm is not None:
        verdict = "stable" if out["stable"] else "CHATTER"
        if out.get("grows_between_passes") and out["stable"]:
            verdict += f" in the long run only (deeper than {out['no_growth_depth_mm']:.3g} mm a perturbation of the surface can grow for many passes)"
        if steps is None and not result.converged:
            verdict += "; the critical depth did NOT converge: not assured"
        table.add_row(f"at {depth_mm:g} mm", verdict if steps is None else f"spectral radius {out['spectral_radius']:.6f} ({verdict})")
    console.print(table)
    if result.surface_memory:
        note = (f"note: between cuts the chattering mode's vibration decays by e^-{result.free_flight_decay_efolds:.0f}: only the surface remembers the last pass, and the "
                "critical depth is the asymptotic (Floquet) boundary; ")
        if out["no_growth_depth_mm"] is not None:
            note += (f"from {out['no_growth_depth_mm']:.3g} mm a perturbation of the surface can grow for many passes before it decays, and below "
                     "that depth none grows from one pass to the next: keep below it")
        else:
            carrying = modes_carrying_over(model.dyn, model.cut, rpm)
            note += ("below it a perturbation can grow for many passes before it decays (300-fold at a sixth of it in the README's 300 rpm "
                     f"example); the depth where that starts is not given here because the {', '.join(f'{f:.4g}' for f in carrying)} Hz "
                     "mode keeps vibrating between cuts (it needs every mode to die out): keep well below the critical depth")
        console.print(note)


#: Speeds a lobe diagram computes between progress lines on a terminal (`_lobes_with_progress`).
PROGRESS_SPEEDS = 25


def _lobes_with_progress(model, rpm: np.ndarray, workers: int) -> list:
    """`critical_lobes`, and on a terminal a line on stderr after each PROGRESS_SPEEDS speeds
    (low speeds with kHz modes take seconds a speed: 200 of them ran 8-12 min in silence);
    piped or captured, all at once."""
    if not sys.stderr.isatty() or len(rpm) <= PROGRESS_SPEEDS:
        return critical_lobes(model.dyn, model.cut, rpm, workers=workers)
    results, start = [], time.monotonic()
    for lo in range(0, len(rpm), PROGRESS_SPEEDS):
        results += critical_lobes(model.dyn, model.cut, rpm[lo : lo + PROGRESS_SPEEDS], workers=workers)
        done, spent = len(results), time.monotonic() - start
        print(f"lobes: {done} of {len(rpm)} speeds, {spent:.0f} s" + (f", about {spent / done * (len(rpm) - done):.0f} s to go" if done < len(rpm) else ""),
              file=sys.stderr, flush=True)
    return results


def lobes(
    modes: Path = MODES,
    pose_id: Optional[str] = POSE,
    rpm_min: float = typer.Option(..., "--rpm-min", help="Lowest spindle speed (rpm)."),
    rpm_max: float = typer.Option(..., "--rpm-max", help="Highest spindle speed (rpm)."),
    rpm_steps: int = typer.Option(200, "--rpm-steps", help="Number of speeds."),
    teeth: int = TEETH,
    kt_mpa: float = KT,
    kn_mpa: float = KN,
    radial_immersion: float = IMMERSION,
    milling: Milling = MILLING,
    method: Method = typer.Option(Method.floquet, "--method", help="floquet (converged engine), sdm (semi-discretization, --steps) or zoa (zeroth-order approximation)."),
    feed_angle_deg: float = FEED_ANGLE,
    steps: int = STEPS,
    order: int = ORDER,
    csv_out: Optional[Path] = typer.Option(None, "--csv", help="Write rpm, critical_depth_mm (and, with floquet, rel_error_estimate, converged) to this CSV."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Write a PNG of the lobes."),
    workers: int = typer.Option(2, "--workers", min=1, help="Processes sharing the speeds (floquet; one core each)."),
    as_json: bool = JSON,
):
    """Stability lobes: critical depth against spindle speed, and the absolute limit."""
    output_file(csv_out, "--csv")
    output_file(plot, "--plot")
    if steps is not None and method is Method.zoa:
        raise InputError("--steps with --method sdm (or floquet, which it replaces), not zoa", got=steps, column="--steps")
    if steps is not None:  # the expert override, as in `posedyn chatter`
        method = Method.sdm
    pose, model = _setup(modes, pose_id, teeth, kt_mpa, kn_mpa, radial_immersion, milling, feed_angle_deg, steps, order)
    check_rpm(rpm_min, "--rpm-min")
    check_rpm(rpm_max, "--rpm-max")
    if not rpm_min < rpm_max:
        raise InputError("--rpm-min < --rpm-max", got=(rpm_min, rpm_max), column="--rpm-min")
    if rpm_steps < 2:
        raise InputError("at least 2 speeds", got=rpm_steps, column="--rpm-steps")
    rpm = np.linspace(rpm_min, rpm_max, rpm_steps)
    converged, no_growth, rel_error = None, np.full(len(rpm), np.nan), None
    if method is Method.floquet:
        results = _lobes_with_progress(model, rpm, workers)
        depth = np.array([r.depth_m for r in results])
        converged = [r.converged for r in results]
        rel_error = [finite_or_none(r.rel_error_estimate) for r in results]
        no_growth = np.array([r.no_growth_depth_m for r in results])
        limit = absolute_limit(model.dyn, model.cut, depth)
        absolute, source = limit.depth_m, limit.source
    elif method is Method.sdm:
        depth = model.critical_depths(rpm, frequencies=False).depth_m
        absolute, _ = model.absolute_limit_m()  # the semi-discretization's own lobe bottoms
        absolute, source = min(absolute, float(np.nanmin(depth, initial=np.inf))), "sdm"
    else:
        depth = zoa.lobes(model.dyn, model.cut, rpm)
        absolute, source = zoa.absolute_limit_m(model.dyn, model.cut), "zoa"
    depth_mm = [finite_or_none(d * 1e3) for d in depth]
    out = {"rpm": rpm.tolist(), "critical_depth_mm": depth_mm, "absolute_limit_mm": finite_or_none(absolute * 1e3), "absolute_limit_source": source, "method": method.value}
    if converged is not None:
        out["converged"] = converged
        out["rel_error_estimate"] = rel_error
    if np.isfinite(no_growth).any():  # (where only the surface remembers the last pass)
        out["no_growth_depth_mm"] = [finite_or_none(d * 1e3) for d in no_growth]
    if method is Method.sdm:
        out["steps"] = model.disc.steps
    if csv_out is not None:
        _write_csv(csv_out, rpm, depth_mm, rel_error, converged)
    if plot is not None:
        _plot(plot, rpm, depth * 1e3, absolute * 1e3, f"pose {pose}, {method.value}", no_growth * 1e3)
    if as_json:
        print_json(out)
        return
    how = f"{method.value}, {model.disc.steps} steps per delay: error not estimated" if method is Method.sdm else method.value
    if rel_error is not None and any(e is not None for e in rel_error):
        how += f", within {100 * max(e for e in rel_error if e is not None):.2g} % (estimated, the worst speed)"
    console.print(f"pose {pose}: {how} lobes over {rpm_min:g}-{rpm_max:g} rpm")
    said = {"zoa": "zeroth-order estimate", "sdm": "semi-discretization lobe bottoms", "computed": "the lowest depth computed: the zeroth-order estimate is above it"}[source]
    console.print(f"  lowest critical depth {np.min(depth) * 1e3:.4g} mm at {rpm[np.argmin(depth)]:.0f} rpm; absolute limit {absolute * 1e3:.4g} mm ({said})")
    best = int(np.argmax(np.where(np.isfinite(depth), depth, -np.inf)))
    console.print(f"  highest critical depth {depth[best] * 1e3:.4g} mm at {rpm[best]:.0f} rpm")
    if np.isfinite(no_growth).any():
        shown = no_growth[np.isfinite(no_growth)] * 1e3
        console.print(f"  only the surface remembers the last pass at {len(shown)} of {len(rpm)} speeds: there the critical depth is the asymptotic "
                      f"boundary, and no surface perturbation grows from one pass to the next below {shown.min():.4g}-{shown.max():.4g} mm "
                      "(--json: 'no_growth_depth_mm'; `posedyn chatter` at one speed says more)")
    if converged is not None and not all(converged):
        missed = [f"{r:.0f}" for r, ok in zip(rpm, converged) if not ok]
        console.print(f"  NOT converged at {len(missed)} of {len(rpm)} speeds ({', '.join(missed[:8])}{', ...' if len(missed) > 8 else ''} rpm): "
                      "those depths are not assured (--json: 'converged')")
    for path in (csv_out, plot):
        if path is not None:
            console.print(f"  wrote {path}")


def _write_csv(path: Path, rpm, depth_mm, rel_error=None, converged=None) -> None:
    """rpm, critical_depth_mm and, where the engine estimated them, rel_error_estimate and converged."""
    text = lambda v: "" if v is None else repr(v)  # noqa: E731
    if rel_error is None:
        lines = ["rpm,critical_depth_mm"] + [f"{float(r)!r},{text(d)}" for r, d in zip(rpm, depth_mm)]
    else:
        lines = ["rpm,critical_depth_mm,rel_error_estimate,converged"] + [
            f"{float(r)!r},{text(d)},{text(e)},{str(bool(c)).lower()}" for r, d, e, c in zip(rpm, depth_mm, rel_error, converged)]
    write_text_atomic(path, "\n".join(lines) + "\n")


def _plot(path: Path, rpm, depth_mm, absolute_mm, title: str, no_growth_mm=None) -> None:
    import matplotlib  # heavy (about 0.3 s): only when a figure is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # heavy (about 0.3 s): only when a figure is drawn

    fig, ax = plt.subplots(figsize=(8, 4.5))
    ax.fill_between(rpm, np.where(np.isfinite(depth_mm), depth_mm, np.nan), np.nanmax(depth_mm[np.isfinite(depth_mm)]) * 1.1, color="tab:red", alpha=0.12, label="chatter")
    ax.plot(rpm, depth_mm, color="tab:red")
    if np.isfinite(absolute_mm):
        ax.axhline(absolute_mm, color="0.3", ls="--", lw=1, label=f"absolute limit {absolute_mm:.3g} mm")
    if no_growth_mm is not None and np.isfinite(no_growth_mm).any():
        ax.plot(rpm, no_growth_mm, color="tab:blue", lw=1.5, label="no-growth depth (surface memory)")
    ax.set_xlabel("spindle speed (rpm)")
    ax.set_ylabel("critical axial depth (mm)")
    ax.set_title(title)
    ax.set_ylim(bottom=0)
    ax.legend(loc="upper right")
    fig.tight_layout()
    fd, tmp = tempfile.mkstemp(dir=path.parent if str(path.parent) else ".", prefix=f".{path.name}.", suffix=".png")
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=120)
        os.replace(tmp, path)
    finally:
        plt.close(fig)
        Path(tmp).unlink(missing_ok=True)
