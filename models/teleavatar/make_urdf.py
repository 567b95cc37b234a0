"""Regenerate ``teleavatar.urdf`` from the vendor's dual-arm URDF (urdf20260625).

Provenance script, not part of the package. It copies the kinematic numbers (joint origins, axes and limits; link
inertials) of the vendor's file, drops the meshes, and adds taplan's collision capsules and named frames::

    python models/teleavatar/make_urdf.py ../shared/reference/teleavatar/urdf20260625.urdf \
        > models/teleavatar/teleavatar.urdf
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

# Collision capsules [m], in the frame of the link that carries them: (link, start, end, radius).
# The vendor ships meshes only; these are sized from the joint origins (segment ends) and a generous estimate of
# the link girth (radius), so they over-approximate the arm. Cylinders in the file stand for capsules of the same
# radius around the same segment (caps included), which is how taplan reads them.
CAPSULES = {
    "L": [
        ("Link-L3", (0.0, 0.0, 0.1286), (0.0300, 0.0040, -0.1455), 0.050),  # upper arm: shoulder centre to elbow
        ("Link-L4", (0.0, 0.0, 0.0), (0.2761, -0.0304, 0.0031), 0.045),  # forearm: elbow to wrist centre
        ("Link-L7", (0.0, 0.0, -0.031), (0.010, 0.200, -0.031), 0.045),  # hand and gripper: wrist centre to fingers
    ],
    "R": [
        ("Link-R3", (0.0, 0.0, 0.1284), (0.0300, -0.0210, -0.1455), 0.050),
        ("Link-R4", (0.0, 0.0, 0.0), (0.2754, 0.0306, 0.0210), 0.045),
        ("Link-R7", (0.0, 0.0, -0.031), (0.010, -0.200, -0.031), 0.045),
    ],
}

# Named frames: (name, parent link, xyz [m], rpy [rad]).
FRAMES = [
    # Wrist centre (where the joint-6 and joint-7 axes meet), axes of Link-7: x forward, y left, z up at q = 0.
    # This is the point and orientation the robot's own end-effector interface reports (see models/README.md).
    ("left_ee", "Link-L7", (0.0, 0.0, -0.031), (0.0, 0.0, 0.0)),
    ("right_ee", "Link-R7", (0.0, 0.0, -0.031), (0.0, 0.0, 0.0)),
    # Midpoint of the two finger bases, same axes as *_ee: a grasp point for tasks that need the fingers.
    ("left_tcp", "Link-L7", (0.010, 0.177, -0.031), (0.0, 0.0, 0.0)),
    ("right_tcp", "Link-R7", (0.010, -0.177, -0.031), (0.0, 0.0, 0.0)),
    # Shoulder centres (where the joint-1, -2 and -3 axes meet), axes of shoulder_base.
    ("left_shoulder_base", "shoulder_base", (0.0, 0.2197, 0.0008), (0.0, 0.0, 0.0)),
    ("right_shoulder_base", "shoulder_base", (0.0, -0.2201, 0.0019), (0.0, 0.0, 0.0)),
]

TORSO = ("base_link", (0.0, 0.0, -0.08), (0.0, 0.0, -0.45), 0.07)  # torso column below the shoulder line


def asked_capsules() -> list[tuple[str, tuple, tuple, float]]:
    """Every capsule this script writes: (link, start, end, radius) in the link's frame [m]."""
    return [c for side in CAPSULES.values() for c in side] + [TORSO]


def _fmt(values) -> str:
    return " ".join(f"{v:.10g}" for v in values)


def _rpy_z_to(direction: np.ndarray) -> tuple[float, float, float]:
    """rpy of a rotation whose z axis points along ``direction``.

    The rotation is the shortest one from z to ``direction`` (a quaternion from the two vectors), converted to rpy
    by pinocchio; at pitch +-90 deg (a direction in the x-y plane with no z) rpy is not unique, and pinocchio
    returns one of the equivalent triples, so the round trip rpy -> matrix -> z axis is exact for every direction.
    An earlier hand-written conversion lost the yaw there and turned the hand capsules 90 deg.
    """
    z = np.asarray(direction, float) / np.linalg.norm(direction)
    rot = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), z).matrix()
    roll, pitch, yaw = pin.rpy.matrixToRpy(rot)
    return float(roll), float(pitch), float(yaw)


def _capsule_element(start, end, radius: float) -> ET.Element:
    start, end = np.asarray(start, float), np.asarray(end, float)
    collision = ET.Element("collision")
    ET.SubElement(collision, "origin", xyz=_fmt((start + end) / 2), rpy=_fmt(_rpy_z_to(end - start)))
    geometry = ET.SubElement(collision, "geometry")
    ET.SubElement(geometry, "cylinder", radius=f"{radius:g}", length=f"{np.linalg.norm(end - start):.6g}")
    return collision


def build(vendor_path: str) -> str:
    vendor = ET.parse(vendor_path).getroot()
    robot = ET.Element("robot", name="teleavatar")
    capsules = {c[0]: c for c in asked_capsules()}
    for element in vendor:
        if element.tag == "link":
            link = ET.SubElement(robot, "link", name=element.get("name"))
            inertial = element.find("inertial")
            if inertial is not None:
                link.append(inertial)
            if link.get("name") in capsules:
                _, start, end, radius = capsules[link.get("name")]
                link.append(_capsule_element(start, end, radius))
        elif element.tag == "joint":
            joint = ET.SubElement(robot, "joint", name=element.get("name"), type=element.get("type"))
            for child in element:
                if child.tag in ("origin", "parent", "child", "axis", "limit"):
                    joint.append(child)
    for name, parent, xyz, rpy in FRAMES:
        ET.SubElement(robot, "link", name=name)
        joint = ET.SubElement(robot, "joint", name=f"{name}_joint", type="fixed")
        ET.SubElement(joint, "origin", xyz=_fmt(xyz), rpy=_fmt(rpy))
        ET.SubElement(joint, "parent", link=parent)
        ET.SubElement(joint, "child", link=name)
    ET.indent(robot, space="  ")
    header = (
        '<?xml version="1.0"?>\n'
        "<!-- taplan's kinematic model of the TeleAvatar (TA1.0) dual arm. Root shoulder_base: midpoint of the\n"
        "     shoulders, x forward, y left, z up. Joint origins, axes, limits and inertials carry the numbers of the\n"
        "     vendor's urdf20260625; no meshes. Collision cylinders are read by taplan as capsules. Generated by\n"
        "     models/teleavatar/make_urdf.py. -->\n"
    )
    return header + ET.tostring(robot, encoding="unicode") + "\n"


if __name__ == "__main__":
    sys.stdout.write(build(sys.argv[1]))
