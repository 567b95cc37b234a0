"""Robot: model loading, forward kinematics against an independent computation, frames, groups, joint order."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import taplan
from taplan.robot import TELEAVATAR_URDF

POS_TOL = 1e-9  # [m]
ROT_TOL = 1e-9  # [-], rotation-matrix entries
MIRROR_TOL = 0.006  # [m]: the CAD exports of the two arms differ by a few millimetres
ARM_LENGTH = 0.55  # [m], arm_config.yml max_arm_len
ARM_LENGTH_TOL = 0.005  # [m]
JAC_TOL = 1e-6  # [m]/[rad]


def _rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    r, p, y = rpy
    rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    k = axis / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _numpy_fk(urdf_path, joint_values: dict[str, float], link: str) -> np.ndarray:
    """Pose of ``link`` by composing the URDF's joint origins and axis rotations: no pinocchio involved."""
    root = ET.parse(urdf_path).getroot()
    parent_joint = {j.find("child").get("link"): j for j in root.findall("joint")}
    chain = []
    while link in parent_joint:
        joint = parent_joint[link]
        chain.append(joint)
        link = joint.find("parent").get("link")
    T = np.eye(4)
    for joint in reversed(chain):
        origin = joint.find("origin")
        step = np.eye(4)
        step[:3, :3] = _rpy_matrix(np.array(origin.get("rpy", "0 0 0").split(), float))
        step[:3, 3] = np.array(origin.get("xyz", "0 0 0").split(), float)
        if joint.get("type") == "revolute":
            axis = np.array(joint.find("axis").get("xyz").split(), float)
            motion = np.eye(4)
            motion[:3, :3] = _axis_rotation(axis, joint_values[joint.get("name")])
            step = step @ motion
        T = T @ step
    return T


def test_joint_names_and_groups(teleavatar):
    expected = tuple(f"l_joint{i}" for i in range(1, 8)) + tuple(f"r_joint{i}" for i in range(1, 8))
    assert teleavatar.joint_names == expected
    assert teleavatar.group("left").joint_names == expected[:7]
    np.testing.assert_array_equal(teleavatar.group("right").indices, np.arange(7, 14))
    assert teleavatar.group("left").ee_frame == "left_ee"
    with pytest.raises(taplan.UnknownNameError, match="valid: left, right"):
        teleavatar.group("middle")


@pytest.mark.parametrize("frame,link,offset", [("left_ee", "Link-L7", (0, 0, -0.031)), ("right_tcp", "Link-R7", None)])
def test_forward_kinematics_matches_numpy_composition(teleavatar, rng, frame, link, offset):
    for _ in range(20):
        q = rng.uniform(teleavatar.limits.lower, teleavatar.limits.upper)
        T_link = _numpy_fk(TELEAVATAR_URDF, dict(zip(teleavatar.joint_names, q, strict=True)), link)
        T_frame = _numpy_fk(TELEAVATAR_URDF, dict(zip(teleavatar.joint_names, q, strict=True)), frame)
        got = teleavatar.frame_pose(q, frame)
        np.testing.assert_allclose(got[:3, 3], T_frame[:3, 3], atol=POS_TOL)
        np.testing.assert_allclose(got[:3, :3], T_frame[:3, :3], atol=ROT_TOL)
        if offset is not None:  # the documented placement of the end effector on Link-7
            np.testing.assert_allclose(got[:3, 3], T_link[:3, :3] @ offset + T_link[:3, 3], atol=POS_TOL)


def test_vendor_urdf_kinematics_are_preserved(teleavatar):
    vendor = Path(__file__).resolve().parents[2] / "shared" / "reference" / "teleavatar" / "urdf20260625.urdf"
    if not vendor.exists():
        pytest.skip("the vendor URDF (shared/ beside the repository) is not available")
    model = pin.buildModelFromUrdf(str(vendor))
    data = model.createData()
    q = teleavatar.home
    pin.framesForwardKinematics(model, data, q)
    for link in ("Link-L7", "Link-R7", "Link-L4", "Link-R4"):
        expected = data.oMf[model.getFrameId(link)].homogeneous
        np.testing.assert_allclose(teleavatar.frame_pose(q, link), expected, atol=POS_TOL)


