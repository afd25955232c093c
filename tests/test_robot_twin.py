"""Robot kinematics (Pinocchio) and the elastodynamic twin."""

import json
import math
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from posedyn.robot.campaign import GridPose, Noise, generate_campaign, kept_compliance, least_kept_compliance, pose_modes
from posedyn.robot.twin_effects import DeviceMass, parse_effect
from posedyn.errors import InputError
from posedyn.io import format_modal_table, read_modal_table
from posedyn.io.grid import read_grid
from posedyn.io.twin_file import read_twin
from posedyn.robot import Robot, ToolPose, abc_from_rotation, rotation_from_abc
from posedyn.robot.twin import mass_matrix, normal_modes, twin_modes
from tests.cli_helpers import run_cli

ROBOTS = "datasets/robots"


@pytest.fixture(scope="module")
def twin(datasets):
    spec = read_twin(datasets / "robots/kr_r2700_twin.toml")
    return Robot.from_urdf(spec.urdf, payload_kg=spec.payload_kg), spec.params


def random_configurations(robot, count, seed=0):
    """Joint angles in the front, elbow-up, A5 > 0 branch that the inverse kinematics returns."""
    rng = np.random.default_rng(seed)
    lo = np.array([-1.2, -1.7, 0.4, -2.5, 0.2, -2.5])
    hi = np.array([1.2, -0.4, 2.2, 2.5, 1.9, 2.5])
    return rng.uniform(lo, hi, (count, 6))


def test_forward_inverse_round_trip_to_a_micrometre(twin):
    robot, _ = twin
    data = robot.model.createData()
    worst_position, worst_joint = 0.0, 0.0
    for q in random_configurations(robot, 300):
        placement = robot.forward(q, data)
        q_back = robot.inverse(ToolPose(placement.translation, placement.rotation), data)
        again = robot.forward(q_back, data)
        worst_position = max(worst_position, np.linalg.norm(again.translation - placement.translation))
        worst_joint = max(worst_joint, np.abs(q_back - q).max())
        assert np.allclose(again.rotation, placement.rotation, atol=1e-9)
    assert worst_position < 1e-6
    assert worst_joint < 1e-6  # the same branch comes back


def test_every_seed003_grid_pose_is_reachable_and_exact(twin, datasets):
    robot, _ = twin
    grid = read_grid(datasets / "campaigns/seed003_grid.toml")
    assert len(grid.poses) == 112
    data = robot.model.createData()
    for g in grid.poses:
        q = robot.inverse(g.pose, data)
        placement = robot.forward(q, data)
        assert np.linalg.norm(placement.translation - g.pose.position_m) < 1e-9
        assert placement.rotation[:, 0] == pytest.approx([0, 0, -1], abs=1e-9)  # tool axis along base -z


def test_unreachable_pose_and_joint_limits_give_a_clear_error(twin):
    robot, _ = twin
    with pytest.raises(InputError, match=r"inside the robot's reach.*tool tip at \(4000\.0, 0\.0, 600\.0\) mm"):
        robot.inverse(ToolPose.from_beta(4.0, 0.0, 0.6, 0.0))
    # tool axis pointing back at the robot base from below: A5 beyond its 122.5 deg limit
    with pytest.raises(InputError, match=r"joint A5 within \[-122\.5, 122\.5\] deg"):
        robot.inverse(ToolPose.from_abc(1.5, 0.0, 0.6, 0.0, math.radians(-60.0), math.radians(180.0)))


def test_jacobian_matches_finite_differences(twin):
    robot, _ = twin
    q = random_configurations(robot, 1, seed=3)[0]
    J = robot.jacobian(q)
    h = 1e-7
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = h
        a, b = robot.forward(q + dq), robot.forward(q - dq)
        assert np.allclose((a.translation - b.translation) / (2 * h), J[:3, j], atol=1e-6)


