"""The robot's own collision bodies and the pairs that are allowed to touch, in one place.

Bodies are capsules on links (a sphere is a capsule of zero length): the URDF's collision cylinders, read as the
capsules around them (:mod:`taplan.scene.capsules`). For the bundled TeleAvatar they are fitted to the real robot's
body (every part: arm links, gripper body with the finger linkage, fingers, wrist cameras, torso, shoulders, head,
head camera, lift carriage, and the lift column over the lift's travel; see ``models/teleavatar/real_body.py`` and
``docs/robot.md``).

**Allowed pairs** (never checked) come from the robot's SRDF when it has one (``<urdf stem>.srdf`` next to the
URDF, MoveIt's ``disable_collisions`` elements, here naming bodies), derived by :func:`sweep_pairs` over the joint
ranges, the rule of MoveIt's setup assistant:

* ``Rigid``: both bodies on the same joint (or both fixed to the root): they never move relative to each other;
* ``Adjacent``: bodies on a joint and on its parent joint;
* ``Default``: in contact (closer than ``ALLOWED_CONTACT``) at the home configuration;
* ``Always``: in contact in at least ``ALWAYS_FRACTION`` of the sampled configurations;
* ``Never``: never in collision over the samples: pairs moved by at most ``DENSE_JOINTS`` joints (the samples
  cover those few dimensions densely) that never overlap (the shoulder housing and the upper arm, kept apart by
  the joint limits, pass within 2 mm: checking them would only turn margins into false stops); the others when
  never closer than ``NEVER_CLOSE`` (a margin for what sampling 14 joints can miss), skipped for speed.

Without an SRDF (other robots), bodies on the same arm group and pairs in contact at home are allowed.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from taplan.errors import InvalidInputError
from taplan.scene.capsules import read_srdf, segment_closest_points

__all__ = [
    "Body",
    "robot_bodies",
    "allowed_pairs",
    "sweep_pairs",
    "read_srdf",
    "write_srdf",
    "ALLOWED_CONTACT",
]

ALLOWED_CONTACT = 0.005  # [m] pairs closer than this at home are allowed to touch
ALWAYS_FRACTION = 0.95  # pairs in contact in at least this fraction of the sampled configurations
DENSE_JOINTS = 3  # pairs moved by at most this many joints are sampled densely
NEVER_CLOSE = 0.10  # [m] other pairs never closer than this over the samples are skipped


@dataclass(frozen=True)
class Body:
    """A capsule fixed to a joint's frame (``joint`` 0: fixed to the root).

    Attributes:
        name: Body name (the URDF collision element's, else pinocchio's ``<link>_<i>``).
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


GRIPPER_WORDS = {"closed": 0.0, "open": 1.0}


def robot_bodies(robot: object, gripper: object = None) -> list[Body]:
    """The robot's collision bodies: its URDF capsules, with the arm group that moves each.

    Args:
        robot: The robot.
        gripper: The grippers' opening when known (0 closed .. 1 open, the gripper's input): a number or
            ``"open"`` / ``"closed"`` for both hands, or ``{"left": ..., "right": ...}`` (None: unknown). A known
            opening replaces the fingers' conservative bodies (the whole opening range) by the ones fitted to the
            opening interval that contains it (the robot's ``<urdf>.gripper.yaml``); None keeps them.
    """
    bodies = [
        Body(c.name, c.joint, np.asarray(c.start), np.asarray(c.end), c.radius, _group_of(robot, c.joint))
        for c in robot.capsules  # type: ignore[attr-defined]
    ]
    if gripper is None:
        return bodies
    states = getattr(robot, "gripper_states", None)
    if not states:
        raise InvalidInputError("gripper", gripper, "None: this robot has no gripper states (<urdf>.gripper.yaml)")
    by_name = {b.name: k for k, b in enumerate(bodies)}
    model = robot.model  # type: ignore[attr-defined]
    for hand, opening in _openings(gripper, states).items():
        entry = states[f"{hand}_fingers"]
        state = next(s for s in entry["states"] if float(s["opening"][0]) <= opening <= float(s["opening"][1]))
        frame = model.frames[model.getFrameId(entry["link"])]
        for name, capsule in zip(entry["bodies"], state["capsules"], strict=True):
            k = by_name[name]
            start = frame.placement.act(np.asarray(capsule["start"], float))
            end = frame.placement.act(np.asarray(capsule["end"], float))
            source = f"fingers at opening {float(state['opening'][0]):g}-{float(state['opening'][1]):g}"
            bodies[k] = Body(name, bodies[k].joint, start, end, float(capsule["radius"]), bodies[k].group, source)
    return bodies


def _openings(gripper: object, states: dict) -> dict[str, float]:
    """``{hand: opening}`` for the hands whose opening is known."""
    hands = [key.removesuffix("_fingers") for key in states]
    if isinstance(gripper, dict):
        unknown = set(gripper) - set(hands)
        if unknown:
            raise InvalidInputError("gripper", gripper, f"a mapping with keys from {hands}")
        items = [(hand, value) for hand, value in gripper.items() if value is not None]
    else:
        items = [(hand, gripper) for hand in hands]
    out = {}
    for hand, value in items:
        value = GRIPPER_WORDS.get(value, value) if isinstance(value, str) else value
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= float(value) <= 1.0:
            raise InvalidInputError("gripper", gripper, "an opening in [0, 1] (0 closed), 'open', 'closed' or None")
        out[hand] = float(value)
    return out


