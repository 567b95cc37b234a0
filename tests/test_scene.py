"""taplan.scene: shapes, scene files and their errors, attach/detach, signed distances vs coal, Jacobians vs finite
differences, broad phase vs brute force."""

from __future__ import annotations

import math
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest

import taplan
from taplan.errors import CollisionError, InvalidInputError, UnknownNameError
from taplan.scene import (
    Box,
    Capsule,
    CollisionWorld,
    Cylinder,
    HalfSpace,
    Mesh,
    Scene,
    Sphere,
    load_scene,
    save_scene,
    scene_from_dict,
)

MODELS = Path(__file__).resolve().parents[1] / "models" / "teleavatar" / "scenes"
DIST_TOL = 1e-6  # [m] closed form vs coal
FD_TOL = 1e-4  # [m/rad] Jacobian vs central differences (h = 1e-6 rad)


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _cluttered() -> Scene:
    scene = Scene()
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    scene.add("ball", Sphere(0.05), ([0.45, 0.3, -0.2], [0, 0, 0, 1]))
    scene.add("pillar", Cylinder(0.04, 0.6), ([0.5, 0.0, -0.1], [0, 0, 0, 1]))
    scene.add("bar", Capsule(0.02, 0.4), ([0.35, -0.3, 0.0], [0.7071068, 0, 0, 0.7071068]))
    scene.add("floor", HalfSpace(), ([0, 0, -0.9], [0, 0, 0, 1]))
    return scene