def test_abc_round_trip():
    rng = np.random.default_rng(1)
    for a, b, c in rng.uniform([-3, -1.5, -3], [3, 1.5, 3], (50, 3)):
        R = rotation_from_abc(a, b, c)
        assert np.allclose(rotation_from_abc(*abc_from_rotation(R)), R, atol=1e-12)


def test_mass_matrix_is_symmetric_positive_definite(twin):
    robot, params = twin
    for q in random_configurations(robot, 50, seed=2):
        M = mass_matrix(robot, q, params)
        assert np.allclose(M, M.T, rtol=0, atol=1e-12 * np.abs(M).max())
        assert np.linalg.eigvalsh(M).min() > 0


TWO_LINK = """<?xml version="1.0"?>
<robot name="two_link">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="{l1} 0 0"/><mass value="{m1}"/>
    <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
  <link name="l2"><inertial><origin xyz="{l2} 0 0"/><mass value="{m2}"/>
    <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="0" velocity="1"/></joint>
  <joint name="j2" type="revolute"><origin xyz="{l1} 0 0"/><parent link="l1"/><child link="l2"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="0" velocity="1"/></joint>
</robot>"""


@pytest.mark.parametrize("q2", [0.0, 0.7, 2.0])
def test_normal_modes_match_closed_form_two_link_arm(q2):
    """Point masses m1 at l1 and m2 at l1 + l2 (link 2 along its own x), joint springs k1, k2:
    M = [[m1 l1^2 + m2 (l1^2 + l2^2 + 2 l1 l2 c2), m2 (l2^2 + l1 l2 c2)], [., m2 l2^2]] and
    w^2 are the roots of det(K - w^2 M) = 0."""
    m1, m2, l1, l2, k1, k2 = 40.0, 15.0, 1.1, 0.9, 2.0e6, 6.0e5
    model = pin.buildModelFromXML(TWO_LINK.format(m1=m1, m2=m2, l1=l1, l2=l2))
    data = model.createData()
    q = np.array([0.3, q2])
    M = pin.crba(model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    c2 = math.cos(q2)
    expected = np.array([[m1 * l1**2 + m2 * (l1**2 + l2**2 + 2 * l1 * l2 * c2), m2 * (l2**2 + l1 * l2 * c2)], [m2 * (l2**2 + l1 * l2 * c2), m2 * l2**2]])
    assert np.allclose(M, expected, rtol=1e-12)
    K = np.diag([k1, k2])
    w2, phi = normal_modes(M, K)
    a = np.linalg.det(M)
    b = -(k1 * M[1, 1] + k2 * M[0, 0])
    c = k1 * k2
    roots = np.sort([(-b - math.sqrt(b * b - 4 * a * c)) / (2 * a), (-b + math.sqrt(b * b - 4 * a * c)) / (2 * a)])
    assert w2 == pytest.approx(roots, rel=1e-12)
    assert np.allclose(phi.T @ M @ phi, np.eye(2), atol=1e-12)


def test_modes_change_smoothly_along_a_line_and_stay_in_the_robot_band(twin):
    robot, params = twin
    data = robot.model.createData()
    lowest = []
    for x in np.linspace(1.3, 1.9, 61):
        _, modes = pose_modes(robot, GridPose("p", ToolPose.from_beta(x, 0.1, 0.6, math.radians(20))), params, data=data)
        assert np.all((modes.fn_hz[:3] > 5) & (modes.fn_hz[:3] < 40))
        lowest.append(modes.fn_hz[:3])
    lowest = np.array(lowest)
    steps = np.abs(np.diff(lowest, axis=0)) / lowest[:-1]
    assert steps.max() < 0.02  # 10 mm apart: no jumps
    assert lowest[0, 0] != pytest.approx(lowest[-1, 0], rel=0.05)  # but the pose matters


def test_added_device_mass_can_only_lower_the_modes(twin):
    """Rayleigh: adding mass (K fixed) lowers or keeps every eigenfrequency (interlacing)."""
    robot, params = twin
    pose = GridPose("p", ToolPose.from_beta(1.6, -0.2, 0.6, math.radians(-40)))
    _, nominal = pose_modes(robot, pose, params)
    _, heavier = pose_modes(robot, pose, params, effects=(DeviceMass(mass_kg=8.0),))
    assert np.all(heavier.fn_hz <= nominal.fn_hz * (1 + 1e-12))
    assert heavier.fn_hz[0] < 0.99 * nominal.fn_hz[0]
    assert parse_effect("device_mass:mass_kg=8") == DeviceMass(mass_kg=8.0)
    with pytest.raises(InputError, match="effect among"):
        parse_effect("gremlins:count=3")


def test_payload_override_and_stiffness_scaling(twin, datasets):
    robot, params = twin
    light = Robot.from_urdf(datasets / "robots/kr_r2700_spindle.urdf", payload_kg=10.0)
    q = random_configurations(robot, 1, seed=4)[0]
    heavy_fn = twin_modes(robot, q, params).fn_hz
    assert np.all(twin_modes(light, q, params).fn_hz >= heavy_fn * (1 - 1e-12))
    # all joint stiffnesses x4 -> every frequency x2 exactly
    assert twin_modes(robot, q, params.scaled(4.0)).fn_hz == pytest.approx(2 * heavy_fn, rel=1e-10)


def test_twin_receptance_is_the_sum_of_its_modes(twin):
    """The x-y dynamics handed to the stability engine reproduce the direct modal stiffnesses:
    at w -> 0, H_xx = sum_r 1 / k_rx over the robot modes (plus the spindle modes)."""
    robot, params = twin
    q = random_configurations(robot, 1, seed=5)[0]
    modes = twin_modes(robot, q, params)
    static = modes.dynamics().frf(np.array([1e-6]))[0]
    expected = np.sum(1 / modes.stiffness("x")) + sum(1 / m.k_n_per_m for m in params.spindle_modes["x"])
    assert static[0, 0].real == pytest.approx(expected, rel=1e-9)


def test_same_seed_gives_the_same_campaign_bit_for_bit(twin, datasets):
    robot, params = twin
    poses = list(read_grid(datasets / "campaigns/seed003_grid.toml").poses)[:10]
    a = format_modal_table(generate_campaign(robot, poses, params, Noise(), seed=7))
    b = format_modal_table(generate_campaign(robot, poses, params, Noise(), seed=7))
    c = format_modal_table(generate_campaign(robot, poses, params, Noise(), seed=8))
    assert a == b and a != c


def test_noise_free_campaign_is_the_twin(twin, datasets):
    robot, params = twin
    poses = list(read_grid(datasets / "campaigns/seed003_grid.toml").poses)[:3]
    table = generate_campaign(robot, poses, params, Noise(0, 0, 0), seed=0)
    _, modes = pose_modes(robot, poses[0], params)
    x = table.modes(poses[0].label, "x")
    k = modes.stiffness("x")
    count = params.robot_modes_per_direction
    assert count == 6  # the shipped twin's tables keep every robot mode
    assert [m.fn_hz for m in x[:count]] == pytest.approx(modes.fn_hz, rel=1e-12)
    assert [m.k_n_per_m for m in x[:count]] == pytest.approx(k, rel=1e-12)
    assert x[count].fn_hz == 1443.5  # spindle modes follow


def test_a_campaign_that_keeps_fewer_robot_modes_says_how_much_compliance_it_leaves_out(twin, datasets, tmp_path):
    """seed 003's grid, the two lowest robot modes: at some pose they carry 3 % of the tool tip's
    static compliance in y (every mode: all of it); the share is sum 1/k over the kept modes."""
    robot, params = twin
    poses = list(read_grid(datasets / "campaigns/seed003_grid.toml").poses)
    _, modes = pose_modes(robot, poses[0], params)
    k = modes.stiffness("y")
    assert kept_compliance(modes, "y", 2) == pytest.approx((1 / k[:2]).sum() / (1 / k).sum(), rel=1e-12)
    assert kept_compliance(modes, "y", 6) == pytest.approx(1.0, rel=1e-12)
    assert least_kept_compliance(robot, poses[:5], params) == (1.0, "", "")
    share, pose, direction = least_kept_compliance(robot, poses, replace(params, robot_modes_per_direction=2))
    assert share < 0.05 and direction == "y" and pose in {p.label for p in poses}
    twin2 = tmp_path / "twin2.toml"
    twin2.write_text((datasets / "robots/kr_r2700_twin.toml").read_text().replace("robot_modes_per_direction = 6", "robot_modes_per_direction = 2")
                     .replace('urdf = "kr_r2700_spindle.urdf"', f'urdf = "{(datasets / "robots/kr_r2700_spindle.urdf").as_posix()}"'))
    result = run_cli("twin", "campaign", "--grid", datasets / "campaigns/seed003_grid.toml", "--twin", twin2, "--out", tmp_path / "c2.csv", "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["least_kept_compliance"] == pytest.approx(share, rel=1e-9)
    assert f"keeps only {100 * share:.0f} % of the tool tip's static robot compliance in y at pose {pose}" in result.stderr


def test_shipped_campaign_matches_its_recorded_recipe(datasets, tmp_path):
    """datasets/campaigns/seed003_twin_s1.csv is `posedyn twin campaign --grid seed003_grid.toml --seed 1`."""
    out = tmp_path / "again.csv"
    result = run_cli("twin", "campaign", "--grid", datasets / "campaigns/seed003_grid.toml", "--seed", "1", "--out", out, "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["poses"] == 112
    again, shipped = read_modal_table(out), read_modal_table(datasets / "campaigns/seed003_twin_s1.csv")
    # equal up to the last bits that another CPU's LAPACK may round differently
    assert again.poses.pose_id == shipped.poses.pose_id
    for name in ("fn_hz", "zeta", "k_n_per_m"):
        assert np.allclose(getattr(again, name), getattr(shipped, name), rtol=1e-9, atol=0)
    assert again.summary()["modes"] == {"x": 8, "y": 8, "z": 6}
    assert json.loads(result.stdout)["least_kept_compliance"] == 1.0 and "warning" not in result.stderr


def test_twin_modes_cli_and_bad_grid(datasets, tmp_path):
    result = run_cli("twin", "modes", "--x-mm", "1500", "--y-mm", "100", "--z-mm", "600", "--beta-deg", "20", "--json")
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert len(out["modes"]) == 6 and 5 < out["modes"][0]["fn_hz"] < 40
    bad = tmp_path / "grid.toml"
    bad.write_text('[meta]\nkind = "pose_grid"\nsource = "test"\n[grid]\nx_mm = [1500]\ny_mm = [0]\nz_mm = ["high"]\nbeta_deg = [0]\n')
    result = run_cli("twin", "campaign", "--grid", bad, "--out", tmp_path / "o.csv")
    assert result.returncode == 2 and "z_mm" in result.stderr and "grid.toml" in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "o.csv").exists()


def test_an_unreachable_pose_is_named_by_its_row_and_id(tmp_path):
    """`posedyn schedule MODEL --poses P.csv` with one pose out of reach stopped with 'expected a
    tool-tip position inside the robot's reach' and no file, row or pose_id."""
    from posedyn.io import read_pose_table
    from posedyn.io.twin_file import load_twin
    from posedyn.posemodel.model import pose_joints

    path = tmp_path / "poses.csv"
    path.write_text("pose_id,x_mm,y_mm,z_mm,beta_deg\nok,1500,0,600,0\nfar,5000,0,600,0\n")
    robot, _ = load_twin(None)
    with pytest.raises(InputError) as err:
        pose_joints(robot, read_pose_table(path))
    assert err.value.row == 2 and err.value.column == "pose far" and "reach" in str(err.value)
