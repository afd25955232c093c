"""`posedyn data check` and `posedyn data summary`, run as a user would (a subprocess)."""

import json
from tests.cli_helpers import run_cli


def posedyn(*args):
    return run_cli(*args)


def test_data_check_json_on_a_valid_file(datasets):
    result = posedyn("data", "check", datasets / "seeds/swan_spindle_robot.csv", "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout) == {"rows": 37, "poses": 1, "directions": ["x", "y"], "modes": {"x": 20, "y": 17}, "warnings": []}


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


def test_data_summary_checks_every_file_and_names_each_bad_one(tmp_path, datasets):
    """One bad file does not hide the next: every file is checked, each bad one is named on stderr
    (file, row, column), the good ones are still summarised, and the exit code is 2."""
    good = (datasets / "seeds/hou2023_positions.csv").read_text().splitlines()
    (tmp_path / "a_good.csv").write_text("\n".join(good) + "\n")
    broken = list(good)
    broken[2] = broken[2].replace("18.125", "fast")
    (tmp_path / "b_broken.csv").write_text("\n".join(broken) + "\n")
    (tmp_path / "c_no_meta.toml").write_text("[cut]\nteeth = 3\n")
    (tmp_path / "d_latin1.csv").write_bytes("pose_id,direction\nP\xe9,x\n".encode("latin-1"))
    (tmp_path / "e_folder.csv").mkdir()  # a folder named like a table is no file (it stopped the walk)
    result = posedyn("data", "summary", tmp_path, "--json")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    report = {item["file"]: item for item in json.loads(result.stdout)}
    assert report[str(tmp_path / "a_good.csv")]["kind"] == "modal_table"
    assert [item["kind"] for item in report.values()] == ["modal_table", "invalid", "invalid", "invalid"]
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 3 and all(line.startswith("error: ") for line in lines)
    assert lines[0].startswith(f"error: {tmp_path / 'b_broken.csv'}, row 2 (line 3), column 'fn_hz'")
    assert str(tmp_path / "c_no_meta.toml") in lines[1] and str(tmp_path / "d_latin1.csv") in lines[2]
    text = posedyn("data", "summary", tmp_path)
    assert text.returncode == 2 and "1 of 4 files" in text.stdout


def test_an_error_shows_numpy_numbers_as_the_user_wrote_them():
    import numpy as np

    from posedyn.errors import InputError

    message = str(InputError("std > 0", got=np.float64(-1.3), row=1, column="std"))
    assert message.endswith("expected std > 0, got -1.3")
    assert str(InputError("x", got=(np.str_("x"), np.int64(3)))).endswith("got ('x', 3)")


def test_flags_and_file_keys_are_named_as_the_user_wrote_them(tmp_path, datasets):
    """A bad flag value is named by its flag ('--host-fn-hz', not the library's 'fn_hz'); an
    actuator whose loop has no stable gain is named with its file; help text keeps the TOML
    section names ('[host]' vanished as rich markup); an absorber file's fluid density must be
    a density."""
    cut = ("--layout", "tmd", "--teeth", 2, "--kt-mpa", 600, "--kn-mpa", 200, "--radial-immersion", 1)
    host = {"--host-fn-hz": 100, "--host-zeta": 0.01, "--host-k-n-per-m": 1e7, "--mass-ratio": 0.05}
    for flag, bad in (("--host-fn-hz", -5), ("--host-zeta", -0.01), ("--host-k-n-per-m", "nan"), ("--mass-ratio", -1)):
        args = [x for k, v in {**host, flag: bad}.items() for x in (k, v)]
        result = posedyn("absorber", "tune", *args, *cut)
        assert result.returncode == 2 and result.stderr.startswith(f"error: option '{flag}'"), result.stderr
    assert posedyn("absorber", "field", "--target-hz", -3).stderr.startswith("error: option '--target-hz'")
    result = posedyn("twin", "campaign", "--grid", datasets / "campaigns/seed003_grid.toml", "--out", tmp_path / "c.csv", "--noise-fn-pct", -1)
    assert result.returncode == 2 and result.stderr.startswith("error: option '--noise-fn-pct'")
    result = posedyn("twin", "modes", "--x-mm", "nan", "--y-mm", 0, "--z-mm", 600, "--beta-deg", 0)
    assert result.returncode == 2 and result.stderr.startswith("error: option '--x-mm': expected a finite number")
    robust_help = posedyn("absorber", "robust", "--help").stdout
    assert "[host]," in robust_help and "[cut]" in robust_help  # (rich markup ate them; the help may wrap between the two)

    actuator = tmp_path / "slow_actuator.toml"
    actuator.write_text((datasets / "seeds/sahu2024_active_damping.toml").read_text().replace("delay_ms = 0.6", "delay_ms = 600"))
    poses = tmp_path / "p5.csv"
    poses.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nP5,1400,0,800,0\n")
    result = posedyn("control", "schedule", "--modes", datasets / "seeds/hou2023_positions.csv", "--poses", poses, "--actuator", actuator)
    assert result.returncode == 2 and result.stderr.startswith(f"error: {actuator}, column 'actuator'") and "delay_ms" in result.stderr

    absorber = tmp_path / "absorber.toml"
    absorber.write_text((datasets / "seeds/hou2023_mrf_absorber.toml").read_text().replace("density_kg_per_m3 = 2550.0", "density_kg_per_m3 = 0.0"))
    result = posedyn("absorber", "field", "--target-hz", 20, "--absorber", absorber)
    assert result.returncode == 2 and result.stderr.startswith(f"error: {absorber}, column 'mrf.density_kg_per_m3'")


def test_an_unknown_missing_or_malformed_option_is_one_error_line():
    """Click's own usage errors end as every bad input does (README, Command-line reference): one
    line on stderr starting `error:`, naming the command's help, exit status 2 (they were a
    multi-line usage box)."""
    for args, words in ((("chatter", "--rpm", "abc"), "Invalid value for '--rpm'"), (("chatter", "--nope"), "No such option: --nope"),
                        (("train",), "Missing argument"), (("nosuch",), "No such command 'nosuch'")):
        result = posedyn(*args)
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: ") and words in lines[0], result.stderr
        assert lines[0].endswith(f"(posedyn {args[0]} -h for help)" if args[0] != "nosuch" else "(posedyn -h for help)")


def test_a_stiffness_no_tool_tip_has_is_warned_about_where_a_table_is_read(tmp_path):
    """k = 1060 N/m (N/mm written as N/m) was accepted by `data check` and `chatter` without the
    warning `fit` gives (below 1e4 N/m): now both say it, on stderr (and in data check's JSON)."""
    table = tmp_path / "soft.csv"
    table.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg,direction,mode,fn_hz,zeta,k_n_per_m\nP,0,0,0,0,x,1,20,0.03,1060\nP,0,0,0,0,y,1,20,0.03,2e6\n")
    checked = posedyn("data", "check", table, "--json")
    assert checked.returncode == 0 and "x mode 1: k = 1.06e+03 N/m" in checked.stderr
    assert json.loads(checked.stdout)["warnings"] == [line[len("warning: "):] for line in checked.stderr.strip().splitlines()]
    chatter = posedyn("chatter", "--modes", table, "--rpm", 2000, "--teeth", 3, "--kt-mpa", 796, "--kn-mpa", 169, "--radial-immersion", 0.5, "--json")
    assert chatter.returncode == 0 and "x mode 1: k = 1.06e+03 N/m" in chatter.stderr and "y mode" not in chatter.stderr


def test_a_file_of_another_kind_given_as_the_modal_table_is_named_as_such(datasets):
    """A cut file given to `data check` was refused for its first comment line as a column name."""
    result = posedyn("data", "check", datasets / "seeds/hou2023_cut.toml")
    assert result.returncode == 2 and "expected a modal-test table (CSV" in result.stderr and "a .toml file (a cut" in result.stderr


def test_data_summary_checks_parameter_files_as_the_commands_that_read_them(tmp_path, datasets):
    """A cut file that `schedule --cut` refuses (0 teeth, a word for the speed, a missing
    coefficient) is invalid in the summary too, named as the command names it."""
    cut = (datasets / "cuts/sweep_demo_cut.toml").read_text()
    (tmp_path / "a_ok.toml").write_text(cut)
    (tmp_path / "b_teeth0.toml").write_text(cut.replace("teeth = 3", "teeth = 0"))
    (tmp_path / "c_rpm_word.toml").write_text(cut.replace("rpm = 2000.0", 'rpm = "fast"'))
    (tmp_path / "d_no_kt.toml").write_text(cut.replace("kt_mpa = 796.0\n", ""))
    result = posedyn("data", "summary", tmp_path, "--json")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert [item["kind"] for item in json.loads(result.stdout)] == ["cut", "invalid", "invalid", "invalid"]
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 3 and "'cut.teeth'" in lines[0] and str(tmp_path / "b_teeth0.toml") in lines[0]
    assert str(tmp_path / "c_rpm_word.toml") in lines[1] and str(tmp_path / "d_no_kt.toml") in lines[2]