def _random_states(robot: taplan.Robot, count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo, hi = robot.planning_limits.lower, robot.planning_limits.upper
    return lo + rng.uniform(0, 1, (count, robot.nq)) * (hi - lo)


def test_shapes_validate_their_sizes() -> None:
    with pytest.raises(InvalidInputError, match="size"):
        Box((0.1, -0.2, 0.3))
    with pytest.raises(InvalidInputError, match="radius"):
        Sphere(float("nan"))
    with pytest.raises(InvalidInputError, match="faces"):
        Mesh(np.eye(3), np.array([[0, 1, 5]]))
    assert Box([0.1, 0.2, 0.3]).bounding_radius() == pytest.approx(0.5 * math.sqrt(0.14))


def test_scene_add_move_remove_and_versions() -> None:
    scene = Scene()
    scene.add("a", Sphere(0.1), np.eye(4))
    v = scene.version
    scene.move("a", ([0.1, 0.0, 0.0], [0, 0, 0, 1]))
    assert scene.version == v + 1
    np.testing.assert_allclose(scene.obstacles["a"].pose[:3, 3], [0.1, 0.0, 0.0])
    with pytest.raises(InvalidInputError, match="name"):
        scene.add("a", Sphere(0.1))
    with pytest.raises(UnknownNameError):
        scene.move("b", np.eye(4))
    with pytest.raises(InvalidInputError, match="pose"):
        scene.add("c", Sphere(0.1), ([np.nan, 0, 0], [0, 0, 0, 1]))
    scene.remove("a")
    assert len(scene) == 0


def test_scene_file_round_trip(tmp_path: Path) -> None:
    scene = load_scene(MODELS / "table.yaml")
    assert set(scene.obstacles) == {"table", "box"}
    scene.attach("cup", Cylinder(0.04, 0.1), "left_tcp", ([0.0, 0.0, 0.08], [0, 0, 0, 1]))
    for suffix in (".yaml", ".json"):
        path = tmp_path / f"scene{suffix}"
        save_scene(scene, path)
        again = load_scene(path)
        assert set(again.obstacles) == set(scene.obstacles) and set(again.attached) == {"cup"}
        np.testing.assert_allclose(again.obstacles["box"].pose, scene.obstacles["box"].pose, atol=1e-12)
        assert again.obstacles["table"].shape == scene.obstacles["table"].shape


@pytest.mark.parametrize(
    ("data", "field"),
    [
        (None, "scene"),
        ({}, "scene"),
        (
            {"obstacles": [{"name": "t", "shape": {"type": "cone"}, "pose": {"xyz": [0, 0, 0]}}]},
            "obstacles[0].shape.type",
        ),
        ({"obstacles": [{"name": "t", "shape": {"type": "box", "size": [1, 1]}, "pose": {"xyz": [0, 0, 0]}}]}, "size"),
        ({"obstacles": [{"name": "t", "shape": {"type": "sphere", "radius": 0.1}, "pose": {"xyz": [0, 0]}}]}, "xyz"),
        (
            {
                "obstacles": [
                    {
                        "name": "t",
                        "shape": {"type": "sphere", "radius": 0.1},
                        "pose": {"xyz": [0, 0, 0], "xyzw": [0, 0, 0, 2]},
                    }
                ]
            },
            "xyzw",
        ),
        ({"obstacles": [{"name": "t", "shape": {"type": "sphere", "radius": 0.1}}]}, "obstacles[0]"),
        ({"tables": []}, "scene"),
    ],
)
def test_bad_scene_files_name_the_field(data, field) -> None:
    with pytest.raises(InvalidInputError, match=field.replace("[", r"\[").replace("]", r"\]")):
        scene_from_dict(data)


def test_empty_scene_file(tmp_path: Path) -> None:
    path = tmp_path / "empty.yaml"
    path.write_text("")
    with pytest.raises(InvalidInputError, match="empty scene file"):
        load_scene(path)


def test_self_distances_match_coal(robot) -> None:
    world = CollisionWorld(robot)
    request = coal.DistanceRequest()
    request.enable_signed_distance = True
    for q in _random_states(robot, 20, 1):
        d = world.distances(q, jacobian=False)
        pin.forwardKinematics(world.model, world.data, q)  # the bodies' placements (the query need not set them)
        transforms = world._body_transforms()
        index = {b.name: k for k, b in enumerate(world.bodies)}
        for (a, b), value in zip(d.pairs, d.distance, strict=True):
            ga, ta = world._body_geometry_at(index[a], transforms)
            gb, tb = world._body_geometry_at(index[b], transforms)
            reference = coal.distance(ga, ta, gb, tb, request, coal.DistanceResult())
            if value > 0:
                assert value == pytest.approx(reference, abs=DIST_TOL)
            else:
                assert reference < 1e-9  # both see the overlap


def test_obstacle_distances_and_witness_points(robot) -> None:
    world = CollisionWorld(robot, _cluttered())
    for q in _random_states(robot, 10, 2):
        d = world.distances(q, jacobian=False)
        gap = np.einsum("ij,ij->i", d.point_a - d.point_b, d.normal)
        positive = d.distance > 1e-6
        np.testing.assert_allclose(gap[positive], d.distance[positive], atol=1e-6)  # d = n · (p_a - p_b) [m]
        np.testing.assert_allclose(np.linalg.norm(d.normal, axis=1), 1.0, atol=1e-9)


def test_penetration_is_negative_and_named_in_mm(robot) -> None:
    q = robot.home
    hand = robot.frame_pose(q, "left_ee")[:3, 3]
    scene = Scene()
    scene.add("block", Box((0.1, 0.1, 0.1)), (hand.tolist(), [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    d, pair = world.min_distance(q)
    assert d < -0.01 and "block" in pair  # [m]
    with pytest.raises(CollisionError, match=r"collides with block \(penetration \d+\.\d mm\)") as info:
        world.check_configuration(q, "start")
    assert info.value.depth == pytest.approx(-d)
    assert info.value.argument == "start"
    apart = Scene()  # a few mm inside a 10 mm clearance: named as a distance, not as a penetration
    apart.add("block", Box((0.1, 0.1, 0.1)), (hand.tolist(), [0, 0, 0, 1]))
    clear_world = CollisionWorld(robot, apart)
    for lift in np.arange(0.0, 0.3, 0.001):  # [m] raise the block until it is 3-9 mm away
        apart.move("block", ((hand + [0.0, 0.0, lift]).tolist(), [0, 0, 0, 1]))
        d, pair = clear_world.min_distance(q)
        if 0.003 < d < 0.009 and "block" in pair:
            break
    assert 0.003 < d < 0.009 and "block" in pair  # [m]
    pattern = rf"start: .* is {d * 1e3:.1f} mm from block, inside the required clearance of 10\.0 mm$"
    with pytest.raises(CollisionError, match=pattern) as info:
        clear_world.check_configuration(q, "start", margin=0.01)
    assert info.value.depth == pytest.approx(-d) and info.value.clearance == pytest.approx(0.01)


def test_jacobians_match_finite_differences(robot) -> None:
    world = CollisionWorld(robot, _cluttered())
    h = 1e-6
    checked = 0
    for q in _random_states(robot, 8, 3):
        d = world.distances(q)
        for k, pair in enumerate(d.pairs):
            if d.distance[k] < 0.01 or d.distance[k] > 0.5:  # away from contact and from coal's far-field
                continue
            numeric = np.zeros(robot.nq)
            for j in range(robot.nq):
                step = np.zeros(robot.nq)
                step[j] = h
                plus = world.distances(q + step, jacobian=False)
                minus = world.distances(q - step, jacobian=False)
                numeric[j] = (plus.distance[plus.pairs.index(pair)] - minus.distance[minus.pairs.index(pair)]) / (2 * h)
            np.testing.assert_allclose(d.jacobian[k], numeric, atol=FD_TOL, err_msg=str(pair))
            checked += 1
            break  # one pair per state keeps the test short
    assert checked >= 6


def test_broad_phase_keeps_every_pair_within_the_cutoff(robot) -> None:
    scene = _cluttered()
    rng = np.random.default_rng(5)
    for i in range(40):
        scene.add(
            f"clutter{i}",
            Box(tuple(rng.uniform(0.03, 0.1, 3))),
            (rng.uniform([0.2, -0.6, -0.6], [0.9, 0.6, 0.3]).tolist(), [0, 0, 0, 1]),
        )
    world = CollisionWorld(robot, scene)
    for q in _random_states(robot, 5, 6):
        full = world.distances(q, jacobian=False)
        near = world.distances(q, cutoff=0.05, jacobian=False)
        expected = {p for p, d in zip(full.pairs, full.distance, strict=True) if d <= 0.05}
        assert expected == set(near.pairs)
        assert len(near) < len(full)


def test_attached_object_moves_with_the_hand(robot) -> None:
    scene = Scene()
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    scene.attach("cup", Sphere(0.05), "left_tcp", ([0.0, 0.0, 0.0], [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    q = robot.home
    d = world.distances(q)
    k = d.pairs.index(("cup", "table"))
    tcp = robot.frame_pose(q, "left_tcp")[:3, 3]
    expected = tcp[2] - 0.05 - (-0.42 + 0.02)
    assert d.distance[k] == pytest.approx(expected, abs=1e-6)
    # the cup's distance changes with the left arm only
    assert np.abs(d.jacobian[k, 7:]).max() < 1e-12 and np.abs(d.jacobian[k, :7]).max() > 1e-3
    T = robot.frame_pose(q, "left_tcp")
    scene.detach("cup", T)
    assert "cup" in scene.obstacles
    np.testing.assert_allclose(scene.obstacles["cup"].pose[:3, 3], tcp, atol=1e-12)


def test_point_travel_bound_is_an_upper_bound(robot) -> None:
    world = CollisionWorld(robot)
    rng = np.random.default_rng(7)
    for q in _random_states(robot, 20, 8):
        dq = rng.uniform(-0.05, 0.05, robot.nq)
        world.distances(q, jacobian=False)
        before = [world.data.oMi[b.joint].act(b.end) for b in world.bodies]
        world.distances(q + dq, jacobian=False)
        after = [world.data.oMi[b.joint].act(b.end) for b in world.bodies]
        travel = max(np.linalg.norm(a - b) for a, b in zip(before, after, strict=True))
        assert travel <= world.max_point_speed_bound(q, q + dq) + 1e-12


def test_batched_distances_match_one_at_a_time(robot) -> None:
    """distances_many is the same computation as distances, configuration by configuration (to 1e-12)."""
    scene = Scene()
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.45], [0, 0, 0, 1]))
    scene.add("ball", Sphere(0.05), ([0.4, -0.2, -0.2], [0, 0, 0, 1]))
    scene.add("floor", HalfSpace(), ([0.0, 0.0, -1.0], [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    limits = robot.planning_limits
    rng = np.random.default_rng(11)
    Q = limits.lower + rng.uniform(0, 1, (12, robot.nq)) * (limits.upper - limits.lower)
    for cutoff in (0.05, np.inf):
        for q, batched in zip(Q, world.distances_many(Q, cutoff=cutoff), strict=True):
            single = world.distances(q, cutoff=cutoff)
            assert batched.pairs == single.pairs
            for field in ("distance", "point_a", "point_b", "normal", "jacobian", "travel"):
                np.testing.assert_allclose(getattr(batched, field), getattr(single, field), atol=1e-12)
    with pytest.raises(InvalidInputError, match="configurations"):
        world.distances_many(Q[:, :5], cutoff=0.05)


def _cube_mesh(edge: float) -> Mesh:
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float) * edge / 2
    faces = [
        [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
        [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3],
    ]  # fmt: skip
    return Mesh(corners, np.array(faces))


def test_mesh_obstacle_matches_the_same_box(robot) -> None:
    """A triangle-mesh cube and a Box of the same size and pose give the same separations (coal BVH vs GJK)."""
    hand = robot.frame_pose(robot.home, "left_ee")[:3, 3]
    pose = ((hand + [0.0, 0.0, -0.2]).tolist(), [0, 0, 0.3826834, 0.9238795])  # 45° about z
    as_mesh, as_box = Scene(), Scene()
    as_mesh.add("cube", _cube_mesh(0.1), pose)
    as_box.add("cube", Box((0.1, 0.1, 0.1)), pose)
    meshes, boxes = CollisionWorld(robot, as_mesh), CollisionWorld(robot, as_box)
    for q in _random_states(robot, 6, 5):
        a, b = meshes.distances(q), boxes.distances(q)
        assert a.pairs == b.pairs
        apart = b.distance > 1e-4
        np.testing.assert_allclose(a.distance[apart], b.distance[apart], atol=1e-6)  # [m]
    assert meshes.min_distance(robot.home)[1] == boxes.min_distance(robot.home)[1]


def test_scene_files_point_at_a_schema_that_exists() -> None:
    """Each bundled scene names the document of its schema; that document exists and describes the file format."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    scenes = {
        p.resolve() for base in (root / "models", root / "taplan" / "models") for p in base.rglob("scenes/*.yaml")
    }
    assert scenes
    for path in scenes:
        found = re.search(r"Schema: (\S+)", path.read_text())
        assert found, f"{path.name} names no schema document"
        doc = root / found.group(1)
        assert doc.is_file(), f"{path.name} points at {found.group(1)}, which does not exist"
        assert "frame: shoulder_base" in doc.read_text() and "obstacles:" in doc.read_text()


POSE_TOL = 1e-9  # [m] and rotation-matrix entries: a transform composed from FK


def _table_in(frame: str | None, **extra) -> dict:
    data = {
        "obstacles": [
            {
                "name": "box",
                "shape": {"type": "box", "size": [0.12, 0.2, 0.16]},
                "pose": {"xyz": [0.5, 0.1, -0.32], "xyzw": [0.0, 0.0, 0.38268343, 0.92387953]},
            }
        ]
    }
    if frame is not None:
        data["frame"] = frame
    data.update(extra)
    return data


@pytest.mark.parametrize("frame", ["shoulder_base", "base_link", "left_shoulder_base", "Link-R4", "left_ee"])
def test_scene_file_frame_is_honoured(robot, frame) -> None:
    """Obstacles given in any frame land at T_root_frame(home) @ T_frame_obstacle, the frame's FK pose."""
    from taplan.scene import as_pose

    scene = scene_from_dict(_table_in(frame), robot=robot)
    T_frame_box = as_pose(([0.5, 0.1, -0.32], [0.0, 0.0, 0.38268343, 0.92387953]))
    expected = robot.frame_pose(robot.home, frame) @ T_frame_box
    np.testing.assert_allclose(scene.obstacles["box"].pose, expected, atol=POSE_TOL)
    if frame == "base_link":  # rotated 90 deg about z from the root: x forward in the file is y (left) at the root
        np.testing.assert_allclose(scene.obstacles["box"].pose[:3, 3], [-0.1, 0.5, -0.32], atol=POSE_TOL)


def test_scene_file_frame_at_a_stated_configuration(robot) -> None:
    """A moving frame is placed at the stated configuration: the file's entries over the argument's over home."""
    q = robot.home.copy()
    q[robot.joint_names.index("l_joint1")] += 0.4
    q[robot.joint_names.index("l_joint4")] += 0.3
    data = _table_in("left_ee", configuration={"l_joint4": float(q[robot.joint_names.index("l_joint4")])})
    q_arg = robot.home.copy()
    q_arg[robot.joint_names.index("l_joint1")] = q[robot.joint_names.index("l_joint1")]
    scene = scene_from_dict(data, robot=robot, q=q_arg)
    from taplan.scene import as_pose

    T_frame_box = as_pose(([0.5, 0.1, -0.32], [0.0, 0.0, 0.38268343, 0.92387953]))
    np.testing.assert_allclose(scene.obstacles["box"].pose, robot.frame_pose(q, "left_ee") @ T_frame_box, atol=POSE_TOL)


def test_scene_file_without_frame_is_in_the_root_frame(robot) -> None:
    scene = scene_from_dict(_table_in(None), robot=robot)
    np.testing.assert_allclose(scene.obstacles["box"].pose[:3, 3], [0.5, 0.1, -0.32], atol=POSE_TOL)


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (_table_in("world"), r"unknown frame .*'world'; valid: shoulder_base, .*left_ee"),
        (_table_in("left_ee", configuration={"l_jointX": 0.1}), r"unknown joint .*'l_jointX'"),
        (_table_in("left_ee", configuration={"l_joint4": 9.0}), r"configuration.*within the joint limits"),
        (_table_in(None, configuration={"l_joint4": 1.0}), r"configuration.*a frame: to place"),
        (
            {
                "attached": [
                    {
                        "name": "cup",
                        "shape": {"type": "sphere", "radius": 0.04},
                        "frame": "left_tcp",
                        "pose": {"xyz": [0, 0, 0.08]},
                        "touch": ["Link-NOPE"],
                    }
                ]
            },
            r"unknown touch body .*'Link-NOPE'; valid: .*left_gripper_0",
        ),
        (
            {
                "attached": [
                    {
                        "name": "cup",
                        "shape": {"type": "sphere", "radius": 0.04},
                        "frame": "hand",
                        "pose": {"xyz": [0, 0, 0]},
                    }
                ]
            },
            r"unknown frame of attached object 'cup': 'hand'",
        ),
    ],
)
def test_scene_file_unknown_names_are_refused(robot, data, match) -> None:
    with pytest.raises(taplan.TaplanError, match=match):
        scene_from_dict(data, robot=robot)


def test_save_scene_writes_the_root_frame_and_creates_directories(robot, tmp_path: Path) -> None:
    scene = scene_from_dict(_table_in("base_link"), robot=robot)
    path = save_scene(scene, tmp_path / "new" / "dir" / "scene.yaml")
    import yaml

    data = yaml.safe_load(path.read_text())
    assert data["frame"] == robot.root_frame == "shoulder_base"
    again = load_scene(path, robot)
    np.testing.assert_allclose(again.obstacles["box"].pose, scene.obstacles["box"].pose, atol=POSE_TOL)
    with pytest.raises(InvalidInputError, match="ending in"):
        save_scene(scene, tmp_path / "scene.txt")


def test_attach_checks_frame_and_touch_once_bound(robot) -> None:
    scene = Scene(robot)
    with pytest.raises(UnknownNameError, match="'nope'"):
        scene.attach("cup", Sphere(0.04), "nope")
    with pytest.raises(UnknownNameError, match="'Link-NOPE'"):
        scene.attach("cup", Sphere(0.04), "left_tcp", touch=("Link-NOPE",))
    assert scene.attach("cup", Sphere(0.04), "left_tcp", touch=("left_gripper_0",)).frame == "left_tcp"
    loose = Scene()  # no robot yet: checked when a world binds it
    loose.attach("cup", Sphere(0.04), "nope")
    with pytest.raises(UnknownNameError, match="'nope'"):
        CollisionWorld(robot, loose)
    bound = CollisionWorld(robot, Scene()).scene  # a world binds its scene: later attachments checked at once
    with pytest.raises(UnknownNameError, match="'nope'"):
        bound.attach("cup", Sphere(0.04), "nope")


def test_collision_world_refuses_a_file_name(robot) -> None:
    with pytest.raises(InvalidInputError, match="taplan.scene.Scene or None.*load_scene"):
        CollisionWorld(robot, str(MODELS / "table.yaml"))
