"""Loader and writer of the modal-test table: derivations, exact round trip, every bad input."""

import math

import numpy as np
import pytest

from posedyn.errors import InputError
from posedyn.io import format_modal_table, parse_modal_table, read_modal_table, write_modal_table
from posedyn.table import ModalTable, Mode, PoseSet

HEADER = "pose_id,x_mm,y_mm,z_mm,beta_deg,direction,mode,fn_hz,zeta,k_n_per_m"
GOOD = [
    "A,100,200,300,0,x,1,20.0,0.03,1e6",
    "A,100,200,300,0,y,1,22.0,0.04,2e6",
    "B,300,200,300,30,x,1,25.0,0.05,3e6",
]


CROSS = ",k_xy_n_per_m,k_yx_n_per_m"


def csv_text(header=HEADER, rows=GOOD):
    return "\n".join([header] + rows) + "\n"


def parse(text):
    return parse_modal_table(text.encode("utf-8") if isinstance(text, str) else text, name="t.csv")


def test_good_table_parses_into_canonical_arrays():
    table = parse(csv_text())
    assert len(table) == 3 and table.poses.pose_id == ("A", "B")
    assert table.summary()["modes"] == {"x": 1, "y": 1}
    assert table.modes("A", "y") == (Mode(22.0, 0.04, 2e6),)
    assert table.poses.position_m[1].tolist() == [0.3, 0.2, 0.3]


@pytest.mark.parametrize("given", ["zeta,m_kg", "zeta,c_ns_per_m", "k_n_per_m,c_ns_per_m", "c_ns_per_m,m_kg"])
def test_any_two_dynamic_parameters_give_the_same_mode(given):
    """m = k / wn^2 and c = 2 zeta sqrt(k m): every admissible pair gives back zeta and k."""
    fn, zeta, k = 18.5375, 0.0281, 586000.0
    wn = 2 * math.pi * fn
    value = {"zeta": zeta, "k_n_per_m": k, "m_kg": k / wn**2, "c_ns_per_m": 2 * zeta * math.sqrt(k * k / wn**2)}
    a, b = given.split(",")
    text = f"pose_id,x_mm,y_mm,z_mm,beta_deg,direction,mode,fn_hz,{a},{b}\nP,0,0,0,0,x,1,{fn!r},{value[a]!r},{value[b]!r}\n"
    mode = parse(text).modes("P", "x")[0]
    assert mode.zeta == pytest.approx(zeta, rel=1e-12)
    assert mode.k_n_per_m == pytest.approx(k, rel=1e-12)


def test_redundant_columns_must_agree():
    text = "pose_id,x_mm,y_mm,z_mm,beta_deg,direction,mode,fn_hz,zeta,k_n_per_m,m_kg\nP,0,0,0,0,x,1,10,0.05,1000,2.5\n"
    with pytest.raises(InputError, match=r"row 1 \(line 2\), column 'm_kg'"):
        parse(text)


def random_table(rng, orientation="abc", joints=True, std=True, source=True) -> ModalTable:
    n_poses, n_modes = 5, 3
    width = 3 if orientation == "abc" else 1
    poses = PoseSet(
        pose_id=tuple(f"pose {i}" for i in range(n_poses)),
        position_mm=rng.uniform(-2000, 2000, (n_poses, 3)),
        orientation=orientation,
        orientation_deg=rng.uniform(-180, 180, (n_poses, width)),
        joints_deg=rng.uniform(-170, 170, (n_poses, 6)) if joints else None,
    )
    keys = [(p, d, m) for p in range(n_poses) for d in "xyz" for m in range(1, n_modes + 1)]
    n = len(keys)
    stds = {}
    if std:
        stds = {c: rng.uniform(0, 1, n) for c in ("std_fn_hz", "std_zeta", "std_k_n_per_m")}
        stds["std_zeta"][::4] = np.nan  # empty cells allowed
    return ModalTable(
        poses=poses,
        pose_index=[k[0] for k in keys],
        direction=[k[1] for k in keys],
        mode=[k[2] for k in keys],
        fn_hz=rng.uniform(1, 5000, n),
        zeta=rng.uniform(1e-4, 0.5, n),
        k_n_per_m=10 ** rng.uniform(4, 9, n),
        std=stds,
        source=tuple(f'test, "quoted" é {i}' for i in range(n)) if source else None,
    )


@pytest.mark.parametrize("orientation, joints, std, source", [("abc", True, True, True), ("beta", False, False, False)])
def test_writer_round_trips_exactly(tmp_path, orientation, joints, std, source):
    table = random_table(np.random.default_rng(7), orientation, joints, std, source)
    path = tmp_path / "table.csv"
    write_modal_table(table, path)
    again = read_modal_table(path)
    assert again == table
    assert format_modal_table(again) == path.read_text(encoding="utf-8")
    assert not list(tmp_path.glob(".*.tmp"))


