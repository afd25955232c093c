"""`posedyn sle` and `posedyn sle compensate`: surface location error (seed 001)."""

from __future__ import annotations

import math
from enum import Enum
from pathlib import Path
from typing import Optional

import numpy as np
import typer

from posedyn.dynamics import ToolTipDynamics, combine
from posedyn.errors import InputError
from posedyn.io import read_modal_table
from posedyn.sle import ENGAGEMENTS, SleCut
from posedyn.sle import compensate, sle_m
from posedyn.stability import Cut, critical_lobes
from service.cli.common import Milling, console, finite_or_none, flag_errors, print_json


#: The SLE's fields as its flags name them (`flag_errors`).
SLE_FLAGS = {"offset_m": ("--offset-um", 1e6), "tolerance_m": ("--tolerance-um", 1e6), "rpm": ("--rpm", None), "slices": ("--axial-slices", None)}


UNCHECKED = "the SLE of a stable cut: --stability checks that the cut does not chatter"


def _stability_note(checked: bool) -> dict:
    """Whether the JSON's SLE was checked for chatter; where not, the same hint as the text (a
    cut above its critical depth has no SLE, and without --stability nothing says so)."""
    return {"stability_checked": True} if checked else {"stability_checked": False, "note": UNCHECKED}


def _stability(dyn: ToolTipDynamics, cut: SleCut, rpm: np.ndarray) -> list:
    """The stability result (critical depth, accuracy) of the SLE's cut at each speed (converged
    engine, straight flutes): the SLE is the error of a stable cut; above that depth the cut
    chatters and it means nothing."""
    stability_cut = Cut(teeth=cut.teeth, kt_pa=cut.kt_pa, kn_pa=cut.kn_pa, radial_immersion=min(1.0, cut.radial_depth_m / cut.tool_diameter_m), milling=cut.milling)
    return critical_lobes(dyn, stability_cut, rpm, workers=2)


Engagement = Enum("Engagement", {name: name for name in ENGAGEMENTS}, type=str)  # the choices `posedyn.sle` takes


def _accuracy(results: list) -> dict:
    """The engine's accuracy per speed, as `lobes --json` gives it."""
    return {"converged": [r.converged for r in results], "rel_error_estimate": [finite_or_none(r.rel_error_estimate) for r in results]}


def _inputs(modes, extra, pose_id, teeth, kt_mpa, kn_mpa, tool_diameter_mm, helix_deg, radial_depth_mm, axial_depth_mm, feed_per_tooth_mm, milling, direction,
            engagement="nominal"):
    parts = []
    for path in [modes] + list(extra or []):
        table = read_modal_table(path)
        try:
            dyn = ToolTipDynamics.from_table(table, pose_id if path == modes else None)
        except InputError as exc:
            raise exc.located(file=str(path)) from None
        parts.append(dyn)
    dyn = combine(*parts)
    if direction == "x":  # the surface normal is x: turn the axes so that it becomes y
        dyn = dyn.rotated(-math.pi / 2)
    with flag_errors():
        cut = SleCut(
            teeth=teeth, kt_pa=kt_mpa * 1e6, kn_pa=kn_mpa * 1e6, tool_diameter_m=tool_diameter_mm * 1e-3, helix_rad=math.radians(helix_deg),
            radial_depth_m=radial_depth_mm * 1e-3, axial_depth_m=axial_depth_mm * 1e-3, feed_per_tooth_m=feed_per_tooth_mm * 1e-3, milling=milling.value,
            engagement=engagement,
        )
    return dyn, cut


