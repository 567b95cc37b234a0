"""Perception over the ROS link: Image / CameraInfo / PointCloud2 layouts (CDR checked against an independent
serializer), PointCloud2 decoding, the live PerceptionLink (with bad messages), the simulated depth cameras, a
runner stopped smoothly by a broken camera stream, and a scene built from a recorded bag."""

from __future__ import annotations

import struct

import numpy as np
import pytest

import taplan
from taplan import api
from taplan.errors import InvalidInputError
from taplan.ros import bag, messages
from taplan.ros.bag_perception import perceive_bag
from taplan.ros.interface import FakeRosInterface
from taplan.ros.msg_definitions import MESSAGE_DEFINITIONS
from taplan.ros.perception_link import PerceptionLink
from taplan.ros.runner import Runner, RunnerConfig
from taplan.ros.sim import SimulatedRobot
from taplan.ros.sim_depth import DepthCameraSim
from taplan.scene import Box, CollisionWorld, Perception, Scene
from taplan.scene.camera import TELEAVATAR_DEPTH_TOPICS, PinholeCamera, add_camera_frames
from taplan.scene.pointcloud import cloud_to_points, points_to_cloud
from taplan.scene.raycast import depth_to_16uc1, render_depth

TINY = PinholeCamera(64, 48, 33.7, 33.7, 32.0, 24.0)  # the wrist camera's field of view at 1/10 resolution
POINT_TOL = 1e-6  # [m] float32 coordinates


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _in_view(robot: taplan.Robot) -> Scene:
    """A 30 cm cube 50 cm in front of each wrist camera at home."""
    add_camera_frames(robot)
    scene = Scene()
    for frame in ("left_depth_camera", "right_depth_camera"):
        T = robot.frame_pose(robot.home, frame)
        scene.add(frame + "_box", Box((0.3, 0.3, 0.3)), ((T[:3, :3] @ [0, 0, 0.5] + T[:3, 3]).tolist(), [0, 0, 0, 1]))
    return scene


def _box_distance(scene: Scene, points: np.ndarray) -> np.ndarray:
    """Distance [m] of each point to the nearest (axis-aligned) box of ``scene``."""
    return np.min(
        [
            np.linalg.norm(np.maximum(np.abs(points - o.pose[:3, 3]) - np.asarray(o.shape.size) / 2, 0), axis=1)
            for o in scene.obstacles.values()
        ],
        axis=0,
    )


SENSOR_SAMPLES = {
    "sensor_msgs/msg/Image": {
        "frame_id": "left_depth_camera",
        "height": 2,
        "width": 3,
        "encoding": "16UC1",
        "is_bigendian": 0,
        "step": 6,
        "data": bytes(range(12)),
    },
    "sensor_msgs/msg/CameraInfo": dict(
        TINY.to_camera_info(),
        frame_id="right_depth_camera",
        binning_x=0,
        binning_y=0,
        roi={"x_offset": 1, "y_offset": 2, "height": 3, "width": 4, "do_rectify": True},
    ),
    "sensor_msgs/msg/PointCloud2": points_to_cloud([[0.1, 0.2, 0.3], [np.nan, 0.0, 1.0]], "base_link"),
}


@pytest.mark.parametrize("msg_type", sorted(SENSOR_SAMPLES))
def test_sensor_messages_are_ros2s_on_the_wire(msg_type: str) -> None:
    """Cyclone's CDR of taplan's structs equals mcap-ros2-support's CDR of the .msg text, and reads back."""
    from mcap_ros2._dynamic import serialize_dynamic

    name = msg_type.rsplit("/", 1)[-1]
    assert messages.idl_type(msg_type).__idl_typename__ == f"sensor_msgs::msg::dds_::{name}_"
    fields = SENSOR_SAMPLES[msg_type]
    ours = bytes(messages.to_idl(msg_type, fields, stamp=12.5).serialize())
    encoder = serialize_dynamic(msg_type, MESSAGE_DEFINITIONS[msg_type])[msg_type]
    assert ours == bytes(encoder(bag._ros_dict(msg_type, dict(fields, stamp=12.5), 0)))
    back = messages.from_idl(msg_type, messages.idl_type(msg_type).deserialize(ours))
    assert back["stamp"] == 12.5
    for key, value in fields.items():
        if key != "stamp":
            assert back[key] == value or (isinstance(value, float) and np.isnan(value)), key


