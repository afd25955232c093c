"""FRFs to a modal table: the identification of `posedyn.identify` per pose (a common-pole
matrix fit where the x-y FRF matrix is given, with the cross stiffnesses; direct fits
otherwise), the one place identified modes become a ModalTable (`posedyn fit`, `posedyn
tool-change`)."""

from __future__ import annotations

import contextlib
import math
from typing import Optional

import numpy as np

from posedyn.errors import InputError
from posedyn.identify import IdentifiedMode, direct_modal_parameters, lsfd, matrix_modal_fit
from posedyn.table import ModalTable, PoseSet


#: A mode of the matrix fit whose direct residue in one direction is below this share of the
#: two is a mode of the other direction alone (its row there would have a modal stiffness of
#: noise, 1e20 N/m and cross terms of 1e14 of either sign, which the table format refuses).
SINGLE_DIRECTION = 0.01


def _matrix_mode_rows(mode) -> list:
    """[(direction, k_direct, k_cross or NaN, relative std of k_direct)] of one common-pole mode (shapes L, R; residue
    L_i R_j / w^2 = 1 / k_ij): one row where it lives in one direction only, two uncoupled rows
    where the cross terms' signs disagree (coupling within the noise: the format needs k_xy and
    k_yx of one sign), else the two coupled rows (rank one: k_yy = k_xy k_yx / k_xx exactly)."""
    w2 = (2 * math.pi * mode["fn_hz"]) ** 2
    (lx, ly), (rx, ry) = mode["shape_left"], mode["shape_right"]
    rel_x, rel_y = mode.get("rel_std_k", (np.nan, np.nan))
    rxx, ryy = abs(lx * rx), abs(ly * ry)
    share_y = ryy / (rxx + ryy)
    if share_y < SINGLE_DIRECTION:
        return [("x", w2 / (lx * rx), np.nan, rel_x)]
    if share_y > 1.0 - SINGLE_DIRECTION:
        return [("y", w2 / (ly * ry), np.nan, rel_y)]
    k_xy, k_yx = w2 / (lx * ry), w2 / (ly * rx)
    if np.sign(k_xy) != np.sign(k_yx):
        return [("x", w2 / (lx * rx), np.nan, rel_x), ("y", w2 / (ly * ry), np.nan, rel_y)]
    return [("x", w2 / (lx * rx), k_xy, rel_x), ("y", w2 / (ly * ry), k_yx, rel_y)]


def fit_table(frfs, fmin_hz=None, fmax_hz=None, max_order: int = 40, modes: Optional[int] = None, weighting: str = "relative"):
    """A ModalTable (one pose per FRF set) and, per pose, what the fits found (for plots);
    `weighting`: LSFD's (`identify.WEIGHTINGS`; "absolute" for computed, noise-free FRFs)."""
    rows = {k: [] for k in ("pose_index", "direction", "mode", "fn_hz", "zeta", "k_n_per_m")}
    std = {"std_fn_hz": [], "std_zeta": [], "std_k_n_per_m": []}
    cross = {"k_xy_n_per_m": [], "k_yx_n_per_m": []}
    fits = []
    has_cross = False
    for p, frf in enumerate(frfs):
        f = frf.frequency_hz
        found = {}
        if all(n in frf.frf for n in ("h_xx", "h_xy", "h_yx", "h_yy")):
            with _named(frf, "h_xx, h_xy, h_yx, h_yy"):
                coupled, rebuilt = matrix_modal_fit(f, frf.frf, fmin_hz, fmax_hz, max_order, weighting)
            coupled = coupled[:modes] if modes else coupled
            has_cross = True
            for m, mode in enumerate(coupled, 1):
                for d, k_direct, k_cross, rel_std_k in _matrix_mode_rows(mode):
                    rows["pose_index"].append(p)
                    rows["direction"].append(d)
                    rows["mode"].append(m)
                    rows["fn_hz"].append(mode["fn_hz"])
                    rows["zeta"].append(mode["zeta"])
                    rows["k_n_per_m"].append(abs(k_direct))
                    std["std_fn_hz"].append(mode.get("std_fn_hz", np.nan))
                    std["std_zeta"].append(mode.get("std_zeta", np.nan))
                    std["std_k_n_per_m"].append(abs(k_direct) * rel_std_k)
                    cross["k_xy_n_per_m"].append(k_cross if d == "x" else np.nan)
                    cross["k_yx_n_per_m"].append(k_cross if d == "y" else np.nan)
            found["matrix"] = (coupled, rebuilt)
        else:
            for d in "xyz":
                name = f"h_{d}{d}"
                if name not in frf.frf:
                    continue
                with _named(frf, name):
                    params = direct_modal_parameters(f, frf.frf[name], fmin_hz, fmax_hz, max_order, weighting)
                params = params[:modes] if modes else params
                found[name] = params
                for m, par in enumerate(params, 1):
                    rows["pose_index"].append(p)
                    rows["direction"].append(d)
                    rows["mode"].append(m)
                    for key in ("fn_hz", "zeta", "k_n_per_m"):
                        rows[key].append(par[key])
                    for key in std:
                        std[key].append(par[key])
                    for key in cross:
                        cross[key].append(np.nan)
            if not found:
                raise InputError("direct FRFs (h_xx, h_yy, h_zz) or the x-y matrix", got=sorted(frf.frf), file=frf.source)
        fits.append(found)
    _check_poses(frfs)
    orientation = "abc" if any("a_deg" in f.pose for f in frfs) else "beta"
    angles = [[f.pose.get(k, 0.0) for k in (("a_deg", "b_deg", "c_deg") if orientation == "abc" else ("beta_deg",))] for f in frfs]
    poses = PoseSet(
        pose_id=tuple(f.pose_id for f in frfs),
        position_mm=np.array([[f.pose.get(k, 0.0) for k in ("x_mm", "y_mm", "z_mm")] for f in frfs]),
        orientation=orientation,
        orientation_deg=np.array(angles),
    )
    table = ModalTable(poses=poses, std={k: v for k, v in std.items() if not np.all(np.isnan(v))}, cross=cross if has_cross else {}, source=("posedyn fit",) * len(rows["fn_hz"]), **rows)
    return table, fits


