"""Active damping with an inertial actuator (seed 000) and its per-pose schedule."""

import json
import math

import pytest

from absorber.active_damping import DVF, Actuator, ControlConfig, actuator_angle_to_gravity, gain_schedule, residue_frf
from posedyn.io import read_modal_table, read_params
from posedyn.robot import rotation_from_beta
from tests.cli_helpers import run_cli


@pytest.fixture(scope="module")
def seed000(datasets):
    p = read_params(datasets / "seeds/sahu2024_active_damping.toml")

    def frf(name):
        return residue_frf([(m["fn_hz"], m["zeta"], m["sigma_re_m_per_n"], m["sigma_im_m_per_n"]) for m in p["frf"][name]])

    # H21yy (~ H12yy ~ H22yy) is tabulated with the opposite sign of a direct receptance
    # (negative imaginary part at resonance); as the collocated H22 it must be passive.
    return frf("h11yy"), -frf("h21yy")


def test_residue_form_gives_passive_direct_receptances(seed000):
    h11, h22 = seed000
    for h in (h11, h22):
        assert h(1j * 2 * math.pi * 9.2).imag < 0


def test_interpolation_law_hits_both_measured_mountings():
    a = Actuator()
    assert a.fn_hz(math.pi / 2) == pytest.approx(9.0) and a.fn_hz(0.0) == pytest.approx(14.0) and a.fn_hz(math.pi) == pytest.approx(14.0)
    assert 9.0 < a.fn_hz(math.radians(45)) < 14.0


def test_seed000_reproduction_horizontal_and_vertical_with_c1(seed000, capsys):
    """Seed 000 Fig. 10a / Tables 3-4: with C1 the closed loop at the actuator location is stable
    up to a finite gain, and K = 2000 Ns/m improves the 9.2 Hz mode's dynamic stiffness of the
    order of 100 % (the seed measures ~100 % horizontal, 107 % vertical). The linear model gives
    about 220 %: the seed's improvement saturates at the 36 N actuator limit and was measured with
    the robot drives on; the vertical case runs here on the same y-direction FRFs (the seed's
    vertical test is in z at another pose, whose FRFs it does not tabulate)."""
    h11, h22 = seed000
    report = {}
    for name, fn_act in (("horizontal", 9.0), ("vertical", 14.0)):
        loop = DVF(h11, h22, h22, Actuator(), fn_act)
        k_max = loop.max_stable_gain()
        improvement = loop.stiffness_improvement_pct(2000.0, 9.2)
        report[name] = (k_max, improvement)
        assert 2000 < k_max < 1e5 and loop.stable(2000.0)
        assert 50 < improvement < 400
        assert loop.stiffness_improvement_pct(2000.0, 9.2, where="11") > 50  # at the tool tip too
    print("max stable gain (Ns/m), improvement at K=2000 (%):", report)


def test_a_schedule_for_the_other_orientation_loses_its_margin(seed000):
    """Seed 000's finding that the mounting orientation matters: gains scheduled with the
    actuator vertical (14 Hz, C1 designed for 14 Hz) applied where it hangs horizontally (9 Hz)
    leave the compensator mistuned and the loop without its 6 dB margin."""
    h11, h22 = seed000
    vertical = gain_schedule(DVF(h11, h22, h22, Actuator(), 14.0), 9.2, 10.0)
    assert vertical["gain_margin_db"] >= 6.0
    misplaced = DVF(h11, h22, h22, Actuator(), 9.0, fn_compensator_hz=14.0)
    k_max = misplaced.max_stable_gain()
    assert 20 * math.log10(k_max / vertical["dvf_gain_ns_per_m"]) < 6.0
    assert not misplaced.stable(vertical["dvf_gain_ns_per_m"])


def test_actuator_axis_angle_from_the_pose():
    R = rotation_from_beta(0.3)
    assert actuator_angle_to_gravity(R, "x") == pytest.approx(0.0, abs=1e-12)  # the tool axis is vertical
    assert actuator_angle_to_gravity(R, "y") == pytest.approx(math.pi / 2)