def test_point_clouds_decode_any_layout() -> None:
    rng = np.random.default_rng(0)
    points = rng.uniform(-1, 1, (12, 3))
    np.testing.assert_allclose(cloud_to_points(points_to_cloud(points)), points, atol=POINT_TOL)
    # an organised 3x4 cloud, big-endian float64 x, y, z after a 4-byte rgb field, rows padded by 8 bytes
    point_step, row_step = 4 + 24, 4 * 28 + 8
    rows = []
    for r in range(3):
        row = b"".join(struct.pack(">I3d", 0xFF00FF, *points[4 * r + c]) for c in range(4))
        rows.append(row + b"\0" * 8)
    layout = [{"name": "rgb", "offset": 0, "datatype": 6, "count": 1}]
    layout += [{"name": a, "offset": 4 + 8 * i, "datatype": 8, "count": 1} for i, a in enumerate("xyz")]
    cloud = {
        "height": 3,
        "width": 4,
        "fields": layout,
        "is_bigendian": True,
        "point_step": point_step,
        "row_step": row_step,
        "data": b"".join(rows),
    }
    np.testing.assert_allclose(cloud_to_points(cloud), points, atol=1e-15)
    assert len(cloud_to_points(points_to_cloud([[np.nan, 0.0, 0.0], [0.0, 0.0, 1.0]]))) == 1  # NaN points dropped
    for change, field in (
        ({"fields": layout[:3]}, r"cloud\.fields"),
        ({"fields": [dict(f, datatype=9) for f in layout]}, r"cloud\.fields\.x\.datatype"),
        ({"data": b"\0" * 10}, r"cloud\.data"),
        ({"point_step": 0}, r"cloud\.point_step"),
    ):
        with pytest.raises(InvalidInputError, match=field):
            cloud_to_points(dict(cloud, **change))


class LoopInterface(FakeRosInterface):
    """An in-process ROS graph on a manual clock: publications reach the subscriptions, JointStates get the
    clock as their header stamp (as DdsInterface stamps them), ``spin_once`` steps the simulated devices, and
    everything may be recorded to a bag."""

    def __init__(self, recorder: bag.BagWriter | None = None) -> None:
        super().__init__(start=100.0)
        self.devices: list = []
        self.recorder = recorder

    def create_publisher(self, msg_type: str, topic: str):
        publisher = super().create_publisher(msg_type, topic)
        interface = self

        class Publisher:
            def publish(self, fields: dict) -> None:
                fields = dict(fields)
                fields.setdefault("stamp", interface.time)
                publisher.publish(fields)
                if interface.recorder is not None:
                    interface.recorder.record(topic, msg_type, fields, int(interface.time * 1e9))
                interface.deliver(topic, fields)

        return Publisher()

    def spin_once(self) -> int:
        for device in self.devices:
            device(self.time)
        return 0


def _link(robot: taplan.Robot, interface: LoopInterface, **options) -> PerceptionLink:
    perception = Perception(robot)
    return PerceptionLink(interface, perception, clock=interface.now, **options)


