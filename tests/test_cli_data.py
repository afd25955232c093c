"""`posedyn data check` and `posedyn data summary`, run as a user would (a subprocess)."""

import json
from tests.cli_helpers import run_cli


def posedyn(*args):
    return run_cli(*args)


def test_data_check_json_on_a_valid_file(datasets):
    result = posedyn("data", "check", datasets / "seeds/swan_spindle_robot.csv", "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout) == {"rows": 37, "poses": 1, "directions": ["x", "y"], "modes": {"x": 20, "y": 17}}


def test_data_check_human_output(datasets):
    result = posedyn("data", "check", datasets / "seeds/hou2023_positions.csv")
    assert result.returncode == 0 and "valid modal-test table" in result.stdout and "18.12" in result.stdout


def test_data_check_on_a_broken_file_exits_2_with_the_location(tmp_path, datasets):
    text = (datasets / "seeds/hou2023_positions.csv").read_text().splitlines()
    text[3] = text[3].replace("18.125", "fast")
    broken = tmp_path / "broken.csv"
    broken.write_text("\n".join(text) + "\n")
    result = posedyn("data", "check", broken, "--json")
    assert result.returncode == 2
    assert result.stdout == ""
    assert "Traceback" not in result.stderr
    assert result.stderr.strip() == f"error: {broken}, row 3 (line 4), column 'fn_hz': expected a number, got 'fast'"


def test_data_check_on_a_missing_file_exits_2(tmp_path):
    result = posedyn("data", "check", tmp_path / "absent.csv")
    assert result.returncode == 2 and "Traceback" not in result.stderr and "absent.csv" in result.stderr


def test_data_summary_covers_every_shipped_file(datasets):
    result = posedyn("data", "summary", datasets, "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    shipped = sorted(str(p) for p in datasets.rglob("*") if p.suffix in (".csv", ".toml"))
    assert sorted(item["file"] for item in report) == shipped
    kinds = {item["kind"] for item in report}
    assert {"modal_table", "mrf_absorber", "host_and_cut", "active_damping", "measurement_campaign"} <= kinds
    walls = next(item for item in report if item["file"].endswith("sle_walls.csv"))
    assert walls["quantities"] == {"sle_um": 32} and walls["poses"] == 2


def test_version_and_module_entry_point():
    result = posedyn("--version")
    assert result.returncode == 0 and result.stdout.startswith("posedyn ")