def sle(
    action: Optional[str] = typer.Argument(None, help="compensate: iterate the radial depth (seed 001 section 2.3)."),
    modes: Optional[Path] = typer.Option(None, "--modes", help="Tool-tip modal table (CSV)."),
    extra: Optional[list[Path]] = typer.Option(None, "--add-modes", help="Further FRFs to add, e.g. the workpiece/fixture table (repeatable)."),
    pose_id: Optional[str] = typer.Option(None, "--pose-id"),
    direction: str = typer.Option("y", "--direction", help="Surface-normal direction of the modal table: x or y."),
    rpm: Optional[float] = typer.Option(None, "--rpm"),
    rpm_min: Optional[float] = typer.Option(None, "--rpm-min"),
    rpm_max: Optional[float] = typer.Option(None, "--rpm-max"),
    rpm_steps: int = typer.Option(200, "--rpm-steps"),
    teeth: Optional[int] = typer.Option(None, "--teeth"),
    kt_mpa: Optional[float] = typer.Option(None, "--kt-mpa"),
    kn_mpa: Optional[float] = typer.Option(None, "--kn-mpa"),
    tool_diameter_mm: Optional[float] = typer.Option(None, "--tool-diameter-mm"),
    helix_deg: float = typer.Option(0.0, "--helix-deg"),
    radial_depth_mm: Optional[float] = typer.Option(None, "--radial-depth-mm"),
    axial_depth_mm: Optional[float] = typer.Option(None, "--axial-depth-mm"),
    feed_per_tooth_mm: Optional[float] = typer.Option(None, "--feed-per-tooth-mm"),
    milling: Milling = typer.Option(Milling.down, "--milling"),
    engagement: Engagement = typer.Option(Engagement.nominal, "--engagement", help="nominal: seed 001's fixed engagement angles; geometric: the strip the deflected tool really cuts, its chip entering at zero thickness (radial depth up to the tool radius; tens of ms a speed)."),
    slices: int = typer.Option(20, "--axial-slices", min=1),
    offset_um: float = typer.Option(0.0, "--offset-um", help="Robot path offset added to the SLE (seed 001 Table 2)."),
    tolerance_um: float = typer.Option(2.0, "--tolerance-um", help="compensate: stop when the part error is below this."),
    stability: bool = typer.Option(False, "--stability", help="Also whether the cut is stable at each speed (its critical depth by the converged engine: the SLE is the error of a stable cut; a second to minutes a speed, with many modes)."),
    as_json: bool = typer.Option(False, "--json"),
):
    """SLE at one speed (--rpm) or over a range (--rpm-min --rpm-max --rpm-steps); `posedyn sle compensate ...` iterates the radial depth."""
    if action not in (None, "compensate"):
        raise InputError("no action or 'compensate'", got=action, column="ACTION")
    args = dict(modes=modes, teeth=teeth, kt_mpa=kt_mpa, kn_mpa=kn_mpa, tool_diameter_mm=tool_diameter_mm, radial_depth_mm=radial_depth_mm, axial_depth_mm=axial_depth_mm, feed_per_tooth_mm=feed_per_tooth_mm)
    missing = [k for k, v in args.items() if v is None]
    if missing:
        raise InputError("the option --" + missing[0].replace("_", "-"), got="missing", column="--" + missing[0].replace("_", "-"))
    if direction not in ("x", "y"):
        raise InputError("x or y", got=direction, column="--direction")
    if rpm is not None and (rpm_min is not None or rpm_max is not None):
        raise InputError("--rpm (one speed) or --rpm-min and --rpm-max (a range), not both", got="both", column="--rpm")
    if action == "compensate" and rpm is None:
        raise InputError("--rpm for compensate", got="missing", column="--rpm")
    if action is None and rpm is None and (rpm_min is None or rpm_max is None or not 0 < rpm_min < rpm_max or rpm_steps < 2):
        raise InputError("--rpm, or 0 < --rpm-min < --rpm-max with --rpm-steps >= 2", column="--rpm")
    dyn, cut = _inputs(modes, extra, pose_id, teeth, kt_mpa, kn_mpa, tool_diameter_mm, helix_deg, radial_depth_mm, axial_depth_mm, feed_per_tooth_mm, milling, direction,
                       engagement.value)

    offset = offset_um * 1e-6
    if action == "compensate":
        with flag_errors(SLE_FLAGS):
            history = compensate(dyn, cut, rpm, tolerance_um * 1e-6, slices=slices, offset_m=offset)
        out = {"iterations": [{"radial_depth_mm": a * 1e3, "sle_um": e * 1e6, "part_error_um": p * 1e6} for a, e, p in history]}
        if as_json:
            print_json(out)
        else:
            for i, it in enumerate(out["iterations"], 1):
                console.print(f"{i}: radial depth {it['radial_depth_mm']:.4f} mm, SLE {it['sle_um']:.2f} um, part error {it['part_error_um']:.2f} um")
        return
    if rpm is not None:
        with flag_errors(SLE_FLAGS):
            value = float(sle_m(dyn, cut, rpm, slices, offset_m=offset)[0])
        out = {"sle_um": value * 1e6, **_stability_note(stability)}
        if stability:
            result = _stability(dyn, cut, np.array([rpm]))[0]
            critical = result.depth_m
            out.update(critical_depth_mm=finite_or_none(critical * 1e3), stable=bool(cut.axial_depth_m < critical),
                       converged=result.converged, rel_error_estimate=finite_or_none(result.rel_error_estimate))
        if as_json:
            print_json(out)
            return
        console.print(f"SLE {value * 1e6:.3f} um ({'undercut' if value > 0 else 'overcut'}) at {rpm:g} rpm")
        if not stability:
            console.print(f"  ({UNCHECKED})")
        elif not out["stable"]:
            console.print(f"  the cut CHATTERS: axial depth {cut.axial_depth_m * 1e3:g} mm is above the critical depth {critical * 1e3:.4g} mm; the SLE of a stable cut does not apply")
        return
    speeds = np.linspace(rpm_min, rpm_max, rpm_steps)
    with flag_errors(SLE_FLAGS):
        values = sle_m(dyn, cut, speeds, slices, offset_m=offset)
    out = {"rpm": speeds.tolist(), "sle_um": (values * 1e6).tolist(), **_stability_note(stability)}
    if stability:
        results = _stability(dyn, cut, speeds)
        critical = np.array([r.depth_m for r in results])
        stable = cut.axial_depth_m < critical
        out["critical_depth_mm"] = [finite_or_none(d * 1e3) for d in critical]  # (the README's promise, as at one speed)
        out["stable"] = stable.tolist()
        out.update(_accuracy(results))
    if as_json:
        print_json(out)
        return
    counted = values if not stability else values[stable]  # the SLE of the stable speeds only: a chattering cut has none
    if len(counted):
        console.print(f"SLE from {counted.min() * 1e6:.2f} to {counted.max() * 1e6:.2f} um over {rpm_min:g}-{rpm_max:g} rpm" + (" (stable speeds)" if stability else ""))
    if not stability:
        console.print(f"  ({UNCHECKED})")
    elif not stable.all():
        console.print(f"  the cut CHATTERS at {int((~stable).sum())} of {len(speeds)} speeds (axial depth above the critical depth): their SLE does not apply (--json: 'stable')")