def test_shoulder_to_wrist_length_matches_max_arm_len(teleavatar):
    zero = np.zeros(teleavatar.nq)  # straight arms (outside the joint-4 limit, fine for geometry)
    for side in ("left", "right"):
        straight = teleavatar.relative_pose(zero, f"{side}_ee", f"{side}_shoulder_base")
        assert abs(np.linalg.norm(straight[:3, 3]) - ARM_LENGTH) < ARM_LENGTH_TOL


def test_arms_mirror_each_other(teleavatar, rng):
    mirror = np.diag([1.0, -1.0, 1.0])
    for _ in range(20):
        q_left = rng.uniform(teleavatar.limits.lower[:7], teleavatar.limits.upper[:7])
        q = np.concatenate([q_left, -q_left])
        left = teleavatar.frame_pose(q, "left_ee")
        right = teleavatar.frame_pose(q, "right_ee")
        np.testing.assert_allclose(mirror @ left[:3, 3], right[:3, 3], atol=MIRROR_TOL)
        # reflected orientation: R_right = M R_left M
        np.testing.assert_allclose(mirror @ left[:3, :3] @ mirror, right[:3, :3], atol=0.02)


def test_home_is_mirrored_adjust_pose_inside_limits(teleavatar):
    home = teleavatar.home
    np.testing.assert_allclose(home[7:], [-0.8, -0.9, 0.5, -1.12, -0.38, 0.0, -0.12])
    np.testing.assert_allclose(home[:7], -home[7:])
    assert teleavatar.limits.within(home)
    home[0] = 99.0  # a copy: the robot's home is unchanged
    assert teleavatar.home[0] == pytest.approx(0.8)


def test_frame_jacobian_matches_finite_differences(teleavatar, rng):
    eps = 1e-7  # [rad]
    q = teleavatar.home + rng.uniform(-0.2, 0.2, teleavatar.nq)
    J = teleavatar.frame_jacobian(q, "right_ee")
    T0 = teleavatar.frame_pose(q, "right_ee")
    for i in range(teleavatar.nq):
        dq = np.zeros(teleavatar.nq)
        dq[i] = eps
        T1 = teleavatar.frame_pose(q + dq, "right_ee")
        linear = (T1[:3, 3] - T0[:3, 3]) / eps
        angular = pin.log3(T1[:3, :3] @ T0[:3, :3].T) / eps  # world-aligned angular velocity
        np.testing.assert_allclose(J[:3, i], linear, atol=JAC_TOL)
        np.testing.assert_allclose(J[3:, i], angular, atol=JAC_TOL)
    local = teleavatar.frame_jacobian(q, "right_ee", reference="local")
    np.testing.assert_allclose(local[:3], T0[:3, :3].T @ J[:3], atol=1e-12)
    with pytest.raises(taplan.UnknownNameError, match="reference"):
        teleavatar.frame_jacobian(q, "right_ee", reference="body")


def test_relative_pose_and_add_frame(rng):
    robot = taplan.Robot.teleavatar()
    offset = np.eye(4)
    offset[:3, 3] = [0.0, 0.1, 0.0]
    robot.add_frame("left_tool", "left_ee", offset)
    q = robot.home
    np.testing.assert_allclose(robot.frame_pose(q, "left_tool"), robot.frame_pose(q, "left_ee") @ offset, atol=1e-12)
    np.testing.assert_allclose(robot.relative_pose(q, "left_tool", "left_ee"), offset, atol=1e-12)
    with pytest.raises(taplan.InvalidInputError, match="name"):
        robot.add_frame("left_tool", "left_ee", offset)


