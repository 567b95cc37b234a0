"""A URDF's visual meshes, where the files exist: read from the URDF's ``<visual>`` elements, loaded with trimesh.

``package://pkg/path`` is looked up as ``pkg/path`` in the URDF's folder and its parents (the layout of a ROS
package or of a vendor's zip), ``file://`` and relative paths as they are. Missing or unreadable files are listed in
``skipped`` and left out: the viewer still draws the collision bodies.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

__all__ = ["VisualMesh", "visual_meshes"]


@dataclass(frozen=True)
class VisualMesh:
    """One mesh: ``link``, its file, vertices (V, 3) [m] and faces (F, 3), ``pose`` in the link's frame (4x4)."""

    link: str
    path: Path
    vertices: np.ndarray = field(repr=False)
    faces: np.ndarray = field(repr=False)
    pose: np.ndarray = field(repr=False)


def _resolve(filename: str, urdf: Path) -> Path | None:
    if filename.startswith("file://"):
        candidates = [Path(filename[len("file://") :])]
    elif filename.startswith("package://"):
        relative = filename[len("package://") :]
        candidates = [folder / relative for folder in [urdf.parent, *urdf.parent.parents]]
        candidates.append(urdf.parent / relative.split("/", 1)[-1])  # the package is the URDF's own folder
    else:
        candidates = [urdf.parent / filename]
    return next((c for c in candidates if c.is_file()), None)


def _origin(element: ET.Element | None) -> np.ndarray:
    T = np.eye(4)
    if element is None:
        return T
    xyz = [float(v) for v in element.get("xyz", "0 0 0").split()]
    rpy = [float(v) for v in element.get("rpy", "0 0 0").split()]
    T[:3, :3] = pin.rpy.rpyToMatrix(*rpy)
    T[:3, 3] = xyz
    return T


def visual_meshes(urdf_path: str | Path) -> tuple[list[VisualMesh], list[str]]:
    """The URDF's visual meshes that exist and load, and the files skipped (with the reason)."""
    urdf = Path(urdf_path)
    root = ET.parse(urdf).getroot()
    meshes: list[VisualMesh] = []
    skipped: list[str] = []
    for link in root.iter("link"):
        for visual in link.findall("visual"):
            mesh = visual.find("geometry/mesh")
            if mesh is None or not mesh.get("filename"):
                continue
            filename = mesh.get("filename", "")
            path = _resolve(filename, urdf)
            if path is None:
                skipped.append(f"{filename} (not found)")
                continue
            import trimesh  # here: its import (scipy) costs a second, and most URDFs of ours have no meshes

            try:
                loaded = trimesh.load(path, force="mesh")
                vertices = np.asarray(loaded.vertices, dtype=float)
                faces = np.asarray(loaded.faces, dtype=np.uint32)
            except Exception as exc:  # trimesh raises many kinds on a damaged file
                skipped.append(f"{filename} ({type(exc).__name__}: {exc})")
                continue
            if len(vertices) == 0 or len(faces) == 0:
                skipped.append(f"{filename} (empty)")
                continue
            scale = np.array([float(v) for v in mesh.get("scale", "1 1 1").split()])
            pose = _origin(visual.find("origin"))
            meshes.append(VisualMesh(link.get("name", ""), path, vertices * scale, faces, pose))
    return meshes, skipped
