"""Frequency response functions from impact tests: CSV and UFF (dataset 58, through pyuff).

CSV format: optional `# key = value` header lines, then a header row `frequency_hz,
<name>_re, <name>_im[, <name>_coh], ...` with one row per frequency, frequencies strictly
increasing. Names are `h_<response><reference>` with directions x, y, z (`h_xx`, `h_xy`).
Header keys:

    # quantity = receptance | mobility | accelerance     (default receptance)
    # unit = m/N | m/s/N | m/s^2/N                       (must match the quantity)
    # pose_id = P1
    # x_mm = 1500
    # y_mm = 0
    # z_mm = 600
    # beta_deg = 0                                       (or a_deg, b_deg, c_deg; q1_deg..q6_deg)

UFF: each dataset 58 with function type 4 (FRF) is one FRF; response and reference directions
(1 = x, 2 = y, 3 = z; negative: measured along the negative axis, the FRF's sign follows) name it,
ordinate type 8 / 11 / 12 gives displacement / velocity / acceleration, and `id2` holds the pose
as `pose_id=P1;x_mm=1500;...` (the CSV header's pose keys, each once, the same in every dataset). Files are written in
ASCII (pyuff's binary writer does not read back): values keep 12-13 significant digits, so a
first write-then-read agrees to about 1e-12 and every later read-write-read is exact.

Mobility and accelerance are converted to receptance: H = Y / (i w), H = A / (-w^2).
"""

from __future__ import annotations

import csv
import io
import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from posedyn.errors import InputError
from posedyn.io.atomic import write_text_atomic

QUANTITIES = {"receptance": "m/N", "mobility": "m/s/N", "accelerance": "m/s^2/N"}
UFF_ORDINATE = {"receptance": 8, "mobility": 11, "accelerance": 12}
POSE_KEYS = ("x_mm", "y_mm", "z_mm", "beta_deg", "a_deg", "b_deg", "c_deg") + tuple(f"q{j}_deg" for j in range(1, 7))
#: The `# key = value` lines a CSV FRF file may hold (others are refused: a misspelt pose key
#: would silently leave the pose out).
HEADER_KEYS = ("quantity", "unit", "pose_id") + POSE_KEYS
DIRS = "xyz"
#: An FRF's name: h_<response><reference>.
FRF_NAMES = tuple(f"h_{r}{e}" for r in DIRS for e in DIRS)


@dataclass(frozen=True, eq=False)
class FRFSet:
    """Receptances (m/N) of one pose at common frequencies: `frf[name]` complex (n,), names like
    'h_xx'; optional coherence per name; the pose as given in the file."""

    frequency_hz: np.ndarray
    frf: dict
    coherence: dict = field(default_factory=dict)
    pose_id: str = ""
    pose: dict = field(default_factory=dict)
    source: str = ""

    def __post_init__(self):
        f = np.asarray(self.frequency_hz, dtype=float)
        object.__setattr__(self, "frequency_hz", f)
        _check_frequencies(f, self.source)
        for name, values in self.frf.items():
            if np.shape(values) != f.shape or not np.all(np.isfinite(values)):
                raise InputError(f"{len(f)} finite complex values", got=np.shape(values), file=self.source or None, column=name)

    @property
    def omega_rad_s(self) -> np.ndarray:
        return 2.0 * np.pi * self.frequency_hz


def _check_frequencies(f: np.ndarray, source: str, lines=None) -> None:
    if f.ndim != 1 or len(f) < 3:
        raise InputError("at least three frequencies", got=len(np.atleast_1d(f)), file=source or None, column="frequency_hz")
    bad = np.flatnonzero(~np.isfinite(f) | (f < 0))
    if len(bad):
        i = int(bad[0])
        raise InputError("finite frequencies >= 0 Hz", got=float(f[i]), file=source or None, row=i + 1, line=None if lines is None else lines[i + 1],
                         column="frequency_hz")
    d = np.diff(f)
    if np.any(d <= 0):
        i = int(np.flatnonzero(d <= 0)[0]) + 1
        what = "duplicated" if d[i - 1] == 0 else "decreasing"
        raise InputError("strictly increasing frequencies", got=f"{what} at {f[i]:g} Hz", file=source or None, row=i + 1, line=None if lines is None else lines[i], column="frequency_hz")