@contextlib.contextmanager
def _named(frf, name: str):
    """An identification error names the file and the FRF (it read "column 'frf'", no file)."""
    try:
        yield
    except InputError as exc:
        raise InputError(exc.expected, got=exc.got, file=frf.source or None, column=name if exc.column == "frf" else exc.column) from None


def _check_poses(frfs) -> None:
    """Every FRF set gives the whole pose (x_mm, y_mm, z_mm and beta_deg or a/b/c_deg, as the
    first one does), or none does (a table of poses at the origin, by pose_id only): a pose with
    a key left out was silently put at 0 there."""
    given = [f for f in frfs if f.pose]
    if not given:
        return
    orientation = ("a_deg", "b_deg", "c_deg") if any(k in given[0].pose for k in ("a_deg", "b_deg", "c_deg")) else ("beta_deg",)
    for f in frfs:
        missing = [k for k in ("x_mm", "y_mm", "z_mm") + orientation if k not in f.pose]
        if missing:
            raise InputError(f"the whole pose in every file ({', '.join(('x_mm', 'y_mm', 'z_mm') + orientation)}, as in {given[0].source or given[0].pose_id})",
                             got=f"no {missing[0]}", file=f.source or None, column=missing[0])


#: A fitted FRF that misses the measured one by more than this share of the measured peak at
#: some frequency of the band has left a mode out (a new user's 1 Hz-resolution x FRF lost its
#: 10 Hz robot mode in 4 of 8 noise seeds: a 100 % miss there, 1-3 % where it was found).
FIT_MISS = 0.25


def fitted_frfs(frf, found) -> dict:
    """{FRF name: the fitted FRF} of one pose's fit (`fit_table`'s `fits` entry): the matrix
    fit's reconstruction, or LSFD with the identified poles for each direct FRF."""
    if "matrix" in found:
        return dict(found["matrix"][1])
    return {name: lsfd(frf.frequency_hz, frf.frf[name], [IdentifiedMode(p["fn_hz"], p["zeta"], 0, 0) for p in params])[2][:, 0]
            for name, params in found.items()}


def fit_misses(frfs, fitted, fmin_hz=None, fmax_hz=None) -> list[str]:
    """One line for every FRF whose fit (`fitted`: each pose's `fitted_frfs`) misses the
    measurement by more than FIT_MISS of its peak somewhere in the band (where, and what to try)."""
    out = []
    for frf, fits in zip(frfs, fitted):
        f = frf.frequency_hz
        band = (f >= (fmin_hz or -np.inf)) & (f <= (fmax_hz or np.inf))
        for name, fit in fits.items():
            h = frf.frf[name]
            rel = np.where(band, np.abs(h - fit), 0.0) / np.abs(h[band]).max()
            k = int(np.argmax(rel))
            if rel[k] > FIT_MISS:
                out.append(f"pose {frf.pose_id}, {name}: the fitted FRF misses the measured one by {rel[k]:.0%} of its peak at {f[k]:.4g} Hz: a mode there "
                           "was not identified (see --plot; try --fmin-hz/--fmax-hz around it, --max-order, or a finer frequency resolution)")
    return out
