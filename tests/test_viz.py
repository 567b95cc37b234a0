"""taplan.viz without a browser: scene-graph content (node names, poses against FK), closest pair, limits, sources
(trajectory files, bags, live joint states), playback, the self-contained page and bad input."""

from __future__ import annotations

import base64
import contextlib
import io
import re
import socket
import subprocess
import sys
import time
import urllib.request

import numpy as np
import pinocchio as pin
import pytest

import taplan
from taplan import api, viz
from taplan.errors import InvalidInputError
from taplan.scene import Box, CollisionWorld, Mesh, Scene, Sphere
from taplan.trajectory import Trajectory
from taplan.viz.geometry import capsule_mesh, segment_pose, wxyz
from taplan.viz.sources import LiveFollower, motions_from_bag

POSE_TOL = 1e-6  # [m] node poses against pinocchio's FK (float64 end to end)
ROT_TOL = 1e-6  # rotation matrix entries
RATIO_TOL = 0.005  # limit ratios are printed as whole percent: half a percent


def _motion(robot: taplan.Robot, duration: float = 2.0) -> Trajectory:
    """The right arm swings by ``amp`` rad along (1 - cos) profiles; analytic velocities and accelerations."""
    t = np.linspace(0.0, duration, 41)
    amp = np.zeros(robot.nq)
    amp[robot.group("right").indices] = [0.5, -0.6, 0.3, -0.8, 0.2, 0.3, 0.1]
    w = np.pi / duration
    shape = (1 - np.cos(w * t))[:, None]
    q = robot.home + amp * shape
    v = amp * (w * np.sin(w * t))[:, None]
    a = amp * (w * w * np.cos(w * t))[:, None]
    return Trajectory(t, q, v, a, robot.joint_names)


def _scene() -> Scene:
    scene = Scene()
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    scene.add("ball", Sphere(0.05), ([0.45, -0.35, -0.15], [0, 0, 0, 1]))
    tetra = Mesh(
        np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]),
        np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]),
    )
    scene.add("tetra", tetra, ([0.4, 0.4, -0.3], [0, 0, 0, 1]))
    scene.attach("tool", Box((0.03, 0.03, 0.1)), "right_ee", ([0, 0, 0.05], [0, 0, 0, 1]))
    return scene


@pytest.fixture(scope="module")
def viewer(teleavatar):
    with contextlib.redirect_stdout(io.StringIO()):
        v = viz.Viewer(teleavatar, _scene(), viz.motions_of(teleavatar, [_motion(teleavatar)]), port=0)
    yield v
    with contextlib.redirect_stdout(io.StringIO()):
        v.close()


def _rotation(T: np.ndarray) -> np.ndarray:
    return T[:3, :3]


def test_scene_graph_names_every_joint_body_hand_obstacle_and_path(viewer, teleavatar) -> None:
    names = set(viewer.nodes())
    world = CollisionWorld(teleavatar, _scene())
    for joint in teleavatar.joint_names:
        assert f"/robots/plan/{joint}" in names
    for body in world.bodies:  # whatever bodies the world reports, under the joint that carries them
        assert f"/robots/plan/{teleavatar.model.names[body.joint]}/{body.name}" in names
    assert {"/robots/plan/l_joint7/hand_left_ee", "/robots/plan/r_joint7/hand_right_ee"} <= names
    assert "/robots/plan/r_joint7/tool" in names  # the attached object rides with the hand
    assert {"/scene/table", "/scene/ball", "/scene/tetra"} <= names
    assert {"/paths/plan/left_ee", "/paths/plan/right_ee", "/closest/plan"} <= names


@pytest.mark.parametrize("t", [0.0, 0.37, 1.0, 1.81, 2.0])
def test_node_poses_match_forward_kinematics(viewer, teleavatar, t) -> None:
    viewer.set_time(t)
    q = _motion(teleavatar)(t)
    model, data = teleavatar.model, teleavatar.model.createData()
    pin.forwardKinematics(model, data, q)
    for j, joint in enumerate(teleavatar.joint_names, start=1):
        T = viewer.world_pose(f"/robots/plan/{joint}")
        np.testing.assert_allclose(T[:3, 3], data.oMi[j].translation, atol=POSE_TOL)
        np.testing.assert_allclose(_rotation(T), data.oMi[j].rotation, atol=ROT_TOL)
    for body in viewer.world.bodies:
        T = viewer.world_pose(f"/robots/plan/{model.names[body.joint]}/{body.name}")
        M = data.oMi[body.joint]
        # a capsule's drawn axis runs between its segment's end points
        half = np.linalg.norm(body.end - body.start) / 2
        np.testing.assert_allclose(T[:3, 3] + half * T[:3, 2], M.act(body.end), atol=POSE_TOL)
        np.testing.assert_allclose(T[:3, 3] - half * T[:3, 2], M.act(body.start), atol=POSE_TOL)
    for frame in ("left_ee", "right_ee"):
        parent = model.names[model.frames[teleavatar.frame_id(frame)].parentJoint]
        T = viewer.world_pose(f"/robots/plan/{parent}/hand_{frame}")
        np.testing.assert_allclose(T, teleavatar.frame_pose(q, frame), atol=POSE_TOL)


