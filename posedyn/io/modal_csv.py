"""Read and write modal-test tables (CSV, one row per pose x direction x mode).

Columns (units in the names):

    pose_id, x_mm, y_mm, z_mm,                 tool-tip position in the robot base frame
    a_deg, b_deg, c_deg  |  beta_deg           KUKA A/B/C (ZYX Euler) or the redundant angle
    [q1_deg .. q6_deg]                         optional joint angles, all six or none
    direction, mode, fn_hz                     x|y|z, integer >= 1, natural frequency
    two or more of zeta, k_n_per_m, c_ns_per_m, m_kg   (k and m alone do not fix damping)
    [std_fn_hz, std_zeta, std_k_n_per_m]       optional 1-sigma uncertainties (cells may be empty)
    [source]                                   optional free text

Every problem raises `InputError` naming the file, row, line and column. The writer emits the
canonical columns (fn_hz, zeta, k_n_per_m) with shortest round-trip float text, so a table
written and read back is identical.
"""

from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path

import numpy as np

from posedyn.errors import InputError
from posedyn.io.atomic import write_text_atomic
from posedyn.table import (
    CROSS_COLUMNS,
    DIRECTIONS,
    JOINT_COLUMNS,
    MAX_FN_HZ,
    ORIENTATION_COLUMNS,
    POSITION_COLUMNS,
    STD_COLUMNS,
    ModalTable,
    PoseSet,
    coupled_y_stiffness,
)

DYNAMIC_COLUMNS = ("zeta", "k_n_per_m", "c_ns_per_m", "m_kg")
MODE_COLUMNS = ("direction", "mode", "fn_hz")
KNOWN_COLUMNS = frozenset(
    ("pose_id",)
    + POSITION_COLUMNS
    + sum(ORIENTATION_COLUMNS.values(), ())
    + JOINT_COLUMNS
    + MODE_COLUMNS
    + DYNAMIC_COLUMNS
    + STD_COLUMNS
    + CROSS_COLUMNS
    + ("source",)
)
#: Relative tolerance for redundant damping/stiffness/mass columns to agree with each other.
CONSISTENCY_RTOL = 0.01


def read_modal_table(path: str | os.PathLike) -> ModalTable:
    """Load and validate a modal-test CSV file."""
    path = Path(path)
    kind = OTHER_KINDS.get(path.suffix.lower())
    if kind is not None:  # (a cut file given as the table was refused for its first comment line as a column name)
        raise InputError("a modal-test table (CSV; see README: modal-test table)", got=f"a {path.suffix} file ({kind})", file=str(path))
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError("a readable file", got=exc.strerror, file=str(path)) from None
    return parse_modal_table(data, name=str(path))


#: File kinds that are never a modal table, by suffix: what they are in this project.
OTHER_KINDS = {".toml": "a cut, grid, twin, absorber or parameter file", ".uff": "FRFs: `posedyn fit` makes a table of them",
               ".unv": "FRFs: `posedyn fit` makes a table of them", ".json": "JSON", ".npz": "arrays", ".parquet": "a sweep's results",
               ".html": "a report", ".png": "a plot"}


def parse_modal_table(data: bytes | str, name: str = "<table>") -> ModalTable:
    """Validate modal-table text (bytes must be UTF-8; a BOM is allowed)."""
    text = _decode(data, name) if isinstance(data, bytes) else data
    try:
        return _Parser(name).parse(text)
    except InputError as exc:
        raise exc.located(file=name) from None


#: A cross term's row and the row that carries its partner: k_xy (x response to a y force) on an
#: x row, k_yx on the y row of the same pose and mode number (one coupled mode, `ToolTipDynamics.from_table`).
_CROSS_ROWS = {"k_xy_n_per_m": ("x", "y", "k_yx_n_per_m"), "k_yx_n_per_m": ("y", "x", "k_xy_n_per_m")}


#: The two rows of a coupled mode describe one rank-one mode (`ToolTipDynamics.from_table` averages
#: their fn and zeta and derives the y row's direct stiffness, k_yy = k_xy k_yx / k_xx): rows further
#: apart than this are two modes, or a fit that is not rank one, and would be read silently wrong.
COUPLED_FN_TOL = 0.05  # relative difference of the two rows' fn
COUPLED_ZETA_RATIO = 2.0  # largest ratio of their zeta
COUPLED_K_RATIO = 2.0  # largest ratio of the y row's k to k_xy k_yx / k_xx


