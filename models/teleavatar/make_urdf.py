"""Regenerate ``teleavatar.urdf`` from the vendor's dual-arm URDF (urdf20260625).

Provenance script, not part of the package. It copies the kinematic numbers (joint origins, axes and limits; link
inertials) of the vendor's file, drops the meshes, and adds taplan's collision capsules and named frames::

    python models/teleavatar/make_urdf.py ../shared/reference/teleavatar/urdf20260625.urdf \
        > models/teleavatar/teleavatar.urdf
    python models/teleavatar/make_urdf.py --srdf models/teleavatar/teleavatar.srdf   # allowed pairs, by sweeping

The SRDF lists the body pairs never checked for collision, classified by sweeping 20,000 seeded configurations
over the planning limits (``taplan.scene.robot_bodies.sweep_pairs``; ~1 min).
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin

# Collision capsules [m]: (name, link, start, end, radius), start/end in the frame of the link that carries them
# ("root": taplan's root frame shoulder_base, x forward, y left, z up; written on base_link). Fitted to the real
# body's surface (the TeleAvatar 2.0's published convex collision pieces, placed by its kinematics) by
# ``models/teleavatar/real_body.py fit``: every reference point of tests/data/real_body_points.npz is inside (the
# coverage table is in docs/robot.md; ``real_body.py coverage`` recomputes it). One capsule per arm link, two for
# the gripper body with its finger linkage, one for the wrist camera, one per finger over the whole opening range;
# the torso as head, shoulders and torso, the lift carriage and the lift column behind it (over the lift's travel).
# Cylinders in the file stand for capsules of the same radius around the same segment (caps included), which is how
# taplan reads them.
CAPSULES = [
    ("left_link1", "Link-L1", (-0.0016, 0.005, 0.0222), (0.0025, -0.019, -0.1287), 0.0730),
    ("left_link2", "Link-L2", (0.09, -0.0009, 0.028), (-0.0014, 0.0055, -0.0137), 0.0614),
    ("left_link3", "Link-L3", (0.0002, 0.0005, -0.0227), (0.0202, -0.0184, -0.1385), 0.0723),
    ("left_link4", "Link-L4", (0.0759, -0.0306, 0.0045), (0.0141, -0.0061, -0.0021), 0.0496),
    ("left_link5", "Link-L5", (-0.0009, -0.0011, -0.0156), (-0.0097, -0.0023, -0.15), 0.0609),
    ("left_link6", "Link-L6", (0.0023, -0.0068, -0.0138), (0.0008, -0.0037, -0.0416), 0.0428),
    ("left_gripper_0", "Link-L7", (-0.0026, 0.0479, -0.0194), (-0.0005, 0.0747, -0.0345), 0.0691),
    ("left_gripper_1", "Link-L7", (-0.0028, 0.1352, 0.0087), (-0.002, 0.1482, -0.0759), 0.0300),
    ("left_wrist_camera", "Link-L7", (0.043, 0.094, -0.0133), (0.0434, 0.0933, -0.0563), 0.0235),
    ("left_fingers_0", "Link-L7", (0.0004, 0.136, -0.0728), (-0.0033, 0.2076, -0.0596), 0.0346),
    ("left_fingers_1", "Link-L7", (-0.0046, 0.2072, -0.01), (-0.0003, 0.1362, 0.0031), 0.0345),
    ("right_link1", "Link-R1", (-0.0032, 0.0012, 0.0211), (0.0194, -0.0036, -0.1285), 0.0732),
    ("right_link2", "Link-R2", (-0.0881, -0.0018, 0.03), (-0.0107, 0.0076, 0.0034), 0.0639),
    ("right_link3", "Link-R3", (-0.0019, -0.0017, -0.0045), (0.0216, 0.0185, -0.1397), 0.0723),
    ("right_link4", "Link-R4", (0.0789, 0.0307, 0.0219), (0.0109, 0.0039, -0.0042), 0.0493),
    ("right_link5", "Link-R5", (0.0004, 0.0018, -0.0172), (-0.008, 0.0017, -0.1514), 0.0609),
    ("right_link6", "Link-R6", (0.0023, 0.0046, -0.0135), (-0.0004, 0.0027, -0.0426), 0.0418),
    ("right_gripper_0", "Link-R7", (0.0042, -0.0442, -0.0033), (0.0069, -0.0914, -0.0347), 0.0612),
    ("right_gripper_1", "Link-R7", (-0.0011, -0.1456, -0.0711), (-0.0011, -0.1354, 0.0106), 0.0323),
    ("right_wrist_camera", "Link-R7", (0.0443, -0.0958, -0.011), (0.0446, -0.0953, -0.0549), 0.0234),
    ("right_fingers_0", "Link-R7", (0.0003, -0.2098, -0.0576), (0.0015, -0.1384, -0.0707), 0.0346),
    ("right_fingers_1", "Link-R7", (0.0002, -0.2111, -0.0096), (0.0021, -0.1379, 0.0053), 0.0346),
    ("head", "root", (-0.0012, 0.0455, 0.1976), (-0.0044, -0.0346, 0.186), 0.1356),
    ("shoulders", "root", (-0.0214, 0.0278, 0.0263), (-0.0147, -0.0302, 0.021), 0.1794),
    ("torso", "root", (-0.0346, -0.0064, -0.1577), (-0.0278, 0.0063, -0.1641), 0.1636),
    # The lift carriage behind the torso (rigid with it; robot.xml: body_link is fixed to it).
    ("carriage", "root", (-0.1955, 0.0008, -0.1501), (-0.1234, -0.0098, -0.1501), 0.0922),
    # The lift column behind the torso, over the lift's whole travel (0..0.74 m): it stands on the mobile base while
    # the torso rides the lift, so seen from the torso it reaches from 1.18 m below the shoulders (lift up) to 0.76 m
    # above them (lift down).
    ("column", "root", (-0.2243, -0.0065, -1.1647), (-0.2297, 0.0015, 0.698), 0.1155),
]

# Named frames: (name, parent link, xyz [m], rpy [rad]).
FRAMES = [
    # Wrist centre (where the joint-6 and joint-7 axes meet), axes of Link-7: x forward, y left, z up at q = 0.
    # This is the point and orientation the robot's own end-effector interface reports (see docs/conventions.md).
    ("left_ee", "Link-L7", (0.0, 0.0, -0.031), (0.0, 0.0, 0.0)),
    ("right_ee", "Link-R7", (0.0, 0.0, -0.031), (0.0, 0.0, 0.0)),
    # Midpoint of the two finger bases, same axes as *_ee: a grasp point for tasks that need the fingers.
    ("left_tcp", "Link-L7", (0.010, 0.177, -0.031), (0.0, 0.0, 0.0)),
    ("right_tcp", "Link-R7", (0.010, -0.177, -0.031), (0.0, 0.0, 0.0)),
    # Shoulder centres (where the joint-1, -2 and -3 axes meet), axes of shoulder_base.
    ("left_shoulder_base", "shoulder_base", (0.0, 0.2197, 0.0008), (0.0, 0.0, 0.0)),
    ("right_shoulder_base", "shoulder_base", (0.0, -0.2201, 0.0019), (0.0, 0.0, 0.0)),
]

# base_link is shoulder_base turned +90 deg about z (the vendor's joint shoulder_base_to_base)
_ROOT_TO_BASE_LINK = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def asked_capsules() -> list[tuple[str, str, tuple, tuple, float]]:
    """Every capsule this script writes: (name, link, start, end, radius) in that link's frame [m]."""
    out = []
    for name, link, start, end, radius in CAPSULES:
        if link == "root":
            link = "base_link"
            start, end = (tuple((_ROOT_TO_BASE_LINK @ np.asarray(p, float)).tolist()) for p in (start, end))
        out.append((name, link, tuple(start), tuple(end), radius))
    return out


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