def test_round_trip_of_a_shipped_table_keeps_every_bit(datasets, tmp_path):
    table = read_modal_table(datasets / "seeds/hou2023_positions.csv")
    write_modal_table(table, tmp_path / "copy.csv")
    again = read_modal_table(tmp_path / "copy.csv")
    assert again == table
    assert np.array_equal(again.c_ns_per_m, table.c_ns_per_m)


def test_tables_that_differ_are_not_equal():
    a = parse(csv_text())
    b = parse(csv_text(rows=GOOD[:2] + ["B,300,200,300,30,x,1,25.0,0.05,3.000001e6"]))
    assert a != b


def replace(row_index, column, value, rows=GOOD, header=HEADER):
    columns = header.split(",")
    rows = list(rows)
    cells = rows[row_index].split(",")
    cells[columns.index(column)] = value
    rows[row_index] = ",".join(cells)
    return csv_text(header, rows)


#: One coupled rank-one mode: k_yy = k_xy k_yx / k_xx = (-4e6)(-5e5) / 1e6 = 2e6.
COUPLED = ["A,100,200,300,0,x,1,20.0,0.03,1e6,-4e6,", "A,100,200,300,0,y,1,{fn_hz},{zeta},{k_n_per_m},,{k_yx}"]


def coupled(fn_hz="20.5", zeta="0.035", k_n_per_m="2.2e6", k_yx="-5e5"):
    return csv_text(HEADER + CROSS, [COUPLED[0], COUPLED[1].format(fn_hz=fn_hz, zeta=zeta, k_n_per_m=k_n_per_m, k_yx=k_yx)])


def test_a_coupled_mode_within_the_tolerances_is_read_as_one_mode():
    table = parse(coupled())
    assert table.cross["k_yx_n_per_m"][1] == -5e5 and table.fn_hz[1] == 20.5


# Each bad input: (text, row, line, column, words expected in the message).
BAD_CELLS = {
    "non-numeric cell": (replace(1, "fn_hz", "twenty"), 2, "fn_hz", "expected a number"),
    "nan": (replace(2, "zeta", "nan"), 3, "zeta", "finite"),
    "inf": (replace(0, "x_mm", "inf"), 1, "x_mm", "finite"),
    "fn zero": (replace(1, "fn_hz", "0"), 2, "fn_hz", "> 0"),
    "fn negative": (replace(1, "fn_hz", "-3"), 2, "fn_hz", "> 0"),
    "k zero": (replace(2, "k_n_per_m", "0"), 3, "k_n_per_m", "> 0"),
    "fn beyond any machine": (replace(1, "fn_hz", "1e308"), 2, "fn_hz", "(0, 1e+06] Hz"),  # (reached the shapes as 1 / 0: a RuntimeWarning and no row)
    "zeta one": (replace(0, "zeta", "1"), 1, "zeta", "(0, 1)"),
    "zeta above one": (replace(0, "zeta", "1.3"), 1, "zeta", "(0, 1)"),
    "zeta zero": (replace(0, "zeta", "0"), 1, "zeta", "> 0"),
    "bad direction": (replace(1, "direction", "w"), 2, "direction", "x, y, z"),
    "mode not integer": (replace(1, "mode", "1.5"), 2, "mode", "integer"),
    "mode zero": (replace(1, "mode", "0"), 2, "mode", "integer >= 1"),
    "duplicate pose/direction/mode": (csv_text(rows=GOOD + [GOOD[1]]), 4, "mode", "already in row 2"),
    "inconsistent pose": (csv_text(rows=GOOD + ["A,100,201,300,0,z,1,30,0.03,1e6"]), 4, "y_mm", "as in row 1"),
    "inconsistent orientation": (csv_text(rows=GOOD + ["B,300,200,300,31,y,1,30,0.03,1e6"]), 4, "beta_deg", "as in row 3"),
    "empty pose_id": (replace(0, "pose_id", ""), 1, "pose_id", "non-empty"),
    "ragged row": (csv_text(rows=GOOD[:1] + ["A,100,200"]), 2, None, "fields"),
    # a cross term alone would be dropped (the mode read as uncoupled): the independent check's
    # tables were accepted that way without a word
    "cross term on one row only": (csv_text(HEADER + CROSS, [GOOD[0] + ",-4e6,", GOOD[1] + ",,", GOOD[2] + ",,"]), 1, "k_xy_n_per_m",
                                   "k_yx_n_per_m on the y row of pose 'A', mode 1 as well"),
    "cross term without its row": (csv_text(HEADER + CROSS, [GOOD[0] + ",,", GOOD[1] + ",,", GOOD[2] + ",5e6,"]), 3, "k_xy_n_per_m",
                                   "k_yx_n_per_m on the y row of pose 'B', mode 1 as well"),
    "cross term on the other direction's row": (csv_text(HEADER + CROSS, [GOOD[0] + ",-4e6,", GOOD[1] + ",-3e6,-5e6", GOOD[2] + ",,"]), 2,
                                                "k_xy_n_per_m", "k_xy_n_per_m on x rows only"),
    # the two rows of a coupled mode are one rank-one mode (fn and zeta averaged, k_yy derived):
    # rows further apart than that would be read silently wrong
    "coupled rows' fn apart": (coupled(fn_hz="22.0"), 2, "fn_hz", "fn_hz within 5% of 20.0 (row 1, the x row of the same coupled mode"),
    "coupled rows' zeta apart": (coupled(zeta="0.07"), 2, "zeta", "zeta within a factor 2 of 0.03"),
    "coupled y stiffness not rank one": (coupled(k_n_per_m="5e6"), 2, "k_n_per_m", "within a factor 2 of k_xy k_yx / k_xx = 2e+06"),
    "coupled cross terms of opposite signs": (coupled(k_yx="5e5"), 2, "k_yx_n_per_m", "k_yx_n_per_m of the sign of k_xy_n_per_m"),
}


