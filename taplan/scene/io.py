"""Scene files: YAML or JSON, metres, poses as ``xyz`` + ``xyzw`` quaternion in the robot's root frame.

Schema (``models/teleavatar/scenes/table.yaml`` is an example)::

    frame: shoulder_base          # optional; the robot's root frame, for the reader
    obstacles:                    # each: name, shape, pose
      - name: table
        shape: {type: box, size: [0.8, 1.2, 0.04]}          # box: size; sphere: radius;
        pose: {xyz: [0.55, 0.0, -0.42], xyzw: [0, 0, 0, 1]}  # capsule/cylinder: radius, length (along z);
    attached:                     # optional: objects carried by a frame  # halfspace: (none; solid z <= 0);
      - name: cup                                            # mesh: vertices, faces
        shape: {type: cylinder, radius: 0.04, length: 0.1}
        frame: left_tcp
        pose: {xyz: [0, 0, 0.08], xyzw: [0, 0, 0, 1]}
        touch: [Link-L7]          # optional: robot bodies it may touch

Every error is an :class:`~taplan.errors.InvalidInputError` naming the field (``obstacles[2].shape.size``), what was
received and what is valid.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from taplan.errors import InvalidInputError
from taplan.scene.scene import Scene
from taplan.scene.shapes import shape_from_dict

__all__ = ["load_scene", "save_scene", "scene_from_dict", "scene_to_dict", "TELEAVATAR_SCENES"]

TELEAVATAR_SCENES = Path(__file__).resolve().parents[1] / "models" / "teleavatar" / "scenes"  # bundled examples

_TOP = {"frame", "obstacles", "attached"}


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


def scene_from_dict(data: Any, source: str = "scene") -> Scene:
    """A scene from its dict (the parsed file)."""
    if data is None or data == {}:
        raise InvalidInputError(source, "an empty scene file", f"a mapping with {sorted(_TOP)}")
    if not isinstance(data, dict):
        raise InvalidInputError(source, type(data).__name__, f"a mapping with {sorted(_TOP)}")
    unknown = set(data) - _TOP
    if unknown:
        raise InvalidInputError(source, sorted(unknown), f"only the keys {sorted(_TOP)}")
    scene = Scene()
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
                scene.add(name, shape, pose)
            else:
                touch = item.get("touch", [])
                if not isinstance(touch, list) or not all(isinstance(t, str) for t in touch):
                    raise InvalidInputError(f"{where}.touch", touch, "a list of robot body names")
                scene.attach(name, shape, str(item["frame"]), pose, tuple(touch))
    return scene


def _pose_dict(T: np.ndarray) -> dict[str, list[float]]:
    import pinocchio as pin

    return {"xyz": T[:3, 3].tolist(), "xyzw": pin.Quaternion(T[:3, :3]).coeffs().tolist()}


def scene_to_dict(scene: Scene) -> dict[str, Any]:
    """The file form of ``scene``."""
    return {
        "frame": "root",
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


def load_scene(path: str | Path) -> Scene:
    """Read a scene from ``.yaml``/``.yml`` or ``.json``."""
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
    return scene_from_dict(data, str(path))


def save_scene(scene: Scene, path: str | Path) -> None:
    """Write ``scene`` as YAML (``.yaml``/``.yml``) or JSON (``.json``)."""
    path = Path(path)
    data = scene_to_dict(scene)
    if path.suffix.lower() == ".json":
        path.write_text(json.dumps(data, indent=2))
    else:
        import yaml

        path.write_text(yaml.safe_dump(data, sort_keys=False))