def to_receptance(values: np.ndarray, frequency_hz: np.ndarray, quantity: str) -> np.ndarray:
    w = 2.0 * np.pi * frequency_hz
    with np.errstate(divide="ignore", invalid="ignore"):
        if quantity == "mobility":
            out = values / (1j * w)
        elif quantity == "accelerance":
            out = values / (-(w**2))
        else:
            out = values
    return np.where(w > 0, out, values if quantity == "receptance" else 0.0)


def from_receptance(values: np.ndarray, frequency_hz: np.ndarray, quantity: str) -> np.ndarray:
    w = 2.0 * np.pi * frequency_hz
    return {"receptance": values, "mobility": values * 1j * w, "accelerance": values * -(w**2)}[quantity]


def read_frf_csv(path: str | os.PathLike) -> FRFSet:
    path = Path(path)
    name = str(path)
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except OSError as exc:
        raise InputError("a readable file", got=exc.strerror, file=name) from None
    except UnicodeDecodeError as exc:
        raise InputError("UTF-8 text", got=f"byte offset {exc.start}", file=name) from None
    meta, meta_line, pose, body_lines, first_line = {}, {}, {}, [], None
    for number, raw in enumerate(text.splitlines(), 1):
        stripped = raw.strip()
        if not stripped:
            continue
        if stripped.startswith("#") and first_line is None:
            key, sep, value = stripped[1:].partition("=")
            key = key.strip()
            if sep:  # (a line without "=" is a comment)
                if key not in HEADER_KEYS:
                    raise InputError("a header key among " + ", ".join(HEADER_KEYS), got=key, file=name, line=number, column=key)
                if key in meta:
                    raise InputError(f"each header key once (already on line {meta_line[key]})", got=key, file=name, line=number, column=key)
                if key in POSE_KEYS:
                    pose[key] = _pose_value(value, file=name, line=number, column=key)
                meta[key], meta_line[key] = value.strip(), number
            continue
        if first_line is None:
            first_line = number
        body_lines.append((number, raw))
    if not body_lines:
        raise InputError("a header row and data rows", got="an empty file", file=name)
    quantity = meta.get("quantity", "receptance")
    if quantity not in QUANTITIES:
        raise InputError("quantity receptance, mobility or accelerance", got=quantity, file=name, column="quantity")
    unit = meta.get("unit", QUANTITIES[quantity])
    if unit != QUANTITIES[quantity]:
        raise InputError(f"unit {QUANTITIES[quantity]} for {quantity}", got=unit, file=name, column="unit")
    rows = list(csv.reader(io.StringIO("\n".join(raw for _, raw in body_lines))))
    header = [c.strip() for c in rows[0]]
    line_of = [n for n, _ in body_lines]
    if "frequency_hz" not in header:
        raise InputError("a frequency_hz column", got="missing", file=name, line=line_of[0], column="frequency_hz")
    names = sorted({c[: -len(s)] for c in header for s in ("_re", "_im", "_coh") if c.endswith(s)})
    for k, c in enumerate(header):
        if c != "frequency_hz" and not any(c.endswith(s) for s in ("_re", "_im", "_coh")):
            raise InputError("frequency_hz and <name>_re / _im / _coh columns", got=c, file=name, line=line_of[0], column=c)
        if c in header[:k]:
            raise InputError("each column once", got=f"{c} twice", file=name, line=line_of[0], column=c)
    for n in names:
        if n not in FRF_NAMES:
            raise InputError("FRF names h_<response><reference> with directions x, y, z (h_xx, h_xy, ...)", got=n, file=name, line=line_of[0], column=n + "_re")
    for n in names:
        for part in ("_re", "_im"):
            if n + part not in header:
                raise InputError(f"both {n}_re and {n}_im", got="missing", file=name, line=line_of[0], column=n + part)
    if not names:
        raise InputError("at least one FRF (<name>_re, <name>_im)", got="none", file=name, line=line_of[0])
    data = np.empty((len(rows) - 1, len(header)))
    for r, cells in enumerate(rows[1:], 1):
        if len(cells) != len(header):
            raise InputError(f"{len(header)} fields like the header", got=len(cells), file=name, row=r, line=line_of[r], column=None)
        for c, cell in enumerate(cells):
            try:
                value = float(cell)
            except ValueError:
                raise InputError("a number", got=cell, file=name, row=r, line=line_of[r], column=header[c]) from None
            if not math.isfinite(value):
                raise InputError("a finite number (no NaN or inf)", got=cell, file=name, row=r, line=line_of[r], column=header[c])
            data[r - 1, c] = value
    col = {c: data[:, i] for i, c in enumerate(header)}
    f = col["frequency_hz"]
    _check_frequencies(f, name, line_of[1:] and [None] + line_of[1:])
    frf = {n: to_receptance(col[n + "_re"] + 1j * col[n + "_im"], f, quantity) for n in names}
    coherence = {n: col[n + "_coh"] for n in names if n + "_coh" in col}
    return FRFSet(frequency_hz=f, frf=frf, coherence=coherence, pose_id=meta.get("pose_id", path.stem), pose=pose, source=name)


