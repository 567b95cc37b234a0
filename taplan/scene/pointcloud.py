"""``sensor_msgs/PointCloud2`` decoding and encoding: the x, y, z of a cloud's points as an (N, 3) array [m].

A PointCloud2 is ``height`` rows of ``width`` points, each ``point_step`` bytes, rows ``row_step`` bytes apart; its
``fields`` name where x, y and z sit in a point (``offset`` [bytes], ``datatype`` 1-8: INT8, UINT8, INT16, UINT16,
INT32, UINT32, FLOAT32, FLOAT64). Decoding reads the three coordinates through one numpy structured view (no Python
loop over points), in the message's byte order; other fields (rgb, intensity, ...) are skipped. Non-finite points
(an organised cloud's missing pixels) are dropped.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from taplan.errors import InvalidInputError

__all__ = ["cloud_to_points", "points_to_cloud", "POINT_FIELD_TYPES"]

# sensor_msgs/PointField datatype -> numpy type (the message's constants)
POINT_FIELD_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


def _int(fields: dict[str, Any], name: str, low: int = 0) -> int:
    value = fields.get(name)
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise InvalidInputError(f"cloud.{name}", value, f"an integer >= {low}")
    return int(value)


def cloud_to_points(cloud: dict[str, Any]) -> np.ndarray:
    """The finite points (N, 3) [m, the cloud's frame] of a PointCloud2 given as its fields (``height``, ``width``,
    ``fields``, ``is_bigendian``, ``point_step``, ``row_step``, ``data``)."""
    if not isinstance(cloud, dict):
        raise InvalidInputError("cloud", type(cloud).__name__, "a PointCloud2's fields as a mapping")
    height, width = _int(cloud, "height"), _int(cloud, "width")
    point_step, row_step = _int(cloud, "point_step", 1), _int(cloud, "row_step")
    data = cloud.get("data", b"")
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise InvalidInputError("cloud.data", type(data).__name__, "bytes")
    layout = {f.get("name"): f for f in cloud.get("fields", []) if isinstance(f, dict)}
    order = ">" if cloud.get("is_bigendian") else "<"
    names, formats, offsets = [], [], []
    for axis in "xyz":
        entry = layout.get(axis)
        if entry is None:
            raise InvalidInputError("cloud.fields", sorted(k for k in layout if k), "fields named x, y and z")
        kind = POINT_FIELD_TYPES.get(entry.get("datatype"))  # type: ignore[arg-type]
        if kind is None:
            raise InvalidInputError(f"cloud.fields.{axis}.datatype", entry.get("datatype"), "a PointField type 1-8")
        offset = entry.get("offset")
        if not isinstance(offset, int) or offset < 0 or offset + np.dtype(kind).itemsize > point_step:
            raise InvalidInputError(f"cloud.fields.{axis}.offset", offset, f"inside the {point_step}-byte point")
        names.append(axis)
        formats.append(order + kind)
        offsets.append(offset)
    if row_step < width * point_step or len(data) < row_step * (height - 1) + width * point_step:
        raise InvalidInputError(
            "cloud.data",
            f"{len(data)} bytes (row_step {row_step})",
            f"{height} rows of {width} points of {point_step} bytes",
        )
    if height * width == 0:
        return np.zeros((0, 3))
    point = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": point_step})
    raw = np.frombuffer(data, dtype=np.uint8, count=row_step * (height - 1) + width * point_step)
    rows = [raw[r * row_step : r * row_step + width * point_step] for r in range(height)]
    packed = rows[0] if height == 1 else np.concatenate(rows) if row_step != width * point_step else raw
    records = packed.view(point)
    points = np.stack([records[a].astype(np.float64) for a in "xyz"], axis=1)
    return points[np.all(np.isfinite(points), axis=1)]


def points_to_cloud(points: npt.ArrayLike, frame_id: str = "", stamp: float = 0.0) -> dict[str, Any]:
    """An unorganised PointCloud2 (height 1, little-endian float32 x, y, z; 12-byte points) of ``points`` (N, 3)."""
    P = np.asarray(points, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InvalidInputError("points", f"shape {P.shape}", "(N, 3) positions [m]")
    return {
        "stamp": float(stamp),
        "frame_id": frame_id,
        "height": 1,
        "width": len(P),
        "fields": [{"name": a, "offset": 4 * i, "datatype": 7, "count": 1} for i, a in enumerate("xyz")],
        "is_bigendian": False,
        "point_step": 12,
        "row_step": 12 * len(P),
        "data": P.astype("<f4").tobytes(),
        "is_dense": bool(np.all(np.isfinite(P))),
    }
