"""Scene files: YAML or JSON, metres, poses as ``xyz`` + ``xyzw`` quaternion in the file's ``frame``.

Schema (``models/teleavatar/scenes/table.yaml`` is an example; docs/scene.md is the full description)::

    frame: shoulder_base          # optional (default: the robot's root frame); any frame of the robot's model
    configuration: {l_joint4: -1.2}  # optional: joint angles [rad] placing a moving frame (others: home)
    obstacles:                    # each: name, shape, pose (in `frame`)
      - name: table
        shape: {type: box, size: [0.8, 1.2, 0.04]}          # box: size; sphere: radius;
        pose: {xyz: [0.55, 0.0, -0.42], xyzw: [0, 0, 0, 1]}  # capsule/cylinder: radius, length (along z);
    attached:                     # optional: objects carried by a frame  # halfspace: (none; solid z <= 0);
      - name: cup                                            # mesh: vertices, faces
        shape: {type: cylinder, radius: 0.04, length: 0.1}
        frame: left_tcp
        pose: {xyz: [0, 0, 0.08], xyzw: [0, 0, 0, 1]}
        touch: [left_gripper_0]    # optional: robot bodies it may touch

Obstacles are stored in the root frame: ``T_root_obstacle = T_root_frame(q) @ T_frame_obstacle``, with ``q`` the
robot's home configuration updated by ``configuration`` (a frame on an arm moves with it; the file's obstacles do
not). An unknown frame, joint or touch body is an error naming the valid ones. Every error is a
:class:`~taplan.errors.TaplanError` naming the field (``obstacles[2].shape.size``), what was received and what is
valid.
"""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from taplan.errors import InvalidInputError, UnknownNameError
from taplan.scene.scene import Scene, as_pose, link_frames
from taplan.scene.shapes import shape_from_dict

if TYPE_CHECKING:
    from taplan.robot import Robot

__all__ = ["load_scene", "save_scene", "scene_from_dict", "scene_to_dict", "TELEAVATAR_SCENES"]

TELEAVATAR_SCENES = Path(__file__).resolve().parents[1] / "models" / "teleavatar" / "scenes"  # bundled examples

_TOP = {"frame", "configuration", "obstacles", "attached"}


@lru_cache(maxsize=1)
def _bundled_robot() -> Robot:
    """The TeleAvatar, the robot of the bundled scenes, for files loaded without a robot."""
    from taplan.robot import Robot

    return Robot.teleavatar()


def _configuration(data: Any, robot: Robot, q: Any, source: str) -> np.ndarray:
    """The configuration placing the file's frame: ``q`` (argument) or home, updated by the file's mapping."""
    base = robot.home if q is None else robot.check_configuration(q, "q")
    if data is None:
        return base
    if not isinstance(data, dict):
        raise InvalidInputError(f"{source}: configuration", data, "a mapping joint name -> angle [rad]")
    for joint, value in data.items():
        if joint not in robot.joint_names:
            raise UnknownNameError(f"joint in {source}: configuration", joint, robot.joint_names)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            raise InvalidInputError(f"{source}: configuration.{joint}", value, "a finite angle [rad]")
        base[robot.joint_names.index(joint)] = float(value)
    if not robot.limits.within(base):
        raise InvalidInputError(f"{source}: configuration", data, "angles within the joint limits")
    return base


def _frame_transform(data: dict[str, Any], robot: Robot, q: Any, source: str) -> np.ndarray:
    """``T_root_frame`` of the file's ``frame`` (identity when absent or the root)."""
    frame = data.get("frame")
    if frame is None:
        if data.get("configuration") is not None:
            raise InvalidInputError(f"{source}: configuration", data["configuration"], "a frame: to place")
        return np.eye(4)
    if not isinstance(frame, str) or frame not in robot.frame_names:
        raise UnknownNameError(f"frame in {source}:", frame, link_frames(robot))  # joint frames accepted too
    return robot.frame_pose(_configuration(data.get("configuration"), robot, q, source), frame)


def _pose(data: Any, where: str) -> tuple[list[float], list[float]]:
    if not isinstance(data, dict) or set(data) - {"xyz", "xyzw"} or "xyz" not in data:
        raise InvalidInputError(where, data, "{xyz: [x, y, z], xyzw: [qx, qy, qz, qw]} (xyzw optional)")
    xyz = data["xyz"]
    xyzw = data.get("xyzw", [0.0, 0.0, 0.0, 1.0])
    for key, value, size in (("xyz", xyz, 3), ("xyzw", xyzw, 4)):
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise InvalidInputError(f"{where}.{key}", value, f"{size} numbers") from None
        if arr.shape != (size,) or not np.all(np.isfinite(arr)):
            raise InvalidInputError(f"{where}.{key}", value, f"{size} finite numbers")
    if abs(float(np.linalg.norm(xyzw)) - 1.0) > 1e-3:
        raise InvalidInputError(f"{where}.xyzw", xyzw, "a unit quaternion (x, y, z, w)")
    return list(map(float, xyz)), list(map(float, xyzw))


