"""taplan's plain fields of a ``sensor_msgs/Image``, ``CameraInfo`` or ``PointCloud2`` sample, received over DDS
or decoded from a bag (both have the ROS field names as attributes); no cyclonedds import."""

from __future__ import annotations

from typing import Any

__all__ = ["sensor_fields", "IMAGE", "CAMERA_INFO", "POINT_CLOUD2", "SENSOR_TYPES"]

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