def _check_cross_pairs(cross_rows: dict) -> None:
    """Every cross term on its own direction's row, with its partner on the other row of the same
    pose and mode (one alone would be dropped: the mode is then read as uncoupled), and the two
    rows of a coupled mode consistent with one rank-one mode (COUPLED_FN_TOL, COUPLED_ZETA_RATIO,
    COUPLED_K_RATIO)."""
    for (pose_id, direction, mode), (at, filled, values) in cross_rows.items():
        for column in sorted(filled):
            own, other, partner = _CROSS_ROWS[column]
            if direction != own:
                raise InputError(f"{column} on {own} rows only (empty on {direction} rows)", got=f"{pose_id}/{direction}/{mode}", column=column, **at)
            if partner not in cross_rows.get((pose_id, other, mode), (None, set(), None))[1]:
                raise InputError(f"{partner} on the {other} row of pose '{pose_id}', mode {mode} as well (a coupled mode carries both cross terms)",
                                 got="none", column=column, **at)
        if direction == "y" and filled:
            x_at, _, (fn_x, zeta_x, k_x, k_xy) = cross_rows[(pose_id, "x", mode)]
            fn_y, zeta_y, k_y, k_yx = values
            one = f"(row {x_at['row']}, the x row of the same coupled mode: one rank-one mode)"
            if abs(fn_y - fn_x) > COUPLED_FN_TOL * 0.5 * (fn_x + fn_y):
                raise InputError(f"fn_hz within {COUPLED_FN_TOL:.0%} of {fn_x!r} {one}", got=repr(fn_y), column="fn_hz", **at)
            if max(zeta_x / zeta_y, zeta_y / zeta_x) > COUPLED_ZETA_RATIO:
                raise InputError(f"zeta within a factor {COUPLED_ZETA_RATIO:g} of {zeta_x!r} {one}", got=repr(zeta_y), column="zeta", **at)
            rank_one = coupled_y_stiffness(k_x, k_xy, k_yx)
            if not rank_one > 0:
                raise InputError(f"k_yx_n_per_m of the sign of k_xy_n_per_m, {k_xy!r} {one}: the y direct stiffness k_xy k_yx / k_xx is > 0",
                                 got=repr(k_yx), column="k_yx_n_per_m", **at)
            if max(k_y / rank_one, rank_one / k_y) > COUPLED_K_RATIO:
                raise InputError(f"k_n_per_m within a factor {COUPLED_K_RATIO:g} of k_xy k_yx / k_xx = {rank_one:.6g} {one}",
                                 got=repr(k_y), column="k_n_per_m", **at)


def write_modal_table(table: ModalTable, path: str | os.PathLike) -> None:
    """Write atomically (temporary file in the same folder, then rename)."""
    write_text_atomic(path, format_modal_table(table))


def format_modal_table(table: ModalTable) -> str:
    poses = table.poses
    std_columns = [c for c in STD_COLUMNS if c in table.std]
    cross_columns = [c for c in CROSS_COLUMNS if c in table.cross]
    header = list(poses.columns) + list(MODE_COLUMNS) + ["zeta", "k_n_per_m"] + std_columns + cross_columns
    if table.source is not None:
        header.append("source")
    pose_numbers = poses.numeric_columns()
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    for i in range(len(table)):
        p = int(table.pose_index[i])
        row = [poses.pose_id[p]] + [_num(pose_numbers[c][p]) for c in poses.columns[1:]]
        row += [table.direction[i], str(int(table.mode[i])), _num(table.fn_hz[i])]
        row += [_num(table.zeta[i]), _num(table.k_n_per_m[i])]
        row += ["" if math.isnan(table.std[c][i]) else _num(table.std[c][i]) for c in std_columns]
        row += ["" if math.isnan(table.cross[c][i]) else _num(table.cross[c][i]) for c in cross_columns]
        if table.source is not None:
            row.append(table.source[i])
        writer.writerow(row)
    return buffer.getvalue()