def _items(data: dict[str, Any], key: str) -> list[Any]:
    items = data.get(key, [])
    if items is None:
        return []
    if not isinstance(items, list):
        raise InvalidInputError(key, items, "a list of entries")
    return items


def scene_from_dict(data: Any, source: str = "scene", *, robot: Robot | None = None, q: Any = None) -> Scene:
    """A scene from its dict (the parsed file), its obstacles moved from the file's ``frame`` to the root frame.

    Args:
        data: The parsed file.
        source: Where it came from, for error messages.
        robot: The robot whose frames the file names (default: the bundled TeleAvatar); the scene is bound to it.
        q: Configuration [rad] placing a moving ``frame`` (default: the robot's home), shape (nq,); the file's
            ``configuration`` entries override it joint by joint.
    """
    if data is None or data == {}:
        raise InvalidInputError(source, "an empty scene file", f"a mapping with {sorted(_TOP)}")
    if not isinstance(data, dict):
        raise InvalidInputError(source, type(data).__name__, f"a mapping with {sorted(_TOP)}")
    unknown = set(data) - _TOP
    if unknown:
        raise InvalidInputError(source, sorted(unknown), f"only the keys {sorted(_TOP)}")
    robot = robot if robot is not None else _bundled_robot()
    T_root_frame = _frame_transform(data, robot, q, source)
    scene = Scene(robot)
    for kind in ("obstacles", "attached"):
        for i, item in enumerate(_items(data, kind)):
            where = f"{kind}[{i}]"
            if not isinstance(item, dict):
                raise InvalidInputError(where, item, "a mapping with name, shape and pose")
            required = {"name", "shape", "pose"} | ({"frame"} if kind == "attached" else set())
            allowed = required | ({"touch"} if kind == "attached" else set())
            missing, extra = required - set(item), set(item) - allowed
            if missing or extra:
                raise InvalidInputError(where, sorted(item), f"the keys {sorted(required)} (optional: touch)")
            name = item["name"]
            if not isinstance(name, str) or not name or name in scene.names():
                raise InvalidInputError(f"{where}.name", name, "a new, non-empty name")
            shape = shape_from_dict(item["shape"], f"{where}.shape")
            pose = _pose(item["pose"], f"{where}.pose")
            if kind == "obstacles":
                scene.add(name, shape, T_root_frame @ as_pose(pose, f"{where}.pose"))
            else:
                touch = item.get("touch", [])
                if not isinstance(touch, list) or not all(isinstance(t, str) for t in touch):
                    raise InvalidInputError(f"{where}.touch", touch, "a list of robot body names")
                scene.attach(name, shape, str(item["frame"]), pose, tuple(touch))  # checked against the robot
    return scene


def _pose_dict(T: np.ndarray) -> dict[str, list[float]]:
    import pinocchio as pin

    return {"xyz": T[:3, 3].tolist(), "xyzw": pin.Quaternion(T[:3, :3]).coeffs().tolist()}


def scene_to_dict(scene: Scene, robot: Robot | None = None) -> dict[str, Any]:
    """The file form of ``scene``: obstacles in the root frame of ``robot`` (default: the scene's robot, else the
    bundled TeleAvatar), whose name is written as ``frame``."""
    robot = robot or scene.robot or _bundled_robot()
    return {
        "frame": robot.root_frame,
        "obstacles": [
            {"name": o.name, "shape": o.shape.to_dict(), "pose": _pose_dict(o.pose)} for o in scene.obstacles.values()
        ],
        "attached": [
            {
                "name": a.name,
                "shape": a.shape.to_dict(),
                "frame": a.frame,
                "pose": _pose_dict(a.pose),
                "touch": list(a.touch),
            }
            for a in scene.attached.values()
        ],
    }


def load_scene(path: str | Path, robot: Robot | None = None, *, q: Any = None) -> Scene:
    """Read a scene from ``.yaml``/``.yml`` or ``.json``; ``robot`` and ``q`` as in :func:`scene_from_dict`."""
    path = Path(path)
    if not path.is_file():
        raise InvalidInputError("scene file", str(path), "an existing .yaml, .yml or .json file")
    try:
        text = path.read_text(encoding="utf-8")
        if path.suffix.lower() == ".json":
            data = json.loads(text) if text.strip() else None
        else:
            import yaml

            data = yaml.safe_load(text)
    except Exception as exc:  # yaml and json raise their own kinds; bytes that are not UTF-8 text
        raise InvalidInputError("scene file", str(path), f"valid UTF-8 YAML/JSON ({exc})") from exc
    return scene_from_dict(data, str(path), robot=robot, q=q)


def save_scene(scene: Scene, path: str | Path, robot: Robot | None = None) -> Path:
    """Write ``scene`` as YAML (``.yaml``/``.yml``) or JSON (``.json``), creating missing directories (the rule of
    :func:`taplan.io.output_path`); returns the path."""
    from taplan.io.paths import output_path

    path = output_path(path, "path", suffixes=(".yaml", ".yml", ".json"))
    data = scene_to_dict(scene, robot)
    if path.suffix.lower() == ".json":
        path.write_text(json.dumps(data, indent=2))
    else:
        import yaml

        path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path