def test_swept_paths_follow_the_hands(viewer, teleavatar) -> None:
    segments = viewer.nodes()["/paths/plan/right_ee"].points
    motion = _motion(teleavatar)
    for k in (0, len(segments) // 2, len(segments) - 1):
        t = 2.0 * k / len(segments)
        np.testing.assert_allclose(segments[k, 0], teleavatar.frame_pose(motion(t), "right_ee")[:3, 3], atol=1e-5)


def test_closest_pair_and_clearance_match_an_independent_evaluation(viewer, teleavatar) -> None:
    world = CollisionWorld(teleavatar, _scene())
    for t in (0.0, 1.3):
        viewer.set_time(t)
        d = world.distances(_motion(teleavatar)(t), jacobian=False)
        k = int(np.argmin(d.distance))
        text = viewer.gui["plan/closest"].content
        assert f"{d.pairs[k][0]} / {d.pairs[k][1]}" in text
        shown = float(re.search(r"\*\*([-0-9.]+) mm\*\*", text).group(1))
        assert shown == pytest.approx(1e3 * d.distance[k], abs=0.05)  # printed to 0.1 mm
        segment, label = viewer._closest["plan"]
        np.testing.assert_allclose(segment.points[0], [d.point_a[k], d.point_b[k]], atol=1e-6)
        assert label.text == f"{1e3 * d.distance[k]:.1f} mm"
        obstacle = min(
            (i for i, p in enumerate(d.pairs) if p[1] in {"table", "ball", "tetra"}), key=lambda i: d.distance[i]
        )
        line = f"to the scene: {d.pairs[obstacle][0]} / {d.pairs[obstacle][1]}: {1e3 * d.distance[obstacle]:.1f} mm"
        assert line in text
        highlighted = [h for h in (viewer._node_of("plan", m) for m in d.pairs[k]) if h is not None]
        assert highlighted and all(tuple(h.color) == (230, 40, 40) for h in highlighted)
    others = [h for n, h in viewer.robots["plan"].bodies.items() if n not in d.pairs[k]]
    assert all(tuple(h.color) != (230, 40, 40) for h in others)  # the previous pair was restored


def test_velocity_and_acceleration_ratios_against_the_limits(viewer, teleavatar) -> None:
    t = 0.6
    viewer.set_time(t)
    motion = _motion(teleavatar)
    v, a = motion(t, 1), motion(t, 2)
    rows = {
        m.group(1): (float(m.group(2)) / 100, float(m.group(3)) / 100)
        for m in re.finditer(r"\| (\w+)(?: ⚠)? \| (\d+) % \| (\d+) % \|", viewer.gui["plan/limits"].content)
    }
    assert set(rows) == set(teleavatar.joint_names)
    for i, joint in enumerate(teleavatar.joint_names):
        assert rows[joint][0] == pytest.approx(abs(v[i]) / teleavatar.limits.velocity[i], abs=RATIO_TOL)
        assert rows[joint][1] == pytest.approx(abs(a[i]) / teleavatar.limits.acceleration[i], abs=RATIO_TOL)


def test_over_the_limit_is_marked(teleavatar) -> None:
    fast = _motion(teleavatar, duration=0.2)  # the same swing 10x faster: 100x the accelerations
    with (
        contextlib.redirect_stdout(io.StringIO()),
        viz.Viewer(teleavatar, None, viz.motions_of(teleavatar, [fast]), port=0) as v,
    ):
        v.set_time(0.0)
        marked = re.findall(r"\| (\w+) ⚠", v.gui["plan/limits"].content)
    a = np.abs(fast(0.0, 2)) / teleavatar.limits.acceleration
    assert set(marked) == {teleavatar.joint_names[i] for i in np.flatnonzero(a > 1.0)} and marked


def test_playback_advances_at_speed_and_loops(viewer) -> None:
    viewer.pause()
    viewer.set_time(0.5)
    viewer.speed = 2.0
    viewer.advance(0.25)
    assert viewer.time == pytest.approx(1.0)
    viewer.advance(0.75)  # 1.0 + 1.5 = 2.5 -> loops to 0.5
    assert viewer.time == pytest.approx(0.5)
    viewer.loop = False
    viewer.advance(10.0)
    assert viewer.time == pytest.approx(2.0) and not viewer.playing
    viewer.loop, viewer.speed = True, 1.0
    viewer.play()  # at the end: starts over
    assert viewer.time == pytest.approx(0.0) and viewer.playing
    deadline = time.monotonic() + 20.0
    while viewer.time < 0.2 and time.monotonic() < deadline:
        time.sleep(0.02)  # the server thread plays by itself
    viewer.pause()
    time.sleep(0.1)  # an update in flight completes
    with viewer._lock:
        assert viewer.time >= 0.2
        assert viewer.gui["time"].value == pytest.approx(viewer.time)


def test_slider_moved_by_a_person_sets_the_time(viewer) -> None:
    class Person:  # what viser passes for a browser's event: any client object
        client_id = 1

    slider = viewer.gui["time"]
    slider._impl.value = 1.25
    for callback in slider._impl.update_cb:
        callback(type("Event", (), {"client": Person(), "target": slider})())
    assert viewer.time == pytest.approx(1.25)
    np.testing.assert_allclose(viewer.world_pose("/robots/plan/r_joint7")[:3, 3], _fk_joint(viewer, 1.25), atol=1e-9)


def _fk_joint(viewer, t: float) -> np.ndarray:
    robot = viewer.robot
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, _motion(robot)(t))
    return data.oMi[robot.model.getJointId("r_joint7")].translation