def _capsule_element(name: str, start, end, radius: float) -> ET.Element:
    start, end = np.asarray(start, float), np.asarray(end, float)
    collision = ET.Element("collision", name=name)
    ET.SubElement(collision, "origin", xyz=_fmt((start + end) / 2), rpy=_fmt(_rpy_z_to(end - start)))
    geometry = ET.SubElement(collision, "geometry")
    # 10 digits: a 6-digit length put the ends of the 1.9 m column 2.5 um off
    ET.SubElement(geometry, "cylinder", radius=f"{radius:g}", length=f"{np.linalg.norm(end - start):.10g}")
    return collision


def build(vendor_path: str) -> str:
    vendor = ET.parse(vendor_path).getroot()
    robot = ET.Element("robot", name="teleavatar")
    capsules: dict[str, list] = {}
    for name, link, start, end, radius in asked_capsules():
        capsules.setdefault(link, []).append((name, start, end, radius))
    for element in vendor:
        if element.tag == "link":
            link = ET.SubElement(robot, "link", name=element.get("name"))
            inertial = element.find("inertial")
            if inertial is not None:
                link.append(inertial)
            for name, start, end, radius in capsules.get(link.get("name"), []):
                link.append(_capsule_element(name, start, end, radius))
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
        "     vendor's urdf20260625; no meshes. Collision cylinders are read by taplan as capsules, fitted to the\n"
        "     real body by models/teleavatar/real_body.py. Generated by models/teleavatar/make_urdf.py. -->\n"
    )
    return header + ET.tostring(robot, encoding="unicode") + "\n"


def write_srdf(path: str) -> None:
    import taplan
    from taplan.scene.robot_bodies import robot_bodies, sweep_pairs
    from taplan.scene.robot_bodies import write_srdf as write

    robot = taplan.Robot.teleavatar()
    bodies = robot_bodies(robot)
    allowed, lowest = sweep_pairs(robot, bodies, samples=20000, seed=0)
    header = (
        "Body pairs never checked for collision (MoveIt's disable_collisions, naming taplan's bodies), from\n"
        "     sweeping 20000 seeded configurations over the planning limits\n"
        "     (models/teleavatar/make_urdf.py, option srdf)"
    )
    write(path, "teleavatar", allowed, header)
    checked = len(lowest) - len(allowed)
    sys.stderr.write(f"{len(allowed)} pairs allowed, {checked} checked, of {len(lowest)}\n")


if __name__ == "__main__":
    if sys.argv[1] == "--srdf":
        write_srdf(sys.argv[2])
    else:
        sys.stdout.write(build(sys.argv[1]))