def _segments(model: pin.Model, data: pin.Data, bodies: list[Body]) -> list[tuple[np.ndarray, np.ndarray]]:
    out = []
    for b in bodies:
        M = data.oMi[b.joint]
        out.append((M.act(b.start), M.act(b.end)))
    return out


def allowed_pairs(robot: object, bodies: list[Body]) -> set[frozenset[str]]:
    """Pairs never checked: the robot's SRDF pairs (see the module), else same arm or in contact at home."""
    disabled = getattr(robot, "disabled_pairs", None)
    allowed: set[frozenset[str]] = set()
    for i, a in enumerate(bodies):
        for b in bodies[i + 1 :]:
            if a.joint == b.joint:  # rigidly attached: whatever the SRDF says, they never move apart
                allowed.add(frozenset((a.name, b.name)))
    if disabled is not None:
        return allowed | set(disabled)
    model = robot.model  # type: ignore[attr-defined]
    data = model.createData()
    pin.forwardKinematics(model, data, np.asarray(robot.home))  # type: ignore[attr-defined]
    segments = _segments(model, data, bodies)
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


def _path_joints(model: pin.Model, a: int, b: int) -> int:
    """Number of joints on the kinematic-tree path between joints ``a`` and ``b`` (what moves one relative to the
    other)."""
    chain_a, j = [], a
    while j > 0:
        chain_a.append(j)
        j = model.parents[j]
    chain_b, j = [], b
    while j > 0:
        chain_b.append(j)
        j = model.parents[j]
    common = set(chain_a) & set(chain_b)
    return len([j for j in chain_a if j not in common]) + len([j for j in chain_b if j not in common])


def sweep_pairs(
    robot: object, bodies: list[Body], samples: int = 20000, seed: int = 0
) -> tuple[dict[frozenset[str], str], dict[frozenset[str], float]]:
    """Classify every body pair over ``samples`` configurations drawn uniformly within the planning limits (and
    home): returns the allowed pairs with their reason (module docstring) and every pair's smallest distance [m]."""
    from taplan.scene.world import _closest_points

    model = robot.model  # type: ignore[attr-defined]
    lim = robot.planning_limits  # type: ignore[attr-defined]
    rng = np.random.default_rng(seed)
    Q = rng.uniform(lim.lower, lim.upper, size=(samples, model.nq))
    Q[0] = np.asarray(robot.home)  # type: ignore[attr-defined]
    data = model.createData()
    B = len(bodies)
    starts, ends = np.zeros((samples, B, 3)), np.zeros((samples, B, 3))
    local_a = np.array([b.start for b in bodies])
    local_b = np.array([b.end for b in bodies])
    joints = [b.joint for b in bodies]
    for n, q in enumerate(Q):
        pin.forwardKinematics(model, data, q)
        for k, j in enumerate(joints):
            M = data.oMi[j]
            starts[n, k] = M.rotation @ local_a[k] + M.translation
            ends[n, k] = M.rotation @ local_b[k] + M.translation
    first, second = np.triu_indices(B, 1)
    radius = np.array([b.radius for b in bodies])
    d = np.empty((samples, len(first)))
    chunk = max(1, 200000 // max(len(first), 1))
    for lo in range(0, samples, chunk):
        s, e = starts[lo : lo + chunk], ends[lo : lo + chunk]
        pa, pb = _closest_points(
            s[:, first].reshape(-1, 3),
            e[:, first].reshape(-1, 3),
            s[:, second].reshape(-1, 3),
            e[:, second].reshape(-1, 3),
        )
        d[lo : lo + chunk] = np.linalg.norm(pa - pb, axis=1).reshape(len(s), -1) - (radius[first] + radius[second])
    allowed: dict[frozenset[str], str] = {}
    lowest: dict[frozenset[str], float] = {}
    for k, (i, j) in enumerate(zip(first, second, strict=True)):
        a, b = bodies[i], bodies[j]
        pair = frozenset((a.name, b.name))
        lowest[pair] = float(d[:, k].min())
        contact = d[:, k] < ALLOWED_CONTACT
        if a.joint == b.joint:
            allowed[pair] = "Rigid"
        elif model.parents[a.joint] == b.joint or model.parents[b.joint] == a.joint:
            allowed[pair] = "Adjacent"
        elif contact[0]:
            allowed[pair] = "Default"
        elif contact.mean() >= ALWAYS_FRACTION:
            allowed[pair] = "Always"
        elif _path_joints(model, a.joint, b.joint) <= DENSE_JOINTS and lowest[pair] > 0.0 or lowest[pair] > NEVER_CLOSE:
            allowed[pair] = "Never"
    return allowed, lowest


def write_srdf(path: str | Path, robot_name: str, allowed: dict[frozenset[str], str], header: str = "") -> None:
    """Write ``allowed`` pairs as an SRDF's ``disable_collisions`` elements (sorted: a stable file)."""
    root = ET.Element("robot", name=robot_name)
    for pair, reason in sorted(allowed.items(), key=lambda item: sorted(item[0])):
        first, second = sorted(pair)
        ET.SubElement(root, "disable_collisions", link1=first, link2=second, reason=reason)
    ET.indent(root, space="  ")
    text = '<?xml version="1.0"?>\n' + (f"<!-- {header} -->\n" if header else "")
    Path(path).write_text(text + ET.tostring(root, encoding="unicode") + "\n")