def test_self_contained_page_holds_the_client_and_the_recorded_motion(viewer) -> None:
    page = viewer.html(rate=10.0)
    assert page.startswith("<!doctype html>") and "<script" in page
    data = re.search(r'__VISER_EMBED_DATA__="([A-Za-z0-9+/=]+)"', page).group(1)
    recording = base64.b64decode(data)
    inner = int.from_bytes(recording[:8], "little")
    import zstandard

    payload = zstandard.ZstdDecompressor().decompress(recording[8:], max_output_size=inner)
    import msgspec

    header = int.from_bytes(payload[:8], "little")
    meta = msgspec.msgpack.decode(payload[8 : 8 + header])
    assert meta["durationSeconds"] == pytest.approx(2.0, abs=0.1)  # the whole motion, 10 frames a second
    stamps = [t for t, _ in meta["messages"]]
    assert max(stamps) == pytest.approx(2.0, abs=0.1) and len(set(stamps)) >= 20


def test_write_html_creates_parents(tmp_path, teleavatar) -> None:
    with contextlib.redirect_stdout(io.StringIO()):
        path = viz.write_html(tmp_path / "a" / "b" / "plan.html", _motion(teleavatar), scene=_scene(), rate=5)
    assert path.is_file() and path.stat().st_size > 100_000 and "__VISER_EMBED_DATA__" in path.read_text()


def test_a_trajectory_of_some_joints_holds_the_others_at_home(teleavatar) -> None:
    right = _motion(teleavatar).select(teleavatar.group("right").joint_names)
    motion = viz.Motion.from_trajectory(teleavatar, right)
    q, v, _ = motion.joints(1.0)
    left = teleavatar.group("left").indices
    np.testing.assert_array_equal(q[left], teleavatar.home[left])
    np.testing.assert_array_equal(v[left], 0.0)
    np.testing.assert_allclose(q[teleavatar.group("right").indices], right(1.0), atol=1e-12)


def test_bad_input_is_named(teleavatar) -> None:
    alien = Trajectory([0, 1], [[0.0, 0.0], [1.0, 1.0]], joint_names=("r_joint1", "elbow_x"))
    with pytest.raises(InvalidInputError, match="elbow_x"):
        viz.Motion.from_trajectory(teleavatar, alien)
    with pytest.raises(InvalidInputError, match="trajectory joints"):
        viz.Motion.from_trajectory(teleavatar, Trajectory([0, 1], [[0.0], [1.0]]))
    with pytest.raises(InvalidInputError, match="port"):
        viz.check_port("127.0.0.1", 70000)
    with pytest.raises(InvalidInputError, match="scene"):
        viz.Viewer(teleavatar, "table.yaml", port=0)  # type: ignore[arg-type]
    with pytest.raises(InvalidInputError, match="motions"):
        viz.Viewer(teleavatar, None, [], port=0)


