"""taplan.api: payload builders and their validation, and the scheduler over a simulated minute."""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from taplan import api

RATE_TOL = 1  # [messages] over a minute


def test_joint_cmd_position_convention():
    q = np.linspace(0.1, 0.7, 7)
    msg = api.joint_cmd("left", q)
    assert msg.topic == "/api/left_arm/joint_cmd"
    assert msg.type == "sensor_msgs/msg/JointState"
    assert msg.fields["name"] == [f"l_joint{i}" for i in range(1, 8)]
    assert msg.fields["position"] == pytest.approx(q.tolist())
    assert msg.fields["velocity"] == [0.0] * 7 and msg.fields["effort"] == [0.0] * 7


def test_joint_cmd_velocity_feedback_uses_guide_gains_and_clip():
    measured = np.zeros(7)
    small = np.full(7, 0.01)
    msg = api.joint_cmd("right", small, convention="velocity_feedback", measured=measured)
    np.testing.assert_allclose(msg.fields["velocity"], np.array(api.FEEDBACK_KP) * 0.01)
    large = np.full(7, 5.0)
    msg = api.joint_cmd("right", large, convention="velocity_feedback", measured=measured)
    np.testing.assert_allclose(msg.fields["velocity"], [4.5, 4.5, 6.0, 6.0, 13.2, 9.9, 9.9])
    np.testing.assert_allclose(api.feedback_velocity(-large, measured), -np.array([4.5, 4.5, 6, 6, 13.2, 9.9, 9.9]))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"side": "middle", "position": np.zeros(7)}, "side"),
        ({"side": "left", "position": np.zeros(6)}, "position"),
        ({"side": "left", "position": [np.nan] * 7}, "position"),
        ({"side": "left", "position": np.zeros(7), "convention": "torque"}, "convention"),
        ({"side": "left", "position": np.zeros(7), "convention": "velocity_feedback"}, "measured"),
    ],
)
def test_joint_cmd_rejects(kwargs, match):
    with pytest.raises(taplan.TaplanError, match=match):
        api.joint_cmd(**kwargs)


def test_joint_cmd_checks_limits(teleavatar):
    q = teleavatar.home[:7].copy()
    api.joint_cmd("left", q, limits=teleavatar.limits)
    q[3] = 0.0  # l_joint4 lower bound is 0.25
    with pytest.raises(taplan.InvalidInputError, match="l_joint4"):
        api.joint_cmd("left", q, limits=teleavatar.limits)


def test_small_payloads_and_ranges():
    assert api.gripper_cmd("left", 0.6).fields == {"data": 0.6}
    assert api.gripper_cmd("right", 1.0).topic == "/api/right_gripper/cmd"
    assert api.chassis_velocity(0.1, -0.2, 1.0).fields == {"data": [0.1, -0.2, 1.0]}
    assert api.servo_cmd(0.5).fields == {"data": [0.5, 1.0]}
    assert api.servo_cmd(0.0, enable=False).fields == {"data": [0.0, 0.0]}
    assert api.fsm_enable().fields == {"data": 1.0} and api.fsm_enable(False).fields == {"data": -1.0}
    assert api.fsm_adjust().topic == "/api/fsm/adjust"
    for call in (
        lambda: api.gripper_cmd("left", 1.2),
        lambda: api.gripper_cmd("left", float("nan")),
        lambda: api.chassis_velocity(0.0, 1.5, 0.0),
        lambda: api.chassis_velocity("fast", 0.0, 0.0),
        lambda: api.servo_cmd(0.3, enable=False),
        lambda: api.servo_cmd(float("inf")),
        lambda: api.fsm_enable(1.0),
    ):
        with pytest.raises(taplan.InvalidInputError):
            call()


def test_target_pose_from_transform_and_quaternion(teleavatar):
    T = teleavatar.frame_pose(teleavatar.home, "left_ee")
    msg = api.target_pose("left", T)
    p, o = msg.fields["position"], msg.fields["orientation"]
    np.testing.assert_allclose([p["x"], p["y"], p["z"]], T[:3, 3])
    import pinocchio as pin

    quat = pin.Quaternion(T[:3, :3])
    expected = np.array([quat.x, quat.y, quat.z, quat.w]) * np.sign(quat.w)
    np.testing.assert_allclose([o["x"], o["y"], o["z"], o["w"]], expected, atol=1e-12)
    same = api.target_pose("left", position=T[:3, 3], quaternion=expected)
    for part in ("position", "orientation"):
        assert same.fields[part] == pytest.approx(msg.fields[part])
    with pytest.raises(taplan.InvalidInputError):
        api.target_pose("left", position=[0, 0, 0], quaternion=[0, 0, 0, 2])
    with pytest.raises(taplan.InvalidInputError):
        api.target_pose("left", np.diag([1.0, 1.0, -1.0, 1.0]))


def test_parse_joint_state_by_name_and_index():
    names = [f"r_joint{i}" for i in (3, 1, 2, 4, 5, 6, 7)]
    q = api.parse_joint_state("right", names, [3, 1, 2, 4, 5, 6, 7])
    np.testing.assert_array_equal(q, np.arange(1, 8))
    np.testing.assert_array_equal(api.parse_joint_state("left", [], list(range(9))), np.arange(7))
    with pytest.raises(taplan.UnknownNameError):
        api.parse_joint_state("left", names, list(range(7)))


@pytest.mark.parametrize("arm_rate", [50.0, 60.0, 77.0])
def test_scheduler_rates_over_a_simulated_minute(arm_rate, rng):
    clock = api.ManualClock()
    scheduler = api.CommandScheduler(arm_rate, 20.0, extra={"gripper": 10.0}, clock=clock)
    times: dict[str, list[float]] = {"arm": [], "heartbeat": [], "gripper": []}
    while clock.now < 60.0:
        for name in scheduler.tick():
            times[name].append(clock.now)
        clock.advance(rng.uniform(0.5e-3, 1.5e-3))  # a jittery 1 kHz timer
    assert abs(len(times["arm"]) - arm_rate * 60) <= RATE_TOL
    assert abs(len(times["heartbeat"]) - 20 * 60) <= RATE_TOL
    assert abs(len(times["gripper"]) - 10 * 60) <= RATE_TOL
    gaps = np.diff(times["heartbeat"])
    assert gaps.max() < 1.0 / 20.0 + 2e-3  # never close to the robot's 1 s heartbeat timeout


def test_scheduler_skips_missed_slots_and_validates():
    scheduler = api.CommandScheduler(50.0, 20.0)
    assert scheduler.tick(0.0) == {"arm", "heartbeat"}
    assert scheduler.tick(0.5) == {"arm", "heartbeat"}  # a 0.5 s stall: one message each, no burst
    assert scheduler.tick(0.5) == frozenset()
    assert "arm" in scheduler.tick(0.52)
    for bad in (dict(arm_rate=100.0), dict(arm_rate=30.0), dict(heartbeat_rate=1.0)):
        with pytest.raises(taplan.InvalidInputError):
            api.CommandScheduler(**bad)
    with pytest.raises(taplan.InvalidInputError, match="monotonic"):
        scheduler.tick(0.1)
    with pytest.raises(taplan.InvalidInputError):
        api.CommandScheduler().tick()  # no clock and no time
