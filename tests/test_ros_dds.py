"""taplan.ros over DDS (in one process, loopback only): ROS 2 names and layouts, round trips, bags, bad input."""

from __future__ import annotations

import random
import time

import numpy as np
import pytest

from taplan import api
from taplan.errors import ConfigError, InvalidInputError
from taplan.ros import bag, messages
from taplan.ros.dds import DdsInterface, domain_id_from_environment, loopback_config
from taplan.ros.msg_definitions import INT32, MESSAGE_DEFINITIONS

DISCOVERY_TIMEOUT = 5.0  # [s]
POS_TOL = 1e-12  # [rad] float64 fields cross unchanged


def _domain() -> int:
    return random.randint(100, 230)  # other test runs on this machine use other domains


def _spin_until(interface: DdsInterface, done, timeout: float = DISCOVERY_TIMEOUT) -> None:
    end = time.monotonic() + timeout
    while not done() and time.monotonic() < end:
        interface.spin_once()
        time.sleep(0.002)


@pytest.mark.parametrize(
    ("msg_type", "typename"),
    [
        ("sensor_msgs/msg/JointState", "sensor_msgs::msg::dds_::JointState_"),
        ("geometry_msgs/msg/Pose", "geometry_msgs::msg::dds_::Pose_"),
        ("std_msgs/msg/Float32", "std_msgs::msg::dds_::Float32_"),
        ("std_msgs/msg/Float32MultiArray", "std_msgs::msg::dds_::Float32MultiArray_"),
        (INT32, "std_msgs::msg::dds_::Int32_"),
    ],
)
def test_dds_type_names_are_ros2s(msg_type: str, typename: str) -> None:
    assert messages.idl_type(msg_type).__idl_typename__ == typename


def test_topic_names_get_the_rt_prefix() -> None:
    assert messages.dds_topic("/api/left_arm/joint_cmd") == "rt/api/left_arm/joint_cmd"
    for bad in ("api/left", "/api/", "/a//b"):
        with pytest.raises(ConfigError, match="topic"):
            messages.dds_topic(bad)


SAMPLES = {
    "sensor_msgs/msg/JointState": api.joint_cmd("left", np.linspace(-0.5, 0.5, 7)).fields,
    "geometry_msgs/msg/Pose": {
        "position": {"x": 0.3, "y": -0.2, "z": 0.1},
        "orientation": {"x": 0.0, "y": 0.7071067811865476, "z": 0.0, "w": 0.7071067811865476},
    },
    "std_msgs/msg/Float32": {"data": 1.0},
    "std_msgs/msg/Float32MultiArray": {"data": [0.25, -0.5, 0.0]},
    INT32: {"data": 2},
}


@pytest.mark.parametrize("msg_type", sorted(SAMPLES))
def test_cdr_bytes_match_an_independent_ros2_serializer(msg_type: str) -> None:
    """Cyclone's CDR of taplan's structs equals mcap-ros2-support's CDR of the .msg text: the wire layout is ROS 2's."""
    from mcap_ros2._dynamic import serialize_dynamic

    fields = SAMPLES[msg_type]
    ours = bytes(messages.to_idl(msg_type, fields, stamp=12.5).serialize())
    encoder = serialize_dynamic(msg_type, MESSAGE_DEFINITIONS[msg_type])[msg_type]
    theirs = bytes(encoder(bag._ros_dict(msg_type, dict(fields, stamp=12.5), 0)))
    assert ours == theirs


def test_round_trip_over_loopback() -> None:
    domain = _domain()
    sender = DdsInterface(domain, config=loopback_config())
    receiver = DdsInterface(domain, config=loopback_config())
    received: dict[str, list[dict]] = {t: [] for t in SAMPLES}
    publishers = {}
    for msg_type in SAMPLES:
        topic = "/taplan_test/" + msg_type.rsplit("/", 1)[-1].lower()
        receiver.create_subscription(msg_type, topic, received[msg_type].append)
        publishers[msg_type] = sender.create_publisher(msg_type, topic)
    end = time.monotonic() + DISCOVERY_TIMEOUT
    while any(p.matched() == 0 for p in publishers.values()) and time.monotonic() < end:
        time.sleep(0.01)
    for msg_type, fields in SAMPLES.items():
        publishers[msg_type].publish(fields)
    _spin_until(receiver, lambda: all(received.values()))
    joint = received["sensor_msgs/msg/JointState"][0]
    sent = SAMPLES["sensor_msgs/msg/JointState"]
    assert joint["name"] == sent["name"]
    np.testing.assert_allclose(joint["position"], sent["position"], atol=POS_TOL)
    assert abs(joint["stamp"] - time.time()) < 5.0  # header stamped with the wall clock [s]
    assert received["geometry_msgs/msg/Pose"][0] == SAMPLES["geometry_msgs/msg/Pose"]
    assert received["std_msgs/msg/Float32"][0] == {"data": 1.0}
    assert received["std_msgs/msg/Float32MultiArray"][0] == {"data": [0.25, -0.5, 0.0]}
    assert received[INT32][0] == {"data": 2}
    sender.close()
    receiver.close()


def test_domain_id_from_argument_and_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "29")
    assert domain_id_from_environment() == 29
    monkeypatch.setenv("ROS_DOMAIN_ID", "robot")
    with pytest.raises(InvalidInputError, match="ROS_DOMAIN_ID"):
        domain_id_from_environment()
    monkeypatch.delenv("ROS_DOMAIN_ID")
    assert domain_id_from_environment() == 0
    with pytest.raises(InvalidInputError, match="domain_id"):
        DdsInterface(400)


def test_unsupported_message_type_is_refused() -> None:
    interface = DdsInterface(_domain(), config=loopback_config())
    with pytest.raises(ConfigError, match="supported"):
        interface.create_publisher("std_msgs/msg/String", "/x")
    interface.close()


def test_bag_round_trip_and_run_streams(tmp_path) -> None:
    path = tmp_path / "run.mcap"
    start = time.time_ns()
    with bag.BagWriter(path) as writer:
        for k in range(20):
            t = start + k * 13_000_000
            for side in api.SIDES:
                q = np.full(7, 0.01 * k) * (1 if side == "left" else -1)
                writer.record(api.Topics.joint_cmd(side), api.JOINT_STATE, api.joint_cmd(side, q).fields, t)
            if k % 4 == 0:
                writer.record(api.Topics.ENABLE, api.FLOAT32, api.fsm_enable().fields, t)
        writer.record(api.Topics.joint_cmd("left"), api.JOINT_STATE, {"name": ["x"], "position": [0.0]}, t)
        writer.record("/fsm_state", INT32, {"data": 2}, t)
    run = bag.read_run(path)
    assert run.rejected == 1  # the message with a wrong joint name
    stream = run.stream("commanded")
    assert stream.joint_names == api.ARM_JOINT_NAMES["left"] + api.ARM_JOINT_NAMES["right"]
    np.testing.assert_allclose(stream.positions[:, 0], 0.01 * np.arange(20), atol=1e-12)
    np.testing.assert_allclose(stream.positions[:, 7], -0.01 * np.arange(20), atol=1e-12)
    np.testing.assert_allclose(run.heartbeat_gaps, 0.052, atol=1e-9)  # [s]
    assert run.fsm_states == [(pytest.approx(19 * 0.013), 2)]


def test_bad_bag_files(tmp_path) -> None:
    with pytest.raises(InvalidInputError, match="bag"):
        bag.read_run(tmp_path / "missing.mcap")
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(b"not an mcap file")
    with pytest.raises(InvalidInputError, match="readable rosbag2"):
        bag.read_run(broken)