def test_a_port_in_use_is_refused_in_one_line(teleavatar) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        with pytest.raises(InvalidInputError, match=f"{port} is in use"):
            viz.Viewer(teleavatar, None, viz.motions_of(teleavatar, [_motion(teleavatar)]), port=port)


def test_bag_shows_commanded_and_measured_side_by_side(tmp_path, teleavatar) -> None:
    from taplan.ros import bag

    path = tmp_path / "run.mcap"
    start = 1_000_000_000
    with bag.BagWriter(path) as writer:
        for k in range(30):
            t = start + k * 10_000_000
            for side in api.SIDES:
                q = np.full(7, 0.02 * k) * (1 if side == "left" else -1)
                writer.record(api.Topics.joint_cmd(side), api.JOINT_STATE, api.joint_cmd(side, q).fields, t)
                fields = {
                    "name": list(api.ARM_JOINT_NAMES[side]),
                    "position": list(0.9 * q),
                    "velocity": [],
                    "effort": [],
                }
                writer.record(api.Topics.joint_states(side), api.JOINT_STATE, fields, t + 3_000_000)
    motions = motions_from_bag(teleavatar, path)
    assert [m.name for m in motions] == ["commanded", "measured"]
    q_cmd, v_cmd, _ = motions[0].joints(0.10)
    left = teleavatar.indices(api.ARM_JOINT_NAMES["left"])
    np.testing.assert_allclose(q_cmd[left], 0.2, atol=1e-9)  # sample 10 at 0.10 s
    np.testing.assert_allclose(v_cmd[left], 2.0, atol=1e-6)  # 0.02 rad per 10 ms
    q_meas, _, _ = motions[1].joints(0.103)
    np.testing.assert_allclose(q_meas[left], 0.9 * 0.2, atol=1e-9)
    with contextlib.redirect_stdout(io.StringIO()), viz.Viewer(teleavatar, None, motions, port=0) as v:
        assert {"/robots/commanded/l_joint1", "/robots/measured/l_joint1"} <= set(v.nodes())
        v.set_time(0.2)
        a = v.world_pose("/robots/commanded/l_joint7")[:3, 3]
        b = v.world_pose("/robots/measured/l_joint7")[:3, 3]
        assert np.linalg.norm(a - b) > 1e-3  # the measured arm lags: drawn where it was
    with pytest.raises(InvalidInputError, match="bag"):
        motions_from_bag(teleavatar, tmp_path / "missing.mcap")


def test_live_joint_states_pose_the_live_robot(teleavatar) -> None:
    class Interface:  # the subscription side of DdsInterface
        def __init__(self):
            self.callbacks = {}

        def create_subscription(self, msg_type, topic, callback):
            self.callbacks[topic] = callback

        def spin_once(self):
            return 0

    interface = Interface()
    with contextlib.redirect_stdout(io.StringIO()), viz.Viewer(teleavatar, None, live=("live",), port=0) as v:
        follower = LiveFollower(v, interface)
        q = teleavatar.home.copy()
        q[teleavatar.group("right").indices] = [-0.6, -0.8, 0.3, -1.4, 0.0, 0.3, 0.0]
        for side in api.SIDES:
            idx = teleavatar.indices(api.ARM_JOINT_NAMES[side])
            fields = {"name": list(api.ARM_JOINT_NAMES[side]), "position": list(q[idx]), "velocity": [0.1] * 7}
            interface.callbacks[api.Topics.joint_states(side)](fields)
        interface.callbacks[api.Topics.joint_states("left")]({"name": ["x"], "position": [1.0]})
        follower.step()
        assert follower.received == 2 and follower.rejected == 1
        T = v.world_pose("/robots/live/r_joint7/hand_right_ee")
        np.testing.assert_allclose(T, teleavatar.frame_pose(q, "right_ee"), atol=POSE_TOL)
        assert re.search(r"\| r_joint1 \| (\d+) %", v.gui["live/limits"].content).group(1) == str(
            round(100 * 0.1 / teleavatar.limits.velocity[teleavatar.joint_names.index("r_joint1")])
        )