def test_schedule_respects_the_force_limit_on_every_pose_of_the_campaign(datasets):
    from absorber.active_damping import control_entries

    table = read_modal_table(datasets / "campaigns/seed003_twin_s1.csv")
    entries = control_entries(table, ControlConfig())
    assert len(entries) == 112
    for e in entries:
        assert e["max_force_n"] <= e["force_limit_n"] and e["gain_margin_db"] >= 6.0 - 1e-9
        assert e["dvf_gain_ns_per_m"] > 0 and e["dynamic_stiffness_gain_pct"] > 0


def test_control_schedule_cli(datasets, tmp_path):
    poses = tmp_path / "p.csv"
    poses.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nP5,1400,0,800,0\n")
    result = run_cli("control", "schedule", "--modes", datasets / "seeds/hou2023_positions.csv", "--poses", poses,
                     "--actuator", datasets / "seeds/sahu2024_active_damping.toml", "--json")
    assert result.returncode == 0, result.stderr
    entry = json.loads(result.stdout)[0]
    assert {"pose_id", "actuator_fn_hz", "dvf_gain_ns_per_m", "gain_margin_db", "dynamic_stiffness_gain_pct", "max_force_n", "virtual_absorber"} <= set(entry)
    assert entry["actuator_fn_hz"] == pytest.approx(9.0)
    assert entry["virtual_absorber"]["layout"] == "idva-c3" and entry["virtual_absorber"]["force_ok"]


@pytest.mark.parametrize("line, column, expected", [
    ('mount_axis = "diagonal"', "control.mount_axis", "one of x, y, z"),
    ("disturbance_n = nan", "control.disturbance_n", "a finite number"),
    ("margin_db = -6", "control.margin_db", "a number >= 0"),
    ('virtual_layout = "tmdd"', "control.virtual_layout", "one of tmd"),
    ("gain = 3", "control.gain", "a [control] key among"),
])
def test_a_bad_actuator_file_is_named_not_a_traceback_or_a_silent_default(datasets, tmp_path, line, column, expected):
    """A new user's `mount_axis = "diagonal"` ended in `ValueError: substring not found` (and a
    service that answered every query `internal`); NaN, a negative margin and a misspelt key
    were taken (gain 0 with margin inf, or the default)."""
    from absorber.files import read_actuator
    from posedyn.errors import InputError

    bad = tmp_path / "actuator.toml"
    bad.write_text((datasets / "seeds/sahu2024_active_damping.toml").read_text() + f"\n[control]\n{line}\n")
    with pytest.raises(InputError) as err:
        read_actuator(bad)
    assert err.value.file == str(bad) and err.value.column == column and err.value.expected.startswith(expected)
    poses = tmp_path / "p5.csv"
    poses.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nP5,1400,0,800,0\n")
    done = run_cli("control", "schedule", "--modes", datasets / "seeds/hou2023_positions.csv", "--poses", poses, "--actuator", bad)
    assert done.returncode == 2 and done.stderr.startswith(f"error: {bad}, column '{column}'") and done.stdout == ""
    negative_delay = tmp_path / "delay.toml"
    negative_delay.write_text((datasets / "seeds/sahu2024_active_damping.toml").read_text().replace("delay_ms = 0.6", "delay_ms = -0.6"))
    with pytest.raises(InputError, match="delay_ms"):
        read_actuator(negative_delay)


def test_a_service_with_a_bad_settings_file_does_not_start(model_dir, datasets, tmp_path):
    """The service reads its cut, absorber, actuator, twin and tool files before it starts (the
    workers build their engines later): a bad one is the start's error, not every query's."""
    pytest.importorskip("zenoh")
    from posedyn.errors import InputError
    from service.zenoh_service.server import ScheduleService, ServiceSettings
    from service.zenoh_service.session import zenoh_config
    from service.zenoh_service.workers import EngineSpec

    bad = tmp_path / "actuator.toml"
    bad.write_text((datasets / "seeds/sahu2024_active_damping.toml").read_text() + '\n[control]\nmount_axis = "diagonal"\n')
    spec = EngineSpec(model_dir, datasets / "seeds/hou2023_cut.toml", actuator=bad)
    from tests.zenoh_helpers import free_port

    service = ScheduleService(spec, ServiceSettings("refused"), zenoh_config(None, "peer", [f"tcp/127.0.0.1:{free_port()}"]), tmp_path / "state")
    try:
        with pytest.raises(InputError, match="mount_axis"):
            service.start()
        assert service.session is None
    finally:
        service.close()
