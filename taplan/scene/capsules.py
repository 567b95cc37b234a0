"""Collision capsules attached to robot links, and closed-form capsule distances.

taplan represents each collision body as a capsule: a segment with a radius. A URDF ``<cylinder>`` collision element
(axis along its local z, centred at its origin) is read as the capsule of the same radius around the same segment,
which contains the cylinder; it keeps the element's ``name`` attribute when it has one (pinocchio numbers a link's
elements ``<link>_<i>``). Other shapes are ignored (listed in ``skipped``). The distance between two capsules is
the distance between their segments minus both radii, computed in closed form.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

__all__ = ["Capsule", "capsules_from_urdf", "segment_closest_points", "capsule_distance", "read_srdf"]


@dataclass(frozen=True)
class Capsule:
    """A capsule fixed to a link.

    Attributes:
        name: Geometry name (the pinocchio geometry object's name).
        link: Name of the link (body frame) that carries it.
        joint: Index of the pinocchio joint that moves it.
        start: Segment start in the joint frame [m]. Shape (3,).
        end: Segment end in the joint frame [m]. Shape (3,).
        radius: Capsule radius [m].
    """

    name: str
    link: str
    joint: int
    start: np.ndarray
    end: np.ndarray
    radius: float

    def world_segment(self, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        """Segment end points in the root frame [m], from ``data.oMi`` (call forwardKinematics first)."""
        placement = data.oMi[self.joint]
        return placement.act(self.start), placement.act(self.end)


def capsules_from_urdf(model: pin.Model, urdf_path: str | Path) -> tuple[list[Capsule], list[str]]:
    """Read the cylinder collision elements of ``urdf_path`` as capsules.

    Returns:
        The capsules, and the names of collision objects that are not cylinders (skipped).
    """
    geometry = pin.buildGeomFromUrdf(model, str(urdf_path), pin.GeometryType.COLLISION)
    names = _collision_names(urdf_path)
    capsules: list[Capsule] = []
    skipped: list[str] = []
    for obj in geometry.geometryObjects:
        shape = obj.geometry
        half = getattr(shape, "halfLength", None)
        if type(shape).__name__ not in ("Cylinder", "Capsule") or half is None:
            skipped.append(obj.name)
            continue
        placement = obj.placement
        start = placement.act(np.array([0.0, 0.0, -half]))
        end = placement.act(np.array([0.0, 0.0, half]))
        link = model.frames[obj.parentFrame].name
        name = names.get(obj.name, obj.name)
        capsules.append(Capsule(name, link, int(obj.parentJoint), start, end, float(shape.radius)))
    return capsules, skipped


def _collision_names(urdf_path: str | Path) -> dict[str, str]:
    """pinocchio's ``<link>_<i>`` geometry names -> the URDF collision elements' own ``name`` attributes."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(str(urdf_path)).getroot()
    except (ET.ParseError, OSError):
        return {}
    out = {}
    for link in root.iter("link"):
        for i, collision in enumerate(link.findall("collision")):
            if collision.get("name"):
                out[f"{link.get('name')}_{i}"] = collision.get("name")
    return out


def segment_closest_points(
    p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Closest points between segments [p0, p1] and [q0, q1].

    Returns:
        (point on the first segment, point on the second, its parameter s in [0, 1], the second's t in [0, 1]).
    """
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = float(d1 @ d1)
    e = float(d2 @ d2)
    f = float(d2 @ r)
    eps = 1e-12
    if a <= eps and e <= eps:
        return p0, q0, 0.0, 0.0
    if a <= eps:
        s, t = 0.0, min(max(f / e, 0.0), 1.0)
    else:
        c = float(d1 @ r)
        if e <= eps:
            s, t = min(max(-c / a, 0.0), 1.0), 0.0
        else:
            b = float(d1 @ d2)
            denom = a * e - b * b
            s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > eps else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t, s = 0.0, min(max(-c / a, 0.0), 1.0)
            elif t > 1.0:
                t, s = 1.0, min(max((b - c) / a, 0.0), 1.0)
    return p0 + s * d1, q0 + t * d2, s, t


def capsule_distance(data: pin.Data, first: Capsule, second: Capsule) -> float:
    """Signed distance between two capsules [m] (negative when they overlap) at the state held in ``data``."""
    a0, a1 = first.world_segment(data)
    b0, b1 = second.world_segment(data)
    pa, pb, _, _ = segment_closest_points(a0, a1, b0, b1)
    return float(np.linalg.norm(pa - pb)) - first.radius - second.radius


def read_srdf(path: str | Path) -> frozenset[frozenset[str]]:
    """The ``disable_collisions`` pairs of an SRDF file."""
    import xml.etree.ElementTree as ET

    root = ET.parse(str(path)).getroot()
    return frozenset(frozenset((e.get("link1", ""), e.get("link2", ""))) for e in root.iter("disable_collisions"))
