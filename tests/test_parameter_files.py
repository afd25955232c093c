"""Parameter files (TOML) and the other inputs a new user tried (2026-12-06): every bad value is
refused with its file and key, never read as something else."""

from __future__ import annotations

import pytest

from posedyn.errors import InputError
from posedyn.io.atomic import write_text_atomic
from posedyn.io.cut import read_cut, read_sle_cut
from posedyn.io.grid import read_grid
from posedyn.io.modal_csv import read_pose_table, read_tool_path
from posedyn.io.shipped import DATASETS
from posedyn.io.tool_file import read_tool
from absorber.files import read_absorber, read_actuator, read_host

CUT = DATASETS / "cuts/sweep_demo_cut.toml"


def with_line(source, key: str, line: str, tmp_path):
    """The file `source` with its `key = ...` line replaced by `line`."""
    lines = source.read_text().splitlines()
    assert any(l.startswith(f"{key} =") for l in lines), key
    path = tmp_path / source.name
    path.write_text("\n".join(line if l.startswith(f"{key} =") else l for l in lines) + "\n")
    return path


@pytest.mark.parametrize("line, key", [("kt_mpa = true", "cut.kt_mpa"), ('kt_mpa = "796"', "cut.kt_mpa"), ("radial_immersion = true", "cut.radial_immersion"),
                                       ('rpm = "fast"', "cut.rpm"), ("rpm = nan", "cut.rpm")])
def test_a_cut_value_that_is_no_number_is_refused_by_its_key(line, key, tmp_path):
    """kt_mpa = true was read as 1 MPa (a critical depth of 22.28 mm instead of 0.99 mm), a quoted
    number as the number, and 'fast' named no key."""
    path = with_line(CUT, line.split(" =")[0], line, tmp_path)
    with pytest.raises(InputError) as info:
        read_cut(path)
    assert info.value.column == key and info.value.file == str(path)


def test_the_file_kind_is_checked(tmp_path):
    """A pose grid given as a cut file, or a cut as a grid, was read for whatever it had."""
    cut = with_line(CUT, "kind", 'kind = "pose_grid"', tmp_path)
    with pytest.raises(InputError) as info:
        read_cut(cut)
    assert info.value.column == "meta.kind" and "cut" in info.value.expected
    grid = with_line(DATASETS / "campaigns/seed003_grid.toml", "kind", 'kind = "cut"', tmp_path)
    with pytest.raises(InputError) as info:
        read_grid(grid)
    assert info.value.column == "meta.kind"


@pytest.mark.parametrize("reader, source, key, line", [
    (read_tool, "seeds/seed003_reference_tool.toml", "tool.density_kg_m3", "density_kg_m3 = true"),
    (read_absorber, "seeds/hou2023_mrf_absorber.toml", "absorber.mass_kg", "mass_kg = true"),
    (read_host, "seeds/dogan2024_host_milling.toml", "host.fn_hz", 'fn_hz = "40"'),
    (read_actuator, "seeds/sahu2024_active_damping.toml", "actuator.force_limit_n", "force_limit_n = true"),
])
def test_the_other_parameter_files_refuse_booleans_and_quoted_numbers(reader, source, key, line, tmp_path):
    path = with_line(DATASETS / source, line.split(" =")[0], line, tmp_path)
    with pytest.raises(InputError) as info:
        reader(path)
    assert info.value.column == key and info.value.file == str(path)


def test_the_shipped_parameter_files_still_read():
    read_cut(CUT), read_sle_cut(CUT), read_tool(DATASETS / "seeds/seed003_reference_tool.toml")
    read_absorber(DATASETS / "seeds/hou2023_mrf_absorber.toml"), read_host(DATASETS / "seeds/dogan2024_host_milling.toml")
    read_actuator(DATASETS / "seeds/sahu2024_active_damping.toml"), read_grid(DATASETS / "campaigns/seed003_grid.toml")


def test_a_pose_row_with_missing_fields_counts_the_file_s_own_fields(tmp_path):
    """It said 'expected 10 fields like the header, got 9' for 5 and 4 (the placeholder mode's
    five were counted)."""
    path = tmp_path / "poses.csv"
    path.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nP1,1500,0,600,0\nP2,1500,0,600\n")
    with pytest.raises(InputError) as info:
        read_pose_table(path)
    assert (info.value.row, info.value.line, info.value.got) == (2, 3, 4) and info.value.expected.startswith("5 fields")


def test_a_blank_line_in_a_tool_path_is_no_row(tmp_path):
    path = tmp_path / "path.csv"
    path.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg,time_s\nP1,1500,0,600,0,0\n\nP2,1500,0,600,0,x\n")
    with pytest.raises(InputError) as info:
        read_tool_path(path)
    assert (info.value.row, info.value.line, info.value.column) == (2, 4, "time_s")


def test_a_write_that_fails_names_the_path_asked_for(tmp_path):
    """It named the temporary file ('.x.csv.uu6g69x8.tmp') the user never gave."""
    target = tmp_path / "no_such_folder" / "x.csv"
    with pytest.raises(OSError) as info:
        write_text_atomic(target, "a")
    assert info.value.filename == str(target) and "cannot write" in str(info.value)
    assert not any(tmp_path.rglob("*.tmp"))
