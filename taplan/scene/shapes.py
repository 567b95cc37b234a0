"""Obstacle shapes in their own frame (SI units), and their coal collision geometry.

Every shape is centred at its frame's origin; capsules and cylinders have their axis along the frame's z. A
``HalfSpace`` is the solid ``z <= 0`` of its frame: a table top is a half-space (or a thin box) posed at the table's
height. Meshes are triangle soups (coal BVH): their distance is exact outside and 0 in contact (no penetration depth).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from taplan.errors import InvalidInputError

__all__ = ["Shape", "Box", "Sphere", "Capsule", "Cylinder", "HalfSpace", "Mesh", "SHAPES"]


def _positive(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
        raise InvalidInputError(name, value, "a positive length [m]")
    return float(value)


class Shape:
    """Base of the obstacle shapes."""

    kind: str = ""

    def to_coal(self) -> Any:
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:
        raise NotImplementedError

    def bounding_radius(self) -> float:
        """Radius [m] of a sphere about the frame origin that contains the shape (inf for a half-space)."""
        raise NotImplementedError


@dataclass(frozen=True)
class Box(Shape):
    """A box with full edge lengths ``size`` [m] (x, y, z)."""

    size: tuple[float, float, float]
    kind = "box"

    def __post_init__(self) -> None:
        size = np.asarray(self.size, dtype=float).ravel() if not isinstance(self.size, str) else np.zeros(0)
        if size.shape != (3,):
            raise InvalidInputError("size", self.size, "3 edge lengths [m]")
        object.__setattr__(self, "size", tuple(_positive(float(v), "size") for v in size))

    def to_coal(self) -> Any:
        import coal

        return coal.Box(*self.size)

    def to_dict(self) -> dict[str, Any]:
        return {"type": "box", "size": list(self.size)}

    def bounding_radius(self) -> float:
        return 0.5 * float(np.linalg.norm(self.size))


@dataclass(frozen=True)
class Sphere(Shape):
    """A sphere of ``radius`` [m]."""

    radius: float
    kind = "sphere"

    def __post_init__(self) -> None:
        object.__setattr__(self, "radius", _positive(self.radius, "radius"))

    def to_coal(self) -> Any:
        import coal

        return coal.Sphere(self.radius)

    def to_dict(self) -> dict[str, Any]:
        return {"type": "sphere", "radius": self.radius}

    def bounding_radius(self) -> float:
        return self.radius


@dataclass(frozen=True)
class Capsule(Shape):
    """A capsule: the points within ``radius`` [m] of the z-axis segment of ``length`` [m] about the origin."""

    radius: float
    length: float
    kind = "capsule"

    def __post_init__(self) -> None:
        object.__setattr__(self, "radius", _positive(self.radius, "radius"))
        object.__setattr__(self, "length", _positive(self.length, "length"))

    def to_coal(self) -> Any:
        import coal

        return coal.Capsule(self.radius, self.length)

    def to_dict(self) -> dict[str, Any]:
        return {"type": "capsule", "radius": self.radius, "length": self.length}

    def bounding_radius(self) -> float:
        return self.radius + self.length / 2


@dataclass(frozen=True)
class Cylinder(Shape):
    """A cylinder of ``radius`` and ``length`` [m] along z, centred."""

    radius: float
    length: float
    kind = "cylinder"

    def __post_init__(self) -> None:
        object.__setattr__(self, "radius", _positive(self.radius, "radius"))
        object.__setattr__(self, "length", _positive(self.length, "length"))

    def to_coal(self) -> Any:
        import coal

        return coal.Cylinder(self.radius, self.length)

    def to_dict(self) -> dict[str, Any]:
        return {"type": "cylinder", "radius": self.radius, "length": self.length}

    def bounding_radius(self) -> float:
        return math.hypot(self.radius, self.length / 2)


@dataclass(frozen=True)
class HalfSpace(Shape):
    """The solid ``z <= 0`` of its frame (e.g. everything below a table top)."""

    kind = "halfspace"

    def to_coal(self) -> Any:
        import coal

        return coal.Halfspace(np.array([0.0, 0.0, 1.0]), 0.0)

    def to_dict(self) -> dict[str, Any]:
        return {"type": "halfspace"}

    def bounding_radius(self) -> float:
        return math.inf


@dataclass(frozen=True)
class Mesh(Shape):
    """A triangle mesh: ``vertices`` [m] (V, 3) and ``faces`` (F, 3) vertex indices."""

    vertices: np.ndarray = field(repr=False)
    faces: np.ndarray = field(repr=False)
    kind = "mesh"

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=float)
        f = np.asarray(self.faces)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) < 3 or not np.all(np.isfinite(v)):
            raise InvalidInputError("vertices", v.shape, "(V, 3) finite positions [m], V >= 3")
        if f.ndim != 2 or f.shape[1] != 3 or len(f) < 1 or not np.issubdtype(f.dtype, np.integer):
            raise InvalidInputError("faces", f.shape, "(F, 3) integer vertex indices")
        if f.min() < 0 or f.max() >= len(v):
            raise InvalidInputError("faces", f"indices {f.min()}..{f.max()}", f"indices in [0, {len(v) - 1}]")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f.astype(int))

    def to_coal(self) -> Any:
        import coal

        model = coal.BVHModelOBBRSS()
        model.beginModel(len(self.faces), len(self.vertices))
        model.addVertices(self.vertices)
        model.addTriangles(self.faces)
        model.endModel()
        return model

    def to_dict(self) -> dict[str, Any]:
        return {"type": "mesh", "vertices": self.vertices.tolist(), "faces": self.faces.tolist()}

    def bounding_radius(self) -> float:
        return float(np.max(np.linalg.norm(self.vertices, axis=1)))


SHAPES: dict[str, type] = {"box": Box, "sphere": Sphere, "capsule": Capsule, "cylinder": Cylinder}


def shape_from_dict(data: Any, where: str) -> Shape:
    """A shape from its dict (``{"type": "box", "size": [...]}``); errors name ``where``."""
    if not isinstance(data, dict):
        raise InvalidInputError(where, data, "a mapping with a 'type'")
    kind = data.get("type")
    valid = ["box", "sphere", "capsule", "cylinder", "halfspace", "mesh"]
    if kind not in valid:
        raise InvalidInputError(f"{where}.type", kind, f"one of {valid}")
    fields = {k: v for k, v in data.items() if k != "type"}
    expected = {
        "box": {"size"},
        "sphere": {"radius"},
        "capsule": {"radius", "length"},
        "cylinder": {"radius", "length"},
        "halfspace": set(),
        "mesh": {"vertices", "faces"},
    }[kind]
    if set(fields) != expected:
        raise InvalidInputError(f"{where}", sorted(fields), f"the fields {sorted(expected)} for a {kind}")
    try:
        if kind == "halfspace":
            return HalfSpace()
        if kind == "mesh":
            return Mesh(np.asarray(fields["vertices"], dtype=float), np.asarray(fields["faces"]))
        return SHAPES[kind](**fields)
    except InvalidInputError as exc:
        raise InvalidInputError(f"{where}.{exc.argument}", exc.received, exc.expected) from exc
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(where, data, f"valid {kind} fields ({exc})") from exc