def _pose_value(text: str, **where) -> float:
    """A pose key's value in an FRF file (CSV header or UFF id2): a finite number, else an
    InputError at `where`."""
    try:
        value = float(text)
    except ValueError:
        raise InputError("a number", got=text.strip(), **where) from None
    if not math.isfinite(value):
        raise InputError("a finite number", got=text.strip(), **where)
    return value


def write_frf_csv(frfs: FRFSet, path: str | os.PathLike, quantity: str = "receptance") -> None:
    lines = [f"# quantity = {quantity}", f"# unit = {QUANTITIES[quantity]}", f"# pose_id = {frfs.pose_id}"]
    lines += [f"# {k} = {v!r}" for k, v in frfs.pose.items()]
    names = sorted(frfs.frf)
    header = ["frequency_hz"] + [f"{n}{s}" for n in names for s in ("_re", "_im")] + [f"{n}_coh" for n in names if n in frfs.coherence]
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    converted = {n: from_receptance(frfs.frf[n], frfs.frequency_hz, quantity) for n in names}
    for i, f in enumerate(frfs.frequency_hz):
        row = [repr(float(f))]
        for n in names:
            row += [repr(float(converted[n][i].real)), repr(float(converted[n][i].imag))]
        row += [repr(float(frfs.coherence[n][i])) for n in names if n in frfs.coherence]
        writer.writerow(row)
    write_text_atomic(path, "\n".join(lines) + "\n" + buffer.getvalue())


def write_frf_uff(frfs: FRFSet, path: str | os.PathLike, quantity: str = "receptance") -> None:
    import pyuff  # optional reader, loaded only for .uff files

    path = Path(path)
    pose = ";".join([f"pose_id={frfs.pose_id}"] + [f"{k}={v!r}" for k, v in frfs.pose.items()])
    sets = []
    for name in sorted(frfs.frf):
        rsp, ref = name.split("_")[1]
        sets.append(
            pyuff.prepare_58(
                binary=0, func_type=4, id1="posedyn FRF", id2=pose, rsp_node=1, rsp_dir=DIRS.index(rsp) + 1, ref_node=1, ref_dir=DIRS.index(ref) + 1,
                data=from_receptance(frfs.frf[name], frfs.frequency_hz, quantity), x=frfs.frequency_hz,
                abscissa_spec_data_type=18, ordinate_spec_data_type=UFF_ORDINATE[quantity], orddenom_spec_data_type=13,
            )
        )
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".uff")
    os.close(fd)
    try:
        pyuff.UFF(tmp).write_sets(sets, mode="overwrite")
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)