def test_joint_state_mapping(teleavatar):
    names = [f"r_joint{i}" for i in (3, 1, 2, 7, 6, 5, 4)]
    values = np.arange(7, dtype=float)
    q = teleavatar.from_joint_state(names, values, base=teleavatar.home)
    np.testing.assert_allclose(q[:7], teleavatar.home[:7])
    np.testing.assert_allclose(teleavatar.to_joint_state(q, names), values)
    assert q[teleavatar.indices(["r_joint3"])[0]] == 0.0
    with pytest.raises(taplan.InvalidInputError, match="missing"):
        teleavatar.from_joint_state(names, values)
    with pytest.raises(taplan.UnknownNameError, match="joint 'r_joint9'"):
        teleavatar.from_joint_state(["r_joint9"], [0.0], base=teleavatar.home)
    with pytest.raises(taplan.InvalidInputError, match="unique"):
        teleavatar.from_joint_state(["r_joint1", "r_joint1"], [0.0, 0.0], base=teleavatar.home)
    with pytest.raises(taplan.InvalidInputError, match="positions"):
        teleavatar.from_joint_state(names, values[:6], base=teleavatar.home)
    full = teleavatar.from_joint_state(list(reversed(teleavatar.joint_names)), np.arange(14.0))
    np.testing.assert_allclose(full, np.arange(14.0)[::-1])


@pytest.mark.parametrize(
    "q,match",
    [
        (np.zeros(13), r"shape \(14,\)"),
        (np.full(14, np.nan), "finite"),
        ("abc", "numeric"),
        (np.zeros((2, 14)), r"shape \(14,\)"),
    ],
)
def test_bad_configurations_raise(teleavatar, q, match):
    with pytest.raises(taplan.InvalidInputError, match=match):
        teleavatar.frame_pose(q, "left_ee")


def test_unknown_frame_lists_valid_frames(teleavatar):
    with pytest.raises(taplan.UnknownNameError, match="left_ee"):
        teleavatar.frame_pose(teleavatar.home, "left_hand")


def test_capsules_cover_both_arms(teleavatar):
    from taplan.scene.capsules import capsule_distance

    left = {c.link for c, _ in teleavatar.capsule_pairs("left", "right")}
    right = {c.link for _, c in teleavatar.capsule_pairs("left", "right")}
    assert left == {f"Link-L{k}" for k in range(1, 8)}  # every link can meet the other arm (SRDF sweep)
    assert right == {f"Link-R{k}" for k in range(1, 8)}
    pin.forwardKinematics(teleavatar.model, teleavatar.data, teleavatar.home)
    distances = [capsule_distance(teleavatar.data, a, b) for a, b in teleavatar.capsule_pairs("left", "right")]
    assert min(distances) > 0.05  # [m]: the home pose keeps the arms well apart


def test_segment_distance_closed_form_matches_sampling(rng):
    from taplan.scene.capsules import segment_closest_points

    for _ in range(50):
        p0, p1, q0, q1 = rng.normal(size=(4, 3))
        a, b, s, t = segment_closest_points(p0, p1, q0, q1)
        grid = np.linspace(0, 1, 401)
        pts_a = p0 + grid[:, None] * (p1 - p0)
        pts_b = q0 + grid[:, None] * (q1 - q0)
        brute = np.min(np.linalg.norm(pts_a[:, None] - pts_b[None], axis=2))
        assert np.linalg.norm(a - b) <= brute + 1e-12
        assert np.linalg.norm(a - b) >= brute - 0.01  # grid resolution
        assert 0 <= s <= 1 and 0 <= t <= 1


def test_generic_urdf_loads_with_its_own_limits(tmp_path):
    urdf = tmp_path / "two_link.urdf"
    urdf.write_text(
        """<robot name="two"><link name="base"/><link name="a"/><link name="b"/>
        <joint name="j1" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/>
        <limit lower="-1" upper="1" velocity="2" effort="1"/></joint>
        <joint name="j2" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0.5 0 0"/>
        <axis xyz="0 0 1"/><limit lower="-2" upper="0" velocity="3" effort="1"/></joint></robot>"""
    )
    robot = taplan.Robot.from_urdf(urdf)
    assert robot.joint_names == ("j1", "j2")
    np.testing.assert_allclose(robot.home, [0.0, -1.0])
    np.testing.assert_allclose(robot.limits.velocity, [2.0, 3.0])
    np.testing.assert_allclose(robot.frame_pose([0.5, 0.0], "b")[:2, 3], [0.5 * np.cos(0.5), 0.5 * np.sin(0.5)])
    with pytest.raises(taplan.ConfigError, match="not found"):
        taplan.Robot.from_urdf(tmp_path / "missing.urdf")
    with pytest.raises(taplan.ConfigError, match="outside"):
        taplan.Robot.from_urdf(urdf, home=[0.0, 1.0])