def test_geometry_helpers() -> None:
    vertices, faces = capsule_mesh(0.05, 0.2)
    assert np.abs(vertices[:, 2]).max() == pytest.approx(0.15, abs=1e-6)  # half length + radius
    radial = np.linalg.norm(vertices[:, :2], axis=1)
    assert radial.max() == pytest.approx(0.05, abs=1e-6) and faces.max() < len(vertices)
    T = segment_pose(np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.3, 0.0]))
    np.testing.assert_allclose(T[:3, 2], [0, 1, 0], atol=1e-12)
    R = pin.rpy.rpyToMatrix(0.3, -0.2, 1.1)
    w, x, y, z = wxyz(R)
    np.testing.assert_allclose(pin.Quaternion(w, x, y, z).toRotationMatrix(), R, atol=1e-12)


def _taplan(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "taplan", "view", *args], capture_output=True, text=True, timeout=timeout
    )


def test_cli_bad_input_is_one_line(tmp_path, teleavatar) -> None:
    alien = tmp_path / "alien.json"
    Trajectory([0, 1], [[0.0], [1.0]], joint_names=("wrist_z",)).save(alien)
    for args, expected in (
        ((str(tmp_path / "missing.json"),), "missing.json"),
        ((str(alien),), "wrist_z"),
        ((), "--live"),
    ):
        result = _taplan(*args)
        assert result.returncode == 2
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("taplan view: error:") and expected in lines[0]