def test_the_link_fuses_images_and_clouds_and_logs_bad_ones(robot, caplog) -> None:
    interface = LoopInterface()
    link = _link(robot, interface, clouds={"/points": None})
    for side in api.SIDES:  # the joint history: home at t = 99.9 and 100.1
        for stamp in (99.9, 100.1):
            q = robot.home[robot.group(side).indices]
            interface.deliver(
                api.Topics.joint_states(side),
                {"name": list(api.ARM_JOINT_NAMES[side]), "position": list(q), "stamp": stamp},
            )
    image_topic, info_topic = TELEAVATAR_DEPTH_TOPICS["left_depth_camera"]
    T = robot.frame_pose(robot.home, "left_depth_camera")
    scene = _in_view(robot)
    depth = render_depth(TINY, T, scene)
    assert np.count_nonzero(np.isfinite(depth)) > 500  # the left camera sees its cube
    image = {
        "stamp": 100.0,
        "frame_id": "ignored_optical_frame",
        "height": TINY.height,
        "width": TINY.width,
        "encoding": "16UC1",
        "is_bigendian": 0,
        "step": 2 * TINY.width,
        "data": depth_to_16uc1(depth).tobytes(),
    }
    interface.deliver(image_topic, image)
    assert link.rejected == {"no_camera_info": 1}
    interface.deliver(info_topic, dict(TINY.to_camera_info(), stamp=100.0))
    interface.deliver(image_topic, image)
    assert link.integrated == 1
    occupancy = link.perception.scene.obstacles["perceived"].shape
    assert len(occupancy) > 20 and np.all(_box_distance(scene, occupancy.centers()) <= 0.02 * 1.5)
    interface.deliver("/points", points_to_cloud([[0.5, 0.0, 0.3]], stamp=100.05))
    assert link.integrated == 2 and len(link.perception.scene.obstacles["perceived"].shape) == len(occupancy) + 1
    caplog.set_level("WARNING")
    bad = [
        (image_topic, dict(image, encoding="rgb8")),
        (image_topic, dict(image, width=TINY.width // 2)),
        (image_topic, dict(image, data=image["data"][:-2])),
        (image_topic, dict(image, stamp=50.0)),  # before the joint history
        (info_topic, dict(TINY.to_camera_info(), k=[np.nan] * 9)),
        ("/points", points_to_cloud([[0.5, 0.0, 0.3]], frame_id="no_such_frame", stamp=100.05)),
    ]
    for topic, fields in bad:
        interface.deliver(topic, fields)  # never raises into the loop
    assert link.integrated == 2
    assert sum(link.rejected.values()) == 1 + len(bad)
    for field in ("encoding", "image.width", "data", "stamp", r"camera_info.k", "no_such_frame"):
        assert any(field in r.getMessage() for r in caplog.records), field
    assert link.monitor() is None
    interface.advance(1.5)
    assert "no depth image for 1.50 s" in link.monitor()


def test_a_broken_camera_stream_stops_a_run_smoothly(robot) -> None:
    interface = LoopInterface()
    sim = SimulatedRobot(interface, robot)
    cameras = DepthCameraSim(interface, sim, _in_view(robot), camera=TINY, rate=5.0, clock=interface.now)
    link = _link(robot, interface, stale_after=0.5)
    broken_at = 102.0  # [s] the cameras stop while the arm moves
    interface.devices += [sim.step, lambda now: cameras.step(now) if now < broken_at else 0]
    runner = Runner(
        interface,
        robot,
        config=RunnerConfig(ready_timeout=2.0),
        clock=interface.now,
        sleep=lambda dt: interface.advance(max(dt, 1e-4)),
        monitors=(link.monitor,),
    )
    left = robot.group("left").indices

    def target(t: float) -> np.ndarray:  # the left arm keeps moving: the stop has to brake it
        q = robot.home.copy()
        q[left] += 0.3 * np.sin(1.5 * t)
        return q

    result = runner.stream(target, duration=6.0)
    assert link.integrated >= 4 and "perceived" in link.perception.scene.obstacles
    assert result.status == "stopped" and "no depth image" in result.reason
    assert result.sent_times[-1] < 4.0  # [s] the run ended well before its 6 s
    velocity = np.diff(result.sent, axis=0) / runner.period  # finite differences at the arm period [rad/s]
    assert np.all(np.abs(velocity) <= robot.planning_limits.velocity * 1.01 + 1e-9)
    acceleration = np.diff(velocity, axis=0) / runner.period
    assert np.all(np.abs(acceleration) <= robot.planning_limits.acceleration * 1.05 + 1e-6)
    braking = result.sent_times >= result.sent_times[-1] - 0.3
    assert np.abs(velocity[braking[1:]]).max() > 0.05  # it was moving when the stream broke [rad/s]
    assert np.abs(velocity[-1]).max() < 0.02  # and is at rest at the end [rad/s]


def test_scene_from_a_recorded_bag(robot, tmp_path) -> None:
    path = tmp_path / "run.mcap"
    with bag.BagWriter(path) as writer:
        interface = LoopInterface(recorder=writer)
        sim = SimulatedRobot(interface, robot)
        cameras = DepthCameraSim(interface, sim, _in_view(robot), camera=TINY, rate=5.0, clock=interface.now)
        for _ in range(120):  # 1.2 s: joint states at 100 Hz, 6 image pairs
            sim.step(interface.time)
            cameras.step(interface.time)
            interface.advance(0.01)
    topics = {topic for topic, _, _ in bag.read_messages(path)}
    assert {"/left/depth/image_raw", "/right/depth/camera_info", "/left_arm/joint_states"} <= topics
    result = perceive_bag(robot, path)
    assert result.images == cameras.published and not result.skipped
    seen = result.perception.scene
    occupancy = seen.obstacles["perceived"].shape
    assert len(occupancy) > 50
    assert np.all(_box_distance(_in_view(robot), occupancy.centers()) <= 0.02 * 1.5)  # on the boxes, not the arms
    world = CollisionWorld(robot, seen)
    assert not world.in_collision(robot.home)
    empty = tmp_path / "empty.mcap"
    with bag.BagWriter(empty) as writer:
        writer.record("/fsm_state", "std_msgs/msg/Int32", {"data": 2}, 1)
    with pytest.raises(InvalidInputError, match="bag"):
        perceive_bag(robot, empty)


def _record_cameras(robot: taplan.Robot, path, scene: Scene, seconds: float = 1.2) -> None:
    """A bag of the simulated robot at home and its wrist cameras seeing ``scene`` (5 Hz, TINY)."""
    with bag.BagWriter(path) as writer:
        interface = LoopInterface(recorder=writer)
        sim = SimulatedRobot(interface, robot)
        cameras = DepthCameraSim(interface, sim, scene, camera=TINY, rate=5.0, clock=interface.now)
        for _ in range(int(seconds / 0.01)):
            sim.step(interface.time)
            cameras.step(interface.time)
            interface.advance(0.01)


def test_plan_scene_from_bag_avoids_what_the_cameras_saw(robot, tmp_path, capsys) -> None:
    from taplan.cli import main
    from taplan.planning import verify_trajectory

    scene = _in_view(robot)
    record = tmp_path / "run.mcap"
    _record_cameras(robot, record, scene)
    home = robot.home[:7]
    waypoints = tmp_path / "waypoints.csv"
    header = ",".join(f"l_joint{i}" for i in range(1, 8))
    np.savetxt(
        waypoints,
        np.array([home, home + [0.4, 0.2, 0.0, -0.3, 0.0, 0.2, 0.0]]),
        delimiter=",",
        header=header,
        comments="",
    )
    out = tmp_path / "planned.json"
    assert main(["plan", str(waypoints), "--scene-from-bag", str(record), "-o", str(out)]) == 0
    assert "occupied voxels" in capsys.readouterr().out
    trajectory = taplan.Trajectory.load(out)
    verdict = verify_trajectory(CollisionWorld(robot, scene), trajectory, floor=0.0)  # against the true cubes
    assert verdict.collision_free
    assert main(["plan", str(waypoints), "--scene-from-bag", str(tmp_path / "missing.mcap")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("taplan plan: error: bag") and err.count("\n") == 1


def test_sim_depth_needs_a_scene(capsys) -> None:
    from taplan.cli import main

    assert main(["sim", "--depth", "--loopback", "--duration", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "--depth" in err and "--scene" in err and err.count("\n") == 1


def test_sensor_messages_cross_dds_loopback() -> None:
    import random
    import time

    from taplan.ros.dds import DdsInterface, loopback_config

    domain = random.randint(100, 230)
    sender = DdsInterface(domain, config=loopback_config())
    receiver = DdsInterface(domain, config=loopback_config())
    received: dict[str, list[dict]] = {t: [] for t in SENSOR_SAMPLES}
    publishers = {}
    for msg_type in SENSOR_SAMPLES:
        topic = "/taplan_test/" + msg_type.rsplit("/", 1)[-1].lower()
        receiver.create_subscription(msg_type, topic, received[msg_type].append)
        publishers[msg_type] = sender.create_publisher(msg_type, topic)
    end = time.monotonic() + 5.0
    while any(p.matched() == 0 for p in publishers.values()) and time.monotonic() < end:
        time.sleep(0.01)
    big = dict(SENSOR_SAMPLES["sensor_msgs/msg/Image"], height=480, width=640, step=1280, data=bytes(614400))
    for msg_type, fields in SENSOR_SAMPLES.items():
        publishers[msg_type].publish(dict(big if msg_type.endswith("Image") else fields, stamp=7.25))
    end = time.monotonic() + 5.0
    while not all(received.values()) and time.monotonic() < end:
        receiver.spin_once()
        time.sleep(0.002)
    assert received["sensor_msgs/msg/Image"][0]["data"] == big["data"]  # a full 640x480 16UC1 frame
    assert received["sensor_msgs/msg/CameraInfo"][0]["k"] == SENSOR_SAMPLES["sensor_msgs/msg/CameraInfo"]["k"]
    cloud = received["sensor_msgs/msg/PointCloud2"][0]
    assert cloud["stamp"] == 7.25 and cloud["frame_id"] == "base_link"
    np.testing.assert_allclose(cloud_to_points(cloud), [[0.1, 0.2, 0.3]], atol=POINT_TOL)
    sender.close()
    receiver.close()


def test_taplan_sim_publishes_depth_images_a_link_fuses(robot, tmp_path) -> None:
    """The whole loop without a robot: `taplan sim --scene table.yaml --depth` in its own process, a
    PerceptionLink here, real DDS on 127.0.0.1."""
    import os
    import random
    import subprocess
    import sys
    import time
    from pathlib import Path

    from taplan.ros.dds import DdsInterface, loopback_config

    scene_file = Path(__file__).resolve().parents[1] / "models" / "teleavatar" / "scenes" / "table.yaml"
    domain = random.randint(100, 230)
    command = [sys.executable, "-m", "taplan", "sim", "--loopback", "--domain-id", str(domain), "--duration", "60"]
    command += ["--scene", str(scene_file), "--depth", "--depth-rate", "4"]
    log = tmp_path / "sim.log"
    with open(log, "w") as out:
        process = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, env=dict(os.environ))
    interface = DdsInterface(domain, config=loopback_config())
    try:
        link = PerceptionLink(interface, Perception(robot))
        end = time.monotonic() + 45.0  # the sim imports taplan and pinocchio first
        while link.integrated < 4 and time.monotonic() < end and process.poll() is None:
            interface.spin_once()
            time.sleep(0.005)
        assert link.integrated >= 4, (link.rejected, log.read_text())
        assert link.infos["left_depth_camera"].width == 160  # the quarter-size default
        assert "perceived" in link.perception.scene.obstacles
    finally:
        interface.close()
        process.terminate()
        process.wait(timeout=20)


def test_taplan_run_records_the_cameras_and_a_bag_gives_the_scene(robot, tmp_path, capsys) -> None:
    """`taplan run --cameras --bag` against `taplan sim --scene --depth`: the bag holds the depth images and
    camera infos, and `perceive_bag` builds the scene from it."""
    import os
    import random
    import subprocess
    import sys
    from pathlib import Path

    from taplan.cli import main

    scene_file = Path(__file__).resolve().parents[1] / "models" / "teleavatar" / "scenes" / "table.yaml"
    domain = str(random.randint(100, 230))
    command = [sys.executable, "-m", "taplan", "sim", "--loopback", "--domain-id", domain, "--duration", "90"]
    command += ["--scene", str(scene_file), "--depth", "--depth-rate", "4"]
    with open(tmp_path / "sim.log", "w") as out:
        process = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, env=dict(os.environ))
    record = tmp_path / "run.mcap"
    try:
        code = main(
            ["run", "--loopback", "--domain-id", domain, "--hold", "2", "--cameras", "--wait", "60"]
            + ["--camera-timeout", "5", "--bag", str(record), "--state-timeout", "2"]
        )
    finally:
        process.terminate()
        process.wait(timeout=20)
    assert code == 0, capsys.readouterr()
    topics = [topic for topic, _, _ in bag.read_messages(record)]
    assert topics.count("/left/depth/image_raw") >= 2 and "/right/depth/camera_info" in topics
    result = perceive_bag(robot, record)
    assert result.images >= 4 and "perceived" in result.perception.scene.obstacles
