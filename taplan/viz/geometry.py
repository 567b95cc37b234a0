"""Triangle meshes of taplan's shapes for drawing, and pose conversions (no viser needed here).

Capsules and cylinders are built with their axis along the local z (taplan's convention, :mod:`taplan.scene.shapes`);
a robot body's capsule is placed by :func:`segment_pose` so that its local z runs from ``start`` to ``end``.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

# drawn capsules sit in the very frame the collision world places its coal capsules in (z along the segment)
from taplan.scene.world import _segment_frame as segment_pose

__all__ = ["capsule_mesh", "cylinder_mesh", "box_mesh", "segment_pose", "wxyz", "HALF_SPACE_EXTENT"]

HALF_SPACE_EXTENT = 2.0  # [m] a half-space is drawn as a slab this wide: the reachable area of a two-arm robot
_HALF_SPACE_DEPTH = 0.02  # [m]


def wxyz(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix, viser's order (pinocchio stores x, y, z, w)."""
    x, y, z, w = pin.Quaternion(np.asarray(rotation, dtype=float)).normalized().coeffs()
    return np.array([w, x, y, z])


def _ring_faces(rings: int, segments: int) -> np.ndarray:
    faces = []
    for r in range(rings - 1):
        for s in range(segments):
            a = r * segments + s
            b = r * segments + (s + 1) % segments
            c = a + segments
            d = b + segments
            faces += [[a, b, d], [a, d, c]]
    return np.array(faces, dtype=np.uint32)


def capsule_mesh(radius: float, length: float, segments: int = 20, cap_rings: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) and faces (F, 3) of a capsule: radius [m], z-axis segment of ``length`` [m] about the
    origin (a sphere when ``length`` is 0)."""
    angles = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    circle = np.column_stack([np.cos(angles), np.sin(angles)])
    half = length / 2
    rings = []
    # bottom cap from the pole (excluded) up to the equator, then the top cap from the equator to the pole
    for k in range(1, cap_rings + 1):
        phi = -np.pi / 2 + np.pi / 2 * k / cap_rings
        rings.append((radius * np.cos(phi), -half + radius * np.sin(phi)))
    for k in range(0, cap_rings):
        phi = np.pi / 2 * k / cap_rings
        rings.append((radius * np.cos(phi), half + radius * np.sin(phi)))
    vertices = np.vstack([np.column_stack([rho * circle, np.full(segments, z)]) for rho, z in rings])
    faces = _ring_faces(len(rings), segments)
    bottom, top = len(vertices), len(vertices) + 1
    vertices = np.vstack([vertices, [[0, 0, -half - radius], [0, 0, half + radius]]])
    last = (len(rings) - 1) * segments
    caps = [[bottom, (s + 1) % segments, s] for s in range(segments)]
    caps += [[top, last + s, last + (s + 1) % segments] for s in range(segments)]
    return vertices.astype(np.float32), np.vstack([faces, np.array(caps, dtype=np.uint32)])


def cylinder_mesh(radius: float, length: float, segments: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a closed cylinder of ``radius`` and ``length`` [m] along z, centred."""
    angles = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    circle = radius * np.column_stack([np.cos(angles), np.sin(angles)])
    vertices = np.vstack([np.column_stack([circle, np.full(segments, z)]) for z in (-length / 2, length / 2)])
    faces = _ring_faces(2, segments)
    bottom, top = 2 * segments, 2 * segments + 1
    vertices = np.vstack([vertices, [[0, 0, -length / 2], [0, 0, length / 2]]])
    caps = [[bottom, (s + 1) % segments, s] for s in range(segments)]
    caps += [[top, segments + s, segments + (s + 1) % segments] for s in range(segments)]
    return vertices.astype(np.float32), np.vstack([faces, np.array(caps, dtype=np.uint32)])


def box_mesh(size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a box of full edge lengths ``size`` [m], centred."""
    half = np.asarray(size, dtype=float) / 2
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float) * half
    faces = [
        [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
        [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3],
    ]  # fmt: skip
    return corners.astype(np.float32), np.array(faces, dtype=np.uint32)


def half_space_slab() -> tuple[np.ndarray, np.ndarray]:
    """The drawn stand-in of a half-space ``z <= 0``: a slab ``HALF_SPACE_EXTENT`` wide just below z = 0."""
    vertices, faces = box_mesh(np.array([HALF_SPACE_EXTENT, HALF_SPACE_EXTENT, _HALF_SPACE_DEPTH]))
    vertices[:, 2] -= _HALF_SPACE_DEPTH / 2
    return vertices, faces
