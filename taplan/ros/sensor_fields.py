"""taplan's plain fields of a ``sensor_msgs/Image``, ``CameraInfo`` or ``PointCloud2`` sample, received over DDS
or decoded from a bag (both have the ROS field names as attributes); no cyclonedds import."""

from __future__ import annotations

from typing import Any

__all__ = ["sensor_fields", "sensor_body", "IMAGE", "CAMERA_INFO", "POINT_CLOUD2", "SENSOR_TYPES"]

IMAGE, CAMERA_INFO, POINT_CLOUD2 = "sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo", "sensor_msgs/msg/PointCloud2"
SENSOR_TYPES = (IMAGE, CAMERA_INFO, POINT_CLOUD2)


def sensor_fields(msg_type: str, sample: Any) -> dict[str, Any]:
    """taplan's plain fields of a received (or bag-decoded) Image, CameraInfo or PointCloud2: every field by its ROS
    name, byte arrays as ``bytes``, plus ``"stamp"`` [s] and ``"frame_id"`` from the header."""
    stamp = sample.header.stamp
    out: dict[str, Any] = {
        "stamp": stamp.sec + stamp.nanosec * 1e-9,
        "frame_id": str(sample.header.frame_id),
        "height": int(sample.height),
        "width": int(sample.width),
    }
    if msg_type == IMAGE:
        out.update(
            encoding=str(sample.encoding),
            is_bigendian=int(sample.is_bigendian),
            step=int(sample.step),
            data=bytes(sample.data),
        )
    elif msg_type == CAMERA_INFO:
        roi = sample.roi
        out.update(
            distortion_model=str(sample.distortion_model),
            d=[float(v) for v in sample.d],
            k=[float(v) for v in sample.k],
            r=[float(v) for v in sample.r],
            p=[float(v) for v in sample.p],
            binning_x=int(sample.binning_x),
            binning_y=int(sample.binning_y),
            roi={k: getattr(roi, k) for k in ("x_offset", "y_offset", "height", "width", "do_rectify")},
        )
    else:
        out.update(
            fields=[
                {"name": str(f.name), "offset": int(f.offset), "datatype": int(f.datatype), "count": int(f.count)}
                for f in sample.fields
            ],
            is_bigendian=bool(sample.is_bigendian),
            point_step=int(sample.point_step),
            row_step=int(sample.row_step),
            data=bytes(sample.data),
            is_dense=bool(sample.is_dense),
        )
    return out


_ROI = ("x_offset", "y_offset", "height", "width", "do_rectify")


def sensor_body(msg_type: str, fields: dict[str, Any]) -> dict[str, Any]:
    """The message body (everything but the header) of an Image, CameraInfo or PointCloud2 given as taplan's plain
    fields, each field of its ROS type with ROS's defaults: the one normalisation both writers (the DDS link's IDL
    structs and the bag's ROS dicts) start from."""
    body: dict[str, Any] = {"height": int(fields.get("height", 0)), "width": int(fields.get("width", 0))}
    if msg_type.endswith("/Image"):
        body.update(
            encoding=str(fields.get("encoding", "")),
            is_bigendian=int(bool(fields.get("is_bigendian", 0))),
            step=int(fields.get("step", 0)),
            data=bytes(fields.get("data", b"")),
        )
    elif msg_type.endswith("/CameraInfo"):
        roi = fields.get("roi") or {}
        body.update(
            distortion_model=str(fields.get("distortion_model", "")),
            d=[float(v) for v in fields.get("d", [])],
            k=[float(v) for v in fields.get("k", [0.0] * 9)],
            r=[float(v) for v in fields.get("r", [0.0] * 9)],
            p=[float(v) for v in fields.get("p", [0.0] * 12)],
            binning_x=int(fields.get("binning_x", 0)),
            binning_y=int(fields.get("binning_y", 0)),
            roi={k: bool(roi.get(k, False)) if k == "do_rectify" else int(roi.get(k, 0)) for k in _ROI},
        )
    else:
        body.update(
            fields=[
                {
                    "name": str(f["name"]),
                    "offset": int(f["offset"]),
                    "datatype": int(f["datatype"]),
                    "count": int(f.get("count", 1)),
                }
                for f in fields.get("fields", [])
            ],
            is_bigendian=bool(fields.get("is_bigendian", False)),
            point_step=int(fields.get("point_step", 0)),
            row_step=int(fields.get("row_step", 0)),
            data=bytes(fields.get("data", b"")),
            is_dense=bool(fields.get("is_dense", False)),
        )
    return body