def test_cli_serves_prints_the_url_and_stops_cleanly_on_ctrl_c(tmp_path, teleavatar) -> None:
    import signal

    plan = tmp_path / "plan.json"
    _motion(teleavatar).save(plan)
    process = subprocess.Popen(
        [sys.executable, "-m", "taplan", "view", str(plan), "--port", "0", "--play"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    line = process.stdout.readline()
    url = re.search(r"http://127\.0\.0\.1:(\d+)", line)
    assert url, line
    with urllib.request.urlopen(url.group(0), timeout=10) as page:  # serving viser's client
        assert b"<html" in page.read(2000)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=30)
    assert process.returncode == 0 and "Traceback" not in err and "stopped" in out


_ARM_URDF = """<robot name="arm">
  <link name="base_link"/>
  <link name="link1">
    <visual><origin xyz="0 0 0.1" rpy="0 0 0.5"/><geometry><mesh filename="package://pkg/meshes/link1.stl"/></geometry></visual>
    <visual><geometry><mesh filename="package://pkg/meshes/missing.stl"/></geometry></visual>
    <collision><origin xyz="0 0 0.15"/><geometry><cylinder radius="0.03" length="0.3"/></geometry></collision>
  </link>
  <joint name="j1" type="revolute"><parent link="base_link"/><child link="link1"/><origin xyz="0 0 0.2"/>
    <axis xyz="1 0 0"/><limit lower="-2" upper="2" velocity="1" effort="1"/></joint>
</robot>"""


def test_visual_meshes_are_drawn_when_the_files_exist(tmp_path) -> None:
    import trimesh

    folder = tmp_path / "pkg"
    (folder / "meshes").mkdir(parents=True)
    trimesh.creation.box((0.1, 0.2, 0.3)).export(folder / "meshes" / "link1.stl")
    (folder / "arm.urdf").write_text(_ARM_URDF)
    robot = taplan.Robot.from_urdf(folder / "arm.urdf")
    motion = viz.Motion.from_trajectory(robot, Trajectory([0.0, 1.0], [[0.0], [1.2]], joint_names=("j1",)))
    with contextlib.redirect_stdout(io.StringIO()), viz.Viewer(robot, None, [motion], port=0) as v:
        assert v.skipped_visuals == ["package://pkg/meshes/missing.stl (not found)"]
        v.set_time(0.5)
        node = v.nodes()["/robots/plan/j1/visual_link1_0"]
        extent = node.vertices.max(axis=0) - node.vertices.min(axis=0)
        np.testing.assert_allclose(extent, [0.1, 0.2, 0.3], atol=1e-6)  # the STL's box, metres
        T_link = robot.frame_pose(motion.joints(0.5)[0], "link1")
        expected = T_link @ np.block([[pin.rpy.rpyToMatrix(0, 0, 0.5), np.array([[0, 0, 0.1]]).T], [0, 0, 0, 1]])
        np.testing.assert_allclose(v.world_pose("/robots/plan/j1/visual_link1_0"), expected, atol=POSE_TOL)
        assert "visuals" in v.gui


def test_live_view_follows_a_simulated_robot_over_dds(teleavatar) -> None:
    import random

    from taplan.ros.dds import DdsInterface, loopback_config
    from taplan.ros.sim import SimulatedRobot

    domain = random.randint(100, 230)  # other test runs on this machine use other domains
    q = teleavatar.home.copy()
    q[teleavatar.group("left").indices] = [0.6, 0.8, -0.3, 1.4, 0.0, -0.3, 0.0]
    sim = SimulatedRobot(DdsInterface(domain, config=loopback_config()), teleavatar, initial=q)
    stop = sim.start()
    listener = DdsInterface(domain, config=loopback_config())
    try:
        with contextlib.redirect_stdout(io.StringIO()), viz.Viewer(teleavatar, None, live=("live",), port=0) as v:
            follower = LiveFollower(v, listener)
            deadline = time.monotonic() + 15.0  # DDS discovery on loopback, under load
            while len(follower._stamp) < 2 and time.monotonic() < deadline:
                follower.step()
                time.sleep(0.01)
            follower.step()
            T = v.world_pose("/robots/live/l_joint7/hand_left_ee")
            np.testing.assert_allclose(T, teleavatar.frame_pose(q, "left_ee"), atol=POSE_TOL)
    finally:
        listener.close()
        stop()


def test_perceived_occupancy_is_drawn_voxel_by_voxel_and_follows_the_scene(teleavatar) -> None:
    from taplan.scene import Occupancy

    scene = Scene()
    voxels = np.array([[0, 0, 0], [1, 0, 0], [1, 2, 3]])
    scene.put("seen", Occupancy(0.02, np.array([0.4, -0.1, -0.3]), voxels))
    motion = viz.motions_of(teleavatar, [_motion(teleavatar)])
    with contextlib.redirect_stdout(io.StringIO()), viz.Viewer(teleavatar, scene, motion, port=0) as v:
        drawn = v.nodes()["/scene/seen"].batched_positions
        np.testing.assert_allclose(drawn, np.array([0.4, -0.1, -0.3]) + (voxels + 0.5) * 0.02, atol=1e-6)
        scene.put("seen", Occupancy(0.02, np.array([0.4, -0.1, -0.3]), voxels[:1]))  # perception's refresh
        v.set_time(0.5)
        assert len(v.nodes()["/scene/seen"].batched_positions) == 1
        scene.remove("seen")
        v.set_time(0.6)
        assert "/scene/seen" not in v.nodes()


def test_show_serves_a_motion_plan_in_its_scene_on_localhost(teleavatar, capsys) -> None:
    # item 2's Python source: taplan.viz.show(plan, scene) with a MotionPlan, the scene as the last positional
    # argument; outside Jupyter it prints the URL, on 127.0.0.1 unless told otherwise
    from taplan.planning import plan_motion

    scene = Scene()
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    goal = teleavatar.home.copy()
    goal[teleavatar.group("right").indices] += np.array([-0.3, -0.2, 0.1, -0.3, 0.0, 0.2, 0.0])
    plan = plan_motion(teleavatar, teleavatar.home, goal, scene)
    viewer = viz.show(plan, scene, play=True)
    try:
        assert f"taplan.viz: open {viewer.url}" in capsys.readouterr().out
        assert viewer.url.startswith("http://127.0.0.1:")
        assert viewer.end == pytest.approx(plan.trajectory.duration)
        assert {"/scene/table", "/paths/plan/right_ee", f"/robots/plan/{teleavatar.joint_names[0]}"} <= set(
            viewer.nodes()
        )
        with urllib.request.urlopen(viewer.url, timeout=10) as page:  # viser's client is served
            assert b"<html" in page.read(2000)
        deadline = time.monotonic() + 20.0
        while viewer.time <= 0.0 and time.monotonic() < deadline:
            time.sleep(0.02)  # play=True: the server's thread plays by itself
        assert viewer.playing and viewer.time > 0.0
        viewer.pause()
        viewer.set_time(viewer.end)
        end = viewer.world_pose("/robots/plan/r_joint7")
        np.testing.assert_allclose(end[:3, 3], _joint_position(teleavatar, plan.trajectory(viewer.end), "r_joint7"))
    finally:
        with contextlib.redirect_stdout(io.StringIO()):
            viewer.close()


def _joint_position(robot: taplan.Robot, q: np.ndarray, joint: str) -> np.ndarray:
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    return data.oMi[robot.model.getJointId(joint)].translation