def read_frf_uff(path: str | os.PathLike) -> FRFSet:
    import pyuff  # optional reader, loaded only for .uff files

    path = Path(path)
    name = str(path)
    try:
        sets = pyuff.UFF(name).read_sets()
    except Exception as exc:  # pyuff raises assorted errors for foreign files
        raise InputError("a readable universal file (dataset 58)", got=f"{type(exc).__name__}: {exc}", file=name) from None
    sets = [sets] if isinstance(sets, dict) else list(sets)
    sets = [s for s in sets if s.get("type") == 58 and s.get("func_type") == 4]
    if not sets:
        raise InputError("at least one dataset 58 with function type 4 (FRF)", got="none", file=name)
    by_type = {v: k for k, v in UFF_ORDINATE.items()}
    f = np.asarray(sets[0]["x"], dtype=float)
    frf, first = {}, {}  # first: id2 key -> (the dataset that gave it first, its value)
    for k, s in enumerate(sets, 1):
        quantity = by_type.get(int(s.get("ordinate_spec_data_type", 8)))
        if quantity is None:
            raise InputError("ordinate type 8, 11 or 12 (displacement, velocity, acceleration)", got=s.get("ordinate_spec_data_type"), file=name, row=k, column="ordinate_spec_data_type")
        if not np.array_equal(np.asarray(s["x"], dtype=float), f):
            raise InputError("the same frequencies in every dataset", file=name, row=k, column="x")
        directions = []
        for column in ("rsp_dir", "ref_dir"):
            try:
                d = int(s[column])
            except (KeyError, TypeError, ValueError):
                d = 0
            if not 1 <= abs(d) <= 3:
                raise InputError("a direction 1, 2, 3 (x, y, z) or -1, -2, -3 (measured along -x, -y, -z)", got=s.get(column), file=name, row=k, column=column)
            directions.append(d)
        key = f"h_{DIRS[abs(directions[0]) - 1]}{DIRS[abs(directions[1]) - 1]}"
        if key in frf:
            raise InputError("one dataset per response and reference direction", got=f"{key} twice", file=name, row=k, column="rsp_dir")
        # a negative direction is measured along the negative axis: H along +response, +reference
        # is the measured one times the signs of both
        sign = float(np.sign(directions[0]) * np.sign(directions[1]))
        frf[key] = sign * to_receptance(np.asarray(s["data"], dtype=complex), f, quantity)
        given = {}
        for item in str(s.get("id2", "")).split(";"):
            k_, sep, v = item.partition("=")
            k_ = k_.strip()
            if not sep:  # (free text without "=")
                continue
            if k_ not in HEADER_KEYS[2:]:
                raise InputError("id2 keys among " + ", ".join(HEADER_KEYS[2:]), got=k_, file=name, row=k, column="id2")
            if k_ in given:
                raise InputError("each id2 key once", got=f"{k_} twice", file=name, row=k, column=f"id2 {k_}")
            given[k_] = v.strip() if k_ == "pose_id" else _pose_value(v, file=name, row=k, column=f"id2 {k_}")
        for k_, v in given.items():  # the datasets of one file are one pose
            if k_ in first and first[k_][1] != v:
                raise InputError(f"the same {k_} in every dataset (dataset {first[k_][0]}: {first[k_][1]})", got=v, file=name, row=k, column=f"id2 {k_}")
            first.setdefault(k_, (k, v))
    pose = {k_: v for k_, (_, v) in first.items() if k_ != "pose_id"}
    return FRFSet(frequency_hz=f, frf=frf, pose_id=first.get("pose_id", (0, path.stem))[1], pose=pose, source=name)


def read_frf(path: str | os.PathLike) -> FRFSet:
    suffix = Path(path).suffix.lower()
    return read_frf_uff(path) if suffix in (".uff", ".unv") else read_frf_csv(path)

