"""The robot's own collision bodies and the pairs that are allowed to touch, in one place.

Bodies are capsules on links (a sphere is a capsule of zero length): the URDF's collision cylinders, read as the
capsules around them (:mod:`taplan.scene.capsules`), plus sized primitives where the URDF has none. For the
TeleAvatar (recognised by its joint names) taplan adds:

* ``chest``: a capsule from shoulder to shoulder (the ``l_joint1``/``r_joint1`` origins, 0.18 m apart in the URDF),
  radius 0.06 m: the shoulder housings, sized to the 0.05 m radius the URDF gives the upper arm plus 1 cm;
* ``head``: a sphere of radius 0.11 m, 0.25 m above the shoulder midpoint (an estimate of the head and neck above
  the shoulders; the vendor URDF has no head link);
* the URDF's ``base_link`` cylinder (radius 0.07 m, 0.37 m below the shoulders) is the torso.

**Allowed pairs** (never checked): bodies on the same arm (a 7-joint arm's links are adjacent or kept apart by its
joint limits), and every pair closer than ``ALLOWED_CONTACT`` at the robot's home configuration (the shoulder links
against the chest and torso they are mounted on), the rule MoveIt's setup assistant uses for "adjacent / default
in collision".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from taplan.scene.capsules import segment_closest_points

__all__ = ["Body", "robot_bodies", "allowed_pairs", "ALLOWED_CONTACT"]

ALLOWED_CONTACT = 0.005  # [m] pairs closer than this at home are allowed to touch


@dataclass(frozen=True)
class Body:
    """A capsule fixed to a joint's frame (``joint`` 0: fixed to the root).

    Attributes:
        name: Body name (the URDF geometry's, or taplan's for added primitives).
        joint: Pinocchio joint index that carries it.
        start: Segment start in the joint frame [m]. Shape (3,).
        end: Segment end in the joint frame [m] (== start for a sphere). Shape (3,).
        radius: [m].
        group: Arm group name (``"left"``, ``"right"``) or ``""`` for the body of the robot.
        source: Where the size comes from.
    """

    name: str
    joint: int
    start: np.ndarray
    end: np.ndarray
    radius: float
    group: str = ""
    source: str = "urdf"


def _group_of(robot: object, joint: int) -> str:
    model = robot.model  # type: ignore[attr-defined]
    for name, group in robot.groups.items():  # type: ignore[attr-defined]
        joints = {int(i) + 1 for i in group.indices}
        j = joint
        while j > 0:
            if j in joints:
                return name
            j = model.parents[j]
    return ""


def robot_bodies(robot: object) -> list[Body]:
    """The robot's collision bodies: its URDF capsules plus taplan's sized primitives (TeleAvatar)."""
    model = robot.model  # type: ignore[attr-defined]
    bodies = [
        Body(c.name, c.joint, np.asarray(c.start), np.asarray(c.end), c.radius, _group_of(robot, c.joint))
        for c in robot.capsules  # type: ignore[attr-defined]
    ]
    names = set(robot.joint_names)  # type: ignore[attr-defined]
    if {"l_joint1", "r_joint1"} <= names:
        data = model.createData()
        pin.forwardKinematics(model, data, pin.neutral(model))
        left = data.oMi[model.getJointId("l_joint1")].translation.copy()
        right = data.oMi[model.getJointId("r_joint1")].translation.copy()
        mid = (left + right) / 2
        bodies.append(Body("chest", 0, left, right, 0.06, "", "between the l_joint1/r_joint1 origins, radius 0.06"))
        head = mid + np.array([0.0, 0.0, 0.25])
        bodies.append(Body("head", 0, head, head.copy(), 0.11, "", "estimate: sphere 0.11 m, 0.25 m above shoulders"))
    return bodies


def _segments(model: pin.Model, data: pin.Data, bodies: list[Body]) -> list[tuple[np.ndarray, np.ndarray]]:
    out = []
    for b in bodies:
        M = data.oMi[b.joint]
        out.append((M.act(b.start), M.act(b.end)))
    return out


def allowed_pairs(robot: object, bodies: list[Body]) -> set[frozenset[str]]:
    """Pairs never checked: same arm, or within ``ALLOWED_CONTACT`` at ``robot.home``."""
    model = robot.model  # type: ignore[attr-defined]
    data = model.createData()
    pin.forwardKinematics(model, data, np.asarray(robot.home))  # type: ignore[attr-defined]
    segments = _segments(model, data, bodies)
    allowed: set[frozenset[str]] = set()
    for i, a in enumerate(bodies):
        for j in range(i + 1, len(bodies)):
            b = bodies[j]
            if a.joint == 0 and b.joint == 0:
                allowed.add(frozenset((a.name, b.name)))  # both fixed: never move relative to each other
                continue
            if a.group and a.group == b.group:
                allowed.add(frozenset((a.name, b.name)))
                continue
            pa, pb, _, _ = segment_closest_points(*segments[i], *segments[j])
            if float(np.linalg.norm(pa - pb)) - a.radius - b.radius < ALLOWED_CONTACT:
                allowed.add(frozenset((a.name, b.name)))
    return allowed
