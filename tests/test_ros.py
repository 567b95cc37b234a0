"""taplan.ros: the streaming node over a fake ROS interface, message conversion, and the rclpy-missing error."""

from __future__ import annotations

import types

import numpy as np
import pytest

import taplan
from taplan import api
from taplan.ros import FakeRosInterface, RclpyInterface, RosUnavailableError, StreamNode, create_rclpy_node
from taplan.stream import JointStreamer

TICK = 1e-3  # [s]


def _deliver_states(interface, q, robot):
    for side in api.SIDES:
        idx = robot.group(side).indices
        interface.deliver(
            api.Topics.joint_states(side), {"name": list(api.ARM_JOINT_NAMES[side]), "position": list(q[idx])}
        )


@pytest.mark.parametrize("convention", ["position", "velocity_feedback"])
def test_node_streams_commands_and_heartbeats(teleavatar, convention):
    interface = FakeRosInterface()
    scheduler = api.CommandScheduler(77.0, 20.0)
    streamer = JointStreamer(teleavatar.planning_limits, scheduler.arm_period)
    node = StreamNode(interface, streamer, scheduler, convention=convention)
    for _ in range(50):  # no joint state yet: nothing is sent
        node.tick()
        interface.advance(TICK)
    assert not any(p.messages for p in interface.publishers.values())
    goal = teleavatar.home + 0.05
    for k in range(2000):  # 2 s
        if k % 10 == 0:
            _deliver_states(interface, teleavatar.home if not node.started else node.last_state.position, teleavatar)
        if node.started and k % 200 == 0:
            streamer.set_target(goal)
        node.tick()
        interface.advance(TICK)
    left = interface.published(api.Topics.joint_cmd("left"))
    right = interface.published(api.Topics.joint_cmd("right"))
    beats = interface.published(api.Topics.ENABLE)
    assert abs(len(left) - 77 * 2.0) <= 2 and len(left) == len(right)  # 2 s streaming after the first state
    assert abs(len(beats) - 20 * 2.0) <= 2 and all(f["data"] == 1.0 for _, f in beats)
    first = left[0][1]
    np.testing.assert_allclose(first["position"], teleavatar.home[:7], atol=1e-3)  # starts where the robot is
    np.testing.assert_allclose(left[-1][1]["position"], goal[:7], atol=1e-6)
    assert first["name"] == list(api.ARM_JOINT_NAMES["left"])
    if convention == "position":
        assert all(f["velocity"] == [0.0] * 7 for _, f in left)
    node.disable()
    assert interface.published(api.Topics.ENABLE)[-1][1] == {"data": -1.0}


def test_node_rejects_mismatched_setup(teleavatar):
    interface = FakeRosInterface()
    streamer = JointStreamer(teleavatar.planning_limits, 1 / 50)
    with pytest.raises(taplan.InvalidInputError, match="dt"):
        StreamNode(interface, streamer, api.CommandScheduler(77.0))
    left_only = JointStreamer(teleavatar.planning_limits.subset(api.ARM_JOINT_NAMES["left"]), 1 / 77)
    with pytest.raises(taplan.UnknownNameError):
        StreamNode(interface, left_only, api.CommandScheduler(77.0))
    node = StreamNode(interface, left_only, api.CommandScheduler(77.0), sides=("left",))
    node.on_joint_state("left", {"name": ["x"], "position": [0.0]})
    assert node.rejected_states == 1


def test_rclpy_missing_gives_clear_error(teleavatar):
    streamer = JointStreamer(teleavatar.planning_limits, 1 / 77)
    try:
        import rclpy  # noqa: F401
    except ImportError:
        with pytest.raises(RosUnavailableError, match="source a ROS 2"):
            create_rclpy_node(streamer)
    else:  # pragma: no cover
        pytest.skip("rclpy is installed")


def test_rclpy_interface_converts_messages():
    class Point:
        x = y = z = 0.0

    class Quat:
        x = y = z = 0.0
        w = 1.0

    class JointState:
        def __init__(self):
            self.name, self.position, self.velocity, self.effort = [], [], [], []

    class Float32:
        def __init__(self):
            self.data = 0.0

    class Pose:
        def __init__(self):
            self.position, self.orientation = Point(), Quat()

    sent = []

    class FakeNode:
        def create_publisher(self, cls, topic, qos):
            return types.SimpleNamespace(publish=lambda msg: sent.append((topic, msg)))

        def create_subscription(self, cls, topic, callback, qos):
            self.callback = callback

        def get_clock(self):
            return types.SimpleNamespace(now=lambda: types.SimpleNamespace(nanoseconds=1_500_000_000))

    node = FakeNode()
    messages = {
        "sensor_msgs/msg/JointState": JointState,
        "std_msgs/msg/Float32": Float32,
        "geometry_msgs/msg/Pose": Pose,
    }
    interface = RclpyInterface(node, messages=messages)
    assert interface.now() == pytest.approx(1.5)
    cmd = api.joint_cmd("left", np.arange(7) * 0.1)
    interface.create_publisher(cmd.type, cmd.topic).publish(cmd.fields)
    topic, msg = sent[-1]
    assert topic == "/api/left_arm/joint_cmd" and msg.position == pytest.approx(cmd.fields["position"])
    pose = api.target_pose("right", position=[0.1, 0.2, 0.3], quaternion=[0, 0, 0, 1])
    interface.create_publisher(pose.type, pose.topic).publish(pose.fields)
    assert sent[-1][1].position.y == pytest.approx(0.2)
    received = []
    interface.create_subscription("sensor_msgs/msg/JointState", "/left_arm/joint_states", received.append)
    state = JointState()
    state.name, state.position = ["l_joint1"], [0.5]
    node.callback(state)
    assert received[-1]["position"] == [0.5]
    with pytest.raises(taplan.ConfigError):
        interface.create_publisher("std_msgs/msg/String", "/x")