def _num(value) -> str:
    """Shortest text that parses back to the same float."""
    return repr(float(value))


def _decode(data: bytes, name: str) -> str:
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line_start = data.rfind(b"\n", 0, exc.start) + 1
        line = data.count(b"\n", 0, exc.start) + 1
        field_index = data.count(b",", line_start, exc.start)
        header = data.split(b"\n", 1)[0].decode("utf-8", "replace").strip().split(",")
        column = header[field_index].strip() if field_index < len(header) else None
        raise InputError(
            "UTF-8 text",
            got=f"byte 0x{data[exc.start]:02x} at offset {exc.start}",
            file=name,
            row=line - 1 if line > 1 else None,
            line=line,
            column=column,
        ) from None


class _Parser:
    def __init__(self, name: str):
        self.name = name

    def parse(self, text: str) -> ModalTable:
        reader = csv.reader(io.StringIO(text, newline=""))
        header = next(reader, None)
        while header is not None and not any(cell.strip() for cell in header):
            header = next(reader, None)
        if header is None:
            raise InputError("a header row with the modal-table columns", got="an empty file")
        header_line = reader.line_num
        columns = self._check_header([c.strip() for c in header], header_line)
        rows = []
        for cells in reader:
            if not any(cell.strip() for cell in cells):
                continue
            number = len(rows) + 1
            if len(cells) != len(columns):
                raise InputError(f"{len(columns)} fields like the header", got=len(cells), row=number, line=reader.line_num)
            rows.append((number, reader.line_num, dict(zip(columns, (c.strip() for c in cells)))))
        if not rows:
            raise InputError("at least one data row after the header", got="a header only", line=header_line)
        return self._build(columns, rows)

    def _check_header(self, columns: list[str], line: int) -> list[str]:
        seen = set()
        for name in columns:
            if name not in KNOWN_COLUMNS:
                raise InputError("a known column name (see README: modal-test table)", got=name, line=line, column=name)
            if name in seen:
                raise InputError("each column once", got=f"'{name}' twice", line=line, column=name)
            seen.add(name)
        missing = [c for c in ("pose_id",) + POSITION_COLUMNS + MODE_COLUMNS if c not in seen]
        if missing:
            raise InputError("this required column", got="missing", line=line, column=missing[0])
        has = {kind: [c in seen for c in cols] for kind, cols in ORIENTATION_COLUMNS.items()}
        if any(has["abc"]) and any(has["beta"]):
            raise InputError("either a_deg, b_deg, c_deg or beta_deg, not both", line=line, column="beta_deg")
        if any(has["abc"]) and not all(has["abc"]):
            absent = next(c for c in ORIENTATION_COLUMNS["abc"] if c not in seen)
            raise InputError("all of a_deg, b_deg, c_deg", got="missing", line=line, column=absent)
        if not any(has["abc"]) and not any(has["beta"]):
            raise InputError("orientation columns a_deg, b_deg, c_deg or beta_deg", got="missing", line=line, column="beta_deg")
        joints = [c in seen for c in JOINT_COLUMNS]
        if any(joints) and not all(joints):
            absent = next(c for c in JOINT_COLUMNS if c not in seen)
            raise InputError("all six joint columns q1_deg..q6_deg or none", got="missing", line=line, column=absent)
        dynamic = [c for c in DYNAMIC_COLUMNS if c in seen]
        if len(dynamic) < 2:
            raise InputError("two of zeta, k_n_per_m, c_ns_per_m, m_kg", got=dynamic or "none", line=line, column="zeta")
        if set(dynamic) == {"k_n_per_m", "m_kg"}:
            raise InputError("zeta or c_ns_per_m as well: k_n_per_m and m_kg fix fn, not damping", line=line, column="zeta")
        return columns

    def _build(self, columns: list[str], rows: list) -> ModalTable:
        orientation = "abc" if "a_deg" in columns else "beta"
        pose_numeric = list(POSITION_COLUMNS + ORIENTATION_COLUMNS[orientation])
        if "q1_deg" in columns:
            pose_numeric += list(JOINT_COLUMNS)
        std_columns = [c for c in STD_COLUMNS if c in columns]
        cross_columns = [c for c in CROSS_COLUMNS if c in columns]
        dynamic = [c for c in DYNAMIC_COLUMNS if c in columns]

        pose_ids: list[str] = []
        pose_values: dict[str, tuple] = {}
        pose_first_row: dict[str, int] = {}
        seen_keys: dict[tuple, int] = {}
        out = {k: [] for k in ("pose_index", "direction", "mode", "fn_hz", "zeta", "k_n_per_m")}
        std = {c: [] for c in std_columns}
        cross = {c: [] for c in cross_columns}
        source = []
        cross_rows: dict[tuple, tuple] = {}  # (pose_id, direction, mode) -> (where, the cross columns it fills, (fn, zeta, k, its own cross term))
        for number, line, cells in rows:
            at = dict(row=number, line=line)
            pose_id = cells["pose_id"]
            if not pose_id:
                raise InputError("a non-empty pose_id", got="", column="pose_id", **at)
            values = tuple(self._number(cells, c, at) for c in pose_numeric)
            if pose_id in pose_values:
                for c, mine, first in zip(pose_numeric, values, pose_values[pose_id]):
                    if mine != first:
                        raise InputError(
                            f"{first!r} as in row {pose_first_row[pose_id]} (same pose_id '{pose_id}')",
                            got=cells[c], column=c, **at,
                        )
            else:
                pose_values[pose_id] = values
                pose_first_row[pose_id] = number
                pose_ids.append(pose_id)
            direction = cells["direction"].lower()
            if direction not in DIRECTIONS:
                raise InputError("one of x, y, z", got=cells["direction"], column="direction", **at)
            mode = self._integer(cells, "mode", at)
            key = (pose_id, direction, mode)
            if key in seen_keys:
                raise InputError(
                    f"one row per pose_id, direction and mode (already in row {seen_keys[key]})",
                    got=f"{pose_id}/{direction}/{mode}", column="mode", **at,
                )
            seen_keys[key] = number
            fn = self._number(cells, "fn_hz", at)
            if not 0 < fn <= MAX_FN_HZ:
                raise InputError("a number > 0" if fn <= 0 else f"a number in (0, {MAX_FN_HZ:.0e}] Hz", got=cells["fn_hz"], column="fn_hz", **at)
            zeta, k = self._damping_and_stiffness(cells, dynamic, fn, at)
            out["pose_index"].append(pose_ids.index(pose_id))
            out["direction"].append(direction)
            out["mode"].append(mode)
            out["fn_hz"].append(fn)
            out["zeta"].append(zeta)
            out["k_n_per_m"].append(k)
            for c in std_columns:
                std[c].append(self._number(cells, c, at, allow_empty=True, minimum=0.0))
            for c in cross_columns:
                value = self._number(cells, c, at, allow_empty=True)
                if value == 0:
                    raise InputError("empty or a non-zero modal stiffness", got=cells[c], column=c, **at)
                cross[c].append(value)
            filled = {c for c in cross_columns if not math.isnan(cross[c][-1])}
            own_cross = next((cross[c][-1] for c in filled if _CROSS_ROWS[c][0] == direction), math.nan)
            cross_rows[(pose_id, direction, mode)] = (at, filled, (fn, zeta, k, own_cross))
            if "source" in columns:
                source.append(cells["source"])
        _check_cross_pairs(cross_rows)

        poses = PoseSet(
            pose_id=tuple(pose_ids),
            position_mm=np.array([pose_values[p][:3] for p in pose_ids]),
            orientation=orientation,
            orientation_deg=np.array([pose_values[p][3 : 3 + len(ORIENTATION_COLUMNS[orientation])] for p in pose_ids]),
            joints_deg=np.array([pose_values[p][-6:] for p in pose_ids]) if "q1_deg" in columns else None,
        )
        return ModalTable(poses=poses, std=std, source=tuple(source) if "source" in columns else None, cross=cross, **out)

    def _number(self, cells, column, at, allow_empty=False, minimum=None) -> float:
        text = cells[column]
        if text == "" and allow_empty:
            return math.nan
        try:
            value = float(text)
        except ValueError:
            raise InputError("a number", got=text, column=column, **at) from None
        if not math.isfinite(value):
            raise InputError("a finite number (no NaN or inf)", got=text, column=column, **at)
        if minimum is not None and value < minimum:
            raise InputError(f"a number >= {minimum:g}", got=text, column=column, **at)
        return value

    def _integer(self, cells, column, at) -> int:
        text = cells[column]
        try:
            value = int(text)
        except ValueError:
            raise InputError("an integer >= 1", got=text, column=column, **at) from None
        if value < 1:
            raise InputError("an integer >= 1", got=text, column=column, **at)
        return value

    def _damping_and_stiffness(self, cells, dynamic, fn_hz, at) -> tuple[float, float]:
        """zeta and k from any two of zeta, k, c, m (with wn = 2 pi fn):
        m = k / wn^2,  c = 2 zeta k / wn = 2 zeta m wn."""
        v = {c: self._number(cells, c, at) for c in dynamic}
        for c, value in v.items():
            if value <= 0:
                raise InputError("a number > 0", got=cells[c], column=c, **at)
        if "zeta" in v and not 0 < v["zeta"] < 1:
            raise InputError("a number in (0, 1)", got=cells["zeta"], column="zeta", **at)
        wn = 2.0 * math.pi * fn_hz
        if "k_n_per_m" in v:
            k = v["k_n_per_m"]
        elif "m_kg" in v:
            k = v["m_kg"] * wn**2
        else:  # zeta and c
            k = v["c_ns_per_m"] * wn / (2.0 * v["zeta"])
        if "zeta" in v:
            zeta = v["zeta"]
        elif "c_ns_per_m" in v:
            zeta = v["c_ns_per_m"] * wn / (2.0 * k)
        if not 0 < zeta < 1:
            used = ", ".join(["fn_hz"] + dynamic)
            raise InputError(f"damping ratio in (0, 1) derived from {used}", got=round(zeta, 6), column="c_ns_per_m", **at)
        derived = {"zeta": zeta, "k_n_per_m": k, "c_ns_per_m": 2.0 * zeta * k / wn, "m_kg": k / wn**2}
        for c, value in v.items():
            if abs(value - derived[c]) > CONSISTENCY_RTOL * abs(derived[c]):
                raise InputError(
                    f"{derived[c]:.6g} (within {CONSISTENCY_RTOL:.0%}, derived from the other columns)",
                    got=cells[c], column=c, **at,
                )
        return zeta, k


