"""Shipped data against the seed tables (spot values transcribed independently here)."""

import math

import pytest

from posedyn.io import read_modal_table, read_params


def _row(table, pose_id, direction, mode):
    return table.modes(pose_id, direction)[mode - 1]


@pytest.mark.parametrize(
    "position, fn_hz, k_mn_per_m, c_ns_per_m",
    [(1, 18.125, 0.452, 264.56), (3, 18.5375, 0.586, 341.27), (5, 19.0625, 1.06, 725.11), (7, 19.375, 2.37, 940.34)],
)
def test_hou2023_positions_reproduce_seed004_table1(datasets, position, fn_hz, k_mn_per_m, c_ns_per_m):
    table = read_modal_table(datasets / "seeds/hou2023_positions.csv")
    for direction in ("x", "y"):  # same mode for x and y, as the dataset README says
        mode = _row(table, f"P{position}", direction, 1)
        assert mode.fn_hz == fn_hz
        assert mode.k_n_per_m == pytest.approx(k_mn_per_m * 1e6, rel=1e-12)
        assert mode.c_ns_per_m == pytest.approx(c_ns_per_m, rel=1e-12)  # derived back from zeta


def test_hou2023_positions_lie_on_an_equally_spaced_line(datasets):
    poses = read_modal_table(datasets / "seeds/hou2023_positions.csv").poses
    steps = poses.position_mm[1:] - poses.position_mm[:-1]
    assert len(poses) == 7
    assert (steps == steps[0]).all() and abs(steps[0]).sum() > 0


@pytest.mark.parametrize(
    "file, direction, mode, fn_hz, k_n_per_m, zeta",
    [
        ("swan_spindle_robot.csv", "x", 1, 8.4, 594131, 0.182),
        ("swan_spindle_robot.csv", "x", 20, 6629.3, 910e6, 0.008),
        ("swan_spindle_robot.csv", "y", 16, 5418.8, 27.6e6, 0.011),
        ("swan_spindle_robot.csv", "y", 17, 6622.8, 903e6, 0.008),
        ("swan_fixture.csv", "y", 1, 14.5, 6249330, 0.105),
        ("swan_fixture.csv", "x", 5, 102.2, 68406951, 0.045),
        ("swan_machine_tool.csv", "x", 1, 171, 127262000, 0.082),
        ("swan_machine_tool.csv", "y", 10, 5715, 48556500, 0.064),
    ],
)
def test_swan_tables_reproduce_seed001_tables_4_to_6(datasets, file, direction, mode, fn_hz, k_n_per_m, zeta):
    table = read_modal_table(datasets / "seeds" / file)
    got = _row(table, table.poses.pose_id[0], direction, mode)
    assert (got.fn_hz, got.k_n_per_m, got.zeta) == (fn_hz, k_n_per_m, zeta)


def test_swan_mode_counts_match_seed001(datasets):
    counts = {
        f: read_modal_table(datasets / "seeds" / f).summary()["modes"]
        for f in ("swan_spindle_robot.csv", "swan_fixture.csv", "swan_machine_tool.csv")
    }
    assert counts == {
        "swan_spindle_robot.csv": {"x": 20, "y": 17},
        "swan_fixture.csv": {"x": 5, "y": 4},
        "swan_machine_tool.csv": {"x": 10, "y": 10},
    }


def test_parameter_files_reproduce_seed_tables(datasets):
    host = read_params(datasets / "seeds/dogan2024_host_milling.toml")
    assert (host["host"]["fn_hz"], host["host"]["k_n_per_m"], host["host"]["zeta"]) == (129.29, 1.34e7, 0.0134)
    assert (host["cut"]["teeth"], host["cut"]["kt_n_per_m2"], host["cut"]["kr_n_per_m2"]) == (4, 660e6, 180e6)

    mrf = read_params(datasets / "seeds/hou2023_mrf_absorber.toml")
    assert (mrf["mrf"]["g0_pa"], mrf["mrf"]["ginf_pa"], mrf["mrf"]["a1"], mrf["mrf"]["a2"]) == (2510.0, 3.5e6, 6.8339, 1.8248)
    a = mrf["absorber"]
    assert (a["r1_m"], a["r2_m"], a["l1_m"], a["w1_m"], a["h1_m"], a["h2_m"]) == (0.1, 0.15, 0.04, 0.018, 0.02, 0.05)

    act = read_params(datasets / "seeds/sahu2024_active_damping.toml")
    assert act["actuator"]["horizontal"]["fn_hz"] == 9.0 and act["actuator"]["vertical"]["fn_hz"] == 14.0
    assert act["actuator"]["horizontal"]["delay_ms"] == 0.6 and act["actuator"]["force_limit_n"] == 36.0
    assert [m["fn_hz"] for m in act["frf"]["h11yy"]] == [9.2, 21.0, 23.5]
    assert act["frf"]["h21yy"][0]["sigma_im_m_per_n"] == 4.06e-5


def test_mrf_absorber_quoted_stiffness_is_a_frequency_inside_the_robot_band(datasets):
    """Seed 004: k_a = m_a (2 pi f_a)^2 (eq. 14) with m_a = 3 kg and k_a = 41020 N/m gives ~18.6 Hz,
    between position 5's 19.06 Hz mode and the lower positions: a chatter frequency near the mode."""
    mrf = read_params(datasets / "seeds/hou2023_mrf_absorber.toml")
    f_a = math.sqrt(mrf["check"]["stiffness_at_position5_n_per_m"] / mrf["absorber"]["mass_kg"]) / (2 * math.pi)
    assert 18.0 < f_a < 19.0625
