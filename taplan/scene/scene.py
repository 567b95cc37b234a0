"""The collision world's contents: obstacles posed in the robot's root frame, and objects carried by a hand.

A :class:`Scene` is plain data that changes at run time (``add``, ``move``, ``remove``, ``attach``, ``detach``); its
``version`` increases with every change, so evaluators (:class:`~taplan.scene.CollisionWorld`) refresh their
caches only when needed.

A scene may be bound to its robot (``Scene(robot)``, :func:`~taplan.scene.load_scene` and
:class:`~taplan.scene.CollisionWorld` bind it): from then on an attached object's frame and ``touch`` bodies are
checked when it is attached, not first when a world evaluates it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from taplan.errors import InvalidInputError, UnknownNameError
from taplan.scene.shapes import Shape

if TYPE_CHECKING:
    from taplan.robot import Robot

__all__ = ["Obstacle", "AttachedObject", "Scene", "as_pose"]

_ROTATION_TOL = 1e-6
_IDENTITY = np.eye(4)


def as_pose(pose: Any, name: str = "pose") -> np.ndarray:
    """A 4x4 homogeneous transform from a 4x4 array or ``(xyz [m], xyzw quaternion)``; validated."""
    if isinstance(pose, (tuple, list)) and len(pose) == 2 and np.size(pose[0]) == 3 and np.size(pose[1]) == 4:
        p = np.asarray(pose[0], dtype=float).ravel()
        x, y, z, w = np.asarray(pose[1], dtype=float).ravel()
        norm = float(np.sqrt(x * x + y * y + z * z + w * w))
        if not np.all(np.isfinite(p)) or not np.isfinite(norm) or abs(norm - 1.0) > 1e-3:
            raise InvalidInputError(name, pose, "(xyz [m], unit quaternion xyzw), finite")
        x, y, z, w = x / norm, y / norm, z / norm, w / norm
        T = np.eye(4)
        T[:3, :3] = [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
        T[:3, 3] = p
        return T
    try:
        T = np.array(pose, dtype=float)
    except (TypeError, ValueError):
        raise InvalidInputError(name, pose, "a 4x4 transform or (xyz, xyzw)") from None
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InvalidInputError(name, pose, "a finite 4x4 transform or (xyz, xyzw)")
    R = T[:3, :3]
    if np.abs(R @ R.T - np.eye(3)).max() > _ROTATION_TOL or np.linalg.det(R) < 0 or np.any(T[3] != [0, 0, 0, 1]):
        raise InvalidInputError(
            name, "a matrix that is not a rigid transform", "rotation with det +1, last row 0 0 0 1"
        )
    return T


@dataclass(frozen=True)
class Obstacle:
    """A shape fixed in the root frame: ``pose`` is ``T_root_obstacle`` (4x4)."""

    name: str
    shape: Shape
    pose: np.ndarray


@dataclass(frozen=True)
class AttachedObject:
    """A shape carried by a robot frame: ``pose`` is ``T_frame_object`` (4x4); ``touch`` lists robot bodies it may
    touch (the hand holding it)."""

    name: str
    shape: Shape
    frame: str
    pose: np.ndarray
    touch: tuple[str, ...] = ()


class Scene:
    """Obstacles and attached objects, by name.

    Args:
        robot: The robot the scene is for; when given, attached objects' frames and ``touch`` bodies are checked
            against it as they are attached (see :meth:`bind`).
    """

    def __init__(self, robot: Robot | None = None) -> None:
        self.obstacles: dict[str, Obstacle] = {}
        self.attached: dict[str, AttachedObject] = {}
        self.version = 0
        self.robot: Robot | None = None
        self._body_names: tuple[str, ...] = ()
        if robot is not None:
            self.bind(robot)

    def bind(self, robot: Robot) -> None:
        """Check every attached object against ``robot`` and check later ones as they are attached.

        Raises:
            UnknownNameError: an attached object's frame or ``touch`` body is not the robot's (names the valid ones).
            InvalidInputError: the scene is already bound to another robot model.
        """
        if self.robot is robot:
            return
        if self.robot is not None and self.robot.urdf_path != robot.urdf_path:
            raise InvalidInputError("robot", str(robot.urdf_path), f"the scene's robot {str(self.robot.urdf_path)!r}")
        from taplan.scene.robot_bodies import robot_bodies

        body_names = tuple(b.name for b in robot_bodies(robot))
        for item in self.attached.values():
            _check_attachment(item.name, item.frame, item.touch, robot, body_names)
        self.robot, self._body_names = robot, body_names

    def __len__(self) -> int:
        return len(self.obstacles) + len(self.attached)

    def __repr__(self) -> str:
        return f"Scene(obstacles={list(self.obstacles)}, attached={list(self.attached)})"

    def _check_name(self, name: Any) -> str:
        if not isinstance(name, str) or not name:
            raise InvalidInputError("name", name, "a non-empty string")
        if name in self.obstacles or name in self.attached:
            raise InvalidInputError("name", name, f"a name not already in the scene {sorted(self.names())}")
        return name

    def names(self) -> list[str]:
        return [*self.obstacles, *self.attached]

    def add(self, name: str, shape: Shape, pose: npt.ArrayLike | tuple = _IDENTITY) -> Obstacle:
        """Add an obstacle at ``pose`` (``T_root_obstacle``: 4x4 or ``(xyz, xyzw)``)."""
        if not isinstance(shape, Shape):
            raise InvalidInputError("shape", shape, "a taplan.scene shape (Box, Sphere, ...)")
        obstacle = Obstacle(self._check_name(name), shape, as_pose(pose, f"{name}.pose"))
        self.obstacles[name] = obstacle
        self.version += 1
        return obstacle

    def put(self, name: str, shape: Shape, pose: npt.ArrayLike | tuple = _IDENTITY) -> Obstacle:
        """Add obstacle ``name``, or replace its shape and pose in one step (a reader never sees it missing): how
        perception refreshes the occupancy it sees."""
        if name not in self.obstacles:
            return self.add(name, shape, pose)
        if not isinstance(shape, Shape):
            raise InvalidInputError("shape", shape, "a taplan.scene shape (Box, Sphere, ...)")
        obstacle = Obstacle(name, shape, as_pose(pose, f"{name}.pose"))
        self.obstacles[name] = obstacle
        self.version += 1
        return obstacle

    def move(self, name: str, pose: npt.ArrayLike | tuple) -> None:
        """Move an obstacle to a new pose."""
        if name not in self.obstacles:
            raise UnknownNameError("obstacle", name, list(self.obstacles))
        old = self.obstacles[name]
        self.obstacles[name] = Obstacle(name, old.shape, as_pose(pose, f"{name}.pose"))
        self.version += 1

    def remove(self, name: str) -> None:
        """Remove an obstacle or an attached object."""
        if name in self.obstacles:
            del self.obstacles[name]
        elif name in self.attached:
            del self.attached[name]
        else:
            raise UnknownNameError("scene object", name, self.names())
        self.version += 1

    def attach(
        self, name: str, shape: Shape, frame: str, pose: npt.ArrayLike | tuple = _IDENTITY, touch: tuple[str, ...] = ()
    ) -> AttachedObject:
        """Carry ``shape`` with robot ``frame`` at ``pose`` (``T_frame_object``); ``touch``: bodies it may touch."""
        if not isinstance(shape, Shape):
            raise InvalidInputError("shape", shape, "a taplan.scene shape (Box, Sphere, ...)")
        if not isinstance(frame, str) or not frame:
            raise InvalidInputError("frame", frame, "a frame name of the robot")
        if isinstance(touch, str) or not all(isinstance(t, str) for t in touch):
            raise InvalidInputError("touch", touch, "a sequence of robot body names")
        if self.robot is not None:
            _check_attachment(name, frame, tuple(touch), self.robot, self._body_names)
        item = AttachedObject(self._check_name(name), shape, frame, as_pose(pose, f"{name}.pose"), tuple(touch))
        self.attached[name] = item
        self.version += 1
        return item

    def grasp(self, name: str, frame: str, T_root_frame: npt.ArrayLike, touch: tuple[str, ...] = ()) -> None:
        """Attach obstacle ``name`` to ``frame`` where it is now (the hand frame's pose ``T_root_frame`` given)."""
        if name not in self.obstacles:
            raise UnknownNameError("obstacle", name, list(self.obstacles))
        if self.robot is not None:
            _check_attachment(name, frame, tuple(touch), self.robot, self._body_names)
        obstacle = self.obstacles.pop(name)
        T_frame_object = np.linalg.inv(as_pose(T_root_frame, "T_root_frame")) @ obstacle.pose
        self.attached[name] = AttachedObject(name, obstacle.shape, frame, T_frame_object, tuple(touch))
        self.version += 1

    def detach(self, name: str, T_root_frame: npt.ArrayLike) -> Obstacle:
        """Leave attached object ``name`` in the world where its frame (at ``T_root_frame``) holds it now."""
        if name not in self.attached:
            raise UnknownNameError("attached object", name, list(self.attached))
        item = self.attached.pop(name)
        obstacle = Obstacle(name, item.shape, as_pose(T_root_frame, "T_root_frame") @ item.pose)
        self.obstacles[name] = obstacle
        self.version += 1
        return obstacle


def link_frames(robot: Robot) -> list[str]:
    """The robot's link frames: the names worth listing when a frame is unknown (joint frames are valid too)."""
    import pinocchio as pin

    return [f.name for f in robot.model.frames if f.type == pin.FrameType.BODY]


def _check_attachment(name: str, frame: str, touch: tuple[str, ...], robot: Robot, bodies: tuple[str, ...]) -> None:
    if frame not in robot.frame_names:
        frames = link_frames(robot)
        raise UnknownNameError(f"frame of attached object {name!r}:", frame, frames)
    for body in touch:
        if body not in bodies:
            raise UnknownNameError(f"touch body of attached object {name!r}:", body, bodies)