@pytest.mark.parametrize("case", sorted(BAD_CELLS))
def test_bad_cell_names_file_row_line_and_column(case):
    text, row, column, words = BAD_CELLS[case]
    with pytest.raises(InputError) as info:
        parse(text)
    error = info.value
    assert (error.file, error.row, error.line, error.column) == ("t.csv", row, row + 1, column)
    message = str(error)
    assert message.startswith(f"t.csv, row {row} (line {row + 1})")
    if column:
        assert f"column '{column}'" in message
    assert words in message


BAD_HEADERS = {
    "missing column": (HEADER.replace(",fn_hz", ""), "fn_hz", "required column"),
    "unknown column": (HEADER + ",colour", "colour", "known column"),
    "column twice": (HEADER + ",zeta", "zeta", "each column once"),
    "no orientation": (HEADER.replace(",beta_deg", ""), "beta_deg", "orientation"),
    "both orientations": (HEADER + ",a_deg,b_deg,c_deg", "beta_deg", "not both"),
    "partial abc": (HEADER.replace("beta_deg", "a_deg,b_deg"), "c_deg", "all of a_deg"),
    "partial joints": (HEADER + ",q1_deg,q2_deg", "q3_deg", "all six"),
    "one dynamic column": (HEADER.replace(",zeta", ""), "zeta", "two of"),
    "k and m only": (HEADER.replace(",zeta", ",m_kg"), "zeta", "fix fn, not damping"),
}


@pytest.mark.parametrize("case", sorted(BAD_HEADERS))
def test_bad_header_names_file_line_and_column(case):
    header, column, words = BAD_HEADERS[case]
    with pytest.raises(InputError) as info:
        parse(header + "\n")
    assert (info.value.file, info.value.line, info.value.column) == ("t.csv", 1, column)
    assert words in str(info.value) and f"column '{column}'" in str(info.value)


def test_empty_file_and_header_only_are_refused():
    with pytest.raises(InputError, match=r"^t\.csv: expected a header row.*got 'an empty file'"):
        parse(b"")
    with pytest.raises(InputError, match=r"^t\.csv: expected a header row"):
        parse(b"\n\n")
    with pytest.raises(InputError, match=r"^t\.csv, line 1: expected at least one data row"):
        parse(HEADER + "\n")


def test_not_utf8_names_row_line_and_column():
    data = csv_text().encode("utf-8").replace(b"B,300", b"B\xff,300")
    with pytest.raises(InputError) as info:
        parse(data)
    assert (info.value.row, info.value.line, info.value.column) == (3, 4, "pose_id")
    assert "UTF-8" in str(info.value) and "0xff" in str(info.value)


def test_a_byte_order_mark_is_accepted():
    assert parse(b"\xef\xbb\xbf" + csv_text().encode()) == parse(csv_text())


def test_missing_file_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="readable file"):
        read_modal_table(tmp_path / "nope.csv")


def test_mode_validates_its_own_fields():
    with pytest.raises(InputError, match="zeta"):
        Mode(10.0, 1.2, 1e6)
    mode = Mode(10.0, 0.05, 1e6)
    assert mode.m_kg == pytest.approx(1e6 / (2 * math.pi * 10) ** 2)
    # receptance at resonance: 1 / (2 i zeta k)
    assert mode.receptance(mode.wn_rad_s) == pytest.approx(1 / (2j * 0.05 * 1e6))


def test_a_pose_list_with_a_pose_twice_names_the_pose_not_a_mode(tmp_path):
    """A pose list has no direction or mode column: its duplicate is named by pose_id and row
    (it read 'got P5/x/1', the placeholder mode the pose reader adds)."""
    from posedyn.io import read_pose_table

    path = tmp_path / "poses.csv"
    path.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nP5,1400,0,800,0\nP5,1400,0,800,0\n")
    with pytest.raises(InputError) as info:
        read_pose_table(path)
    assert str(info.value) == f"{path}, row 2 (line 3), column 'pose_id': expected one row per pose_id (already in row 1), got 'P5'"