def read_pose_table(path: str | os.PathLike) -> PoseSet:
    """Poses from a CSV with the pose columns of the modal-table format (pose_id, x_mm, y_mm,
    z_mm, orientation, optional joints), one row per pose; a full modal table also works."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError("a readable file", got=exc.strerror, file=str(path)) from None
    return parse_pose_table(_decode(data, str(path)), str(path))


def read_tool_path(path: str | os.PathLike) -> tuple[PoseSet, np.ndarray]:
    """A timed tool path: the pose columns plus `time_s` (s, strictly increasing), one row per
    point; (poses, times)."""
    path = Path(path)
    try:
        text = _decode(path.read_bytes(), str(path))
    except OSError as exc:
        raise InputError("a readable file", got=exc.strerror, file=str(path)) from None
    rows = list(csv.reader(io.StringIO(text, newline="")))
    header = [c.strip() for c in rows[0]] if rows else []
    if "time_s" not in header:
        raise InputError("a time_s column (s) beside the pose columns", got=header[:8], file=str(path), line=1, column="time_s")
    j = header.index("time_s")
    times = []
    for line, cells in enumerate(rows[1:], 2):
        if not any(c.strip() for c in cells):  # blank lines are no rows (as in the other tables)
            continue
        r = len(times) + 1
        try:
            value = float(cells[j])
        except (ValueError, IndexError):
            raise InputError("a number of seconds", got=cells[j] if j < len(cells) else "nothing", file=str(path), row=r, line=line, column="time_s") from None
        if not np.isfinite(value) or (times and value <= times[-1]):
            raise InputError("finite times increasing from row to row", got=value, file=str(path), row=r, line=line, column="time_s")
        times.append(value)
    rest = "\n".join(",".join(_quote(c) for k, c in enumerate(cells) if k != j) for cells in rows if any(c.strip() for c in cells)) + "\n"
    return parse_pose_table(rest, str(path)), np.array(times)


def parse_pose_table(text: str, source: str) -> PoseSet:
    """`read_pose_table` on CSV text (`source` names it in errors)."""
    first = next(csv.reader(io.StringIO(text)), [])
    if "direction" in [c.strip() for c in first]:
        return parse_modal_table(text, source).poses
    pose_columns = ("pose_id",) + POSITION_COLUMNS + sum(ORIENTATION_COLUMNS.values(), ()) + JOINT_COLUMNS
    reader = csv.reader(io.StringIO(text, newline=""))
    header = [c.strip() for c in next(reader, [])]
    if not header:
        raise InputError("a header row with the pose columns", got="an empty file", file=source)
    for name in header:
        if name not in pose_columns:
            raise InputError("pose columns only (pose_id, x_mm, y_mm, z_mm, beta_deg or a/b/c_deg, q1..q6_deg)", got=name, file=source, line=1, column=name)
    # reuse the modal-table checks by giving every pose a placeholder mode row
    lines = [",".join(header + ["direction", "mode", "fn_hz", "zeta", "k_n_per_m"])]
    first_row: dict[str, int] = {}
    for line_number, cells in enumerate(reader, 2):
        if any(c.strip() for c in cells):
            if len(cells) != len(header):  # here: the placeholder mode's five fields would be counted too
                raise InputError(f"{len(header)} fields like the header", got=len(cells), file=source, row=len(lines), line=line_number)
            pose_id = cells[header.index("pose_id")].strip() if "pose_id" in header and len(cells) > header.index("pose_id") else None
            if pose_id in first_row:  # (the placeholder mode below would name it 'P5/x/1')
                raise InputError(f"one row per pose_id (already in row {first_row[pose_id]})", got=pose_id, file=source, row=len(lines), line=line_number, column="pose_id")
            if pose_id is not None:
                first_row[pose_id] = len(lines)
            lines.append(",".join(_quote(c) for c in cells) + ",x,1,1,0.5,1")
    return parse_modal_table("\n".join(lines) + "\n", source).poses


def _quote(cell: str) -> str:
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="").writerow([cell])
    return buffer.getvalue()


def concat_tables(tables: list[ModalTable]) -> ModalTable:
    """Several modal tables as one (distinct pose_ids, one orientation scheme)."""
    if len(tables) == 1:
        return tables[0]
    schemes = {t.poses.orientation for t in tables}
    if len(schemes) > 1:
        raise InputError("tables with the same orientation columns", got=sorted(schemes), column="beta_deg")
    joints = all(t.poses.joints_deg is not None for t in tables)
    ids = [i for t in tables for i in t.poses.pose_id]
    if len(set(ids)) != len(ids):
        raise InputError("distinct pose_id values across the files", got=sorted({i for i in ids if ids.count(i) > 1})[:3], column="pose_id")
    poses = PoseSet(
        pose_id=tuple(ids),
        position_mm=np.vstack([t.poses.position_mm for t in tables]),
        orientation=tables[0].poses.orientation,
        orientation_deg=np.vstack([t.poses.orientation_deg for t in tables]),
        joints_deg=np.vstack([t.poses.joints_deg for t in tables]) if joints else None,
    )
    offsets = np.cumsum([0] + [len(t.poses) for t in tables])
    std_keys = set.intersection(*(set(t.std) for t in tables))
    return ModalTable(
        poses=poses,
        pose_index=np.concatenate([t.pose_index + o for t, o in zip(tables, offsets)]),
        direction=np.concatenate([t.direction for t in tables]),
        mode=np.concatenate([t.mode for t in tables]),
        fn_hz=np.concatenate([t.fn_hz for t in tables]),
        zeta=np.concatenate([t.zeta for t in tables]),
        k_n_per_m=np.concatenate([t.k_n_per_m for t in tables]),
        std={k: np.concatenate([t.std[k] for t in tables]) for k in std_keys},
        source=tuple(s for t in tables for s in (t.source or ("",) * len(t))),
    )
