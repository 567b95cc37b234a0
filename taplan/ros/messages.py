"""ROS 2 message layouts as DDS types (what rmw_cyclonedds puts on the wire), and taplan's plain fields.

ROS 2 maps a message ``pkg/msg/Name`` to the DDS type ``pkg::msg::dds_::Name_`` and a topic ``/a/b`` to the DDS
topic ``rt/a/b``; the fields are serialised in CDR in declaration order. The structs below declare the layouts of
``builtin_interfaces/Time``, ``std_msgs/Header``, ``sensor_msgs/JointState``, ``geometry_msgs/Pose`` (``Point``,
``Quaternion``), ``std_msgs/Float32``, ``std_msgs/Int32``, ``std_msgs/Float32MultiArray`` (``MultiArrayLayout``,
``MultiArrayDimension``) and the depth cameras' ``sensor_msgs/Image``, ``sensor_msgs/CameraInfo``
(``RegionOfInterest``) and ``sensor_msgs/PointCloud2`` (``PointField``) field for field, so a ROS 2 node (rclpy,
rclcpp, ``ros2 topic echo``) and taplan read each other's messages.

Messages cross taplan's interfaces as the plain field dicts of :class:`taplan.api.ApiMessage`; a received
``JointState``, ``Image``, ``CameraInfo`` or ``PointCloud2`` also carries ``"stamp"`` (its header time [s]), the
sensor messages also ``"frame_id"``; byte arrays (``uint8[]``) cross as ``bytes``. This module imports
``cyclonedds``: import it only through :mod:`taplan.ros.dds`.
"""

# no "from __future__ import annotations": cyclonedds evaluates the field annotations of the structs

import math
from dataclasses import dataclass, field
from typing import Any

from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float32, float64, int32, sequence, uint8, uint32

from taplan.errors import ConfigError
from taplan.ros.msg_definitions import INT32, MESSAGE_DEFINITIONS
from taplan.ros.sensor_fields import CAMERA_INFO, IMAGE, POINT_CLOUD2, SENSOR_TYPES, sensor_body, sensor_fields

__all__ = [
    "Time",
    "Header",
    "JointState",
    "Point",
    "Quaternion",
    "Pose",
    "Float32",
    "Int32",
    "MultiArrayDimension",
    "MultiArrayLayout",
    "Float32MultiArray",
    "Image",
    "RegionOfInterest",
    "CameraInfo",
    "PointField",
    "PointCloud2",
    "IDL_TYPES",
    "MESSAGE_DEFINITIONS",
    "dds_topic",
    "idl_type",
    "to_idl",
    "from_idl",
    "INT32",
    "IMAGE",
    "CAMERA_INFO",
    "POINT_CLOUD2",
    "SENSOR_TYPES",
    "sensor_fields",
]


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Header = field(default_factory=Header)
    name: sequence[str] = field(default_factory=list)
    position: sequence[float64] = field(default_factory=list)
    velocity: sequence[float64] = field(default_factory=list)
    effort: sequence[float64] = field(default_factory=list)


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class Float32(IdlStruct, typename="std_msgs::msg::dds_::Float32_"):
    data: float32 = 0.0


@dataclass
class Int32(IdlStruct, typename="std_msgs::msg::dds_::Int32_"):
    data: int32 = 0


@dataclass
class MultiArrayDimension(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayDimension_"):
    label: str = ""
    size: uint32 = 0
    stride: uint32 = 0


@dataclass
class MultiArrayLayout(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayLayout_"):
    dim: sequence[MultiArrayDimension] = field(default_factory=list)
    data_offset: uint32 = 0


@dataclass
class Float32MultiArray(IdlStruct, typename="std_msgs::msg::dds_::Float32MultiArray_"):
    layout: MultiArrayLayout = field(default_factory=MultiArrayLayout)
    data: sequence[float32] = field(default_factory=list)


@dataclass
class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header = field(default_factory=Header)
    height: uint32 = 0
    width: uint32 = 0
    encoding: str = ""
    is_bigendian: uint8 = 0
    step: uint32 = 0
    data: sequence[uint8] = field(default_factory=list)  # bytes in, a list of ints out (bytes() in from_idl)


@dataclass
class RegionOfInterest(IdlStruct, typename="sensor_msgs::msg::dds_::RegionOfInterest_"):
    x_offset: uint32 = 0
    y_offset: uint32 = 0
    height: uint32 = 0
    width: uint32 = 0
    do_rectify: bool = False


@dataclass
class CameraInfo(IdlStruct, typename="sensor_msgs::msg::dds_::CameraInfo_"):
    header: Header = field(default_factory=Header)
    height: uint32 = 0
    width: uint32 = 0
    distortion_model: str = ""
    d: sequence[float64] = field(default_factory=list)
    k: array[float64, 9] = field(default_factory=lambda: [0.0] * 9)
    r: array[float64, 9] = field(default_factory=lambda: [0.0] * 9)
    p: array[float64, 12] = field(default_factory=lambda: [0.0] * 12)
    binning_x: uint32 = 0
    binning_y: uint32 = 0
    roi: RegionOfInterest = field(default_factory=RegionOfInterest)


@dataclass
class PointField(IdlStruct, typename="sensor_msgs::msg::dds_::PointField_"):
    name: str = ""
    offset: uint32 = 0
    datatype: uint8 = 0
    count: uint32 = 0


@dataclass
class PointCloud2(IdlStruct, typename="sensor_msgs::msg::dds_::PointCloud2_"):
    header: Header = field(default_factory=Header)
    height: uint32 = 0
    width: uint32 = 0
    fields: sequence[PointField] = field(default_factory=list)
    is_bigendian: bool = False
    point_step: uint32 = 0
    row_step: uint32 = 0
    data: sequence[uint8] = field(default_factory=list)
    is_dense: bool = False


IDL_TYPES: dict[str, type] = {
    "sensor_msgs/msg/JointState": JointState,
    "geometry_msgs/msg/Pose": Pose,
    "std_msgs/msg/Float32": Float32,
    INT32: Int32,
    "std_msgs/msg/Float32MultiArray": Float32MultiArray,
    IMAGE: Image,
    CAMERA_INFO: CameraInfo,
    POINT_CLOUD2: PointCloud2,
}


def dds_topic(topic: str) -> str:
    """The DDS topic name ROS 2 uses for ``topic``: ``/a/b`` -> ``rt/a/b``."""
    if not topic.startswith("/") or topic.endswith("/") or "//" in topic:
        raise ConfigError(f"ROS topic {topic!r}: expected an absolute name like '/api/left_arm/joint_cmd'")
    return "rt" + topic


def idl_type(msg_type: str) -> type:
    """The DDS struct of a ROS message type name (``"sensor_msgs/msg/JointState"``)."""
    try:
        return IDL_TYPES[msg_type]
    except KeyError:
        raise ConfigError(f"unsupported message type {msg_type!r}; supported: {sorted(IDL_TYPES)}") from None


def _stamp(seconds: float) -> Time:
    sec = math.floor(seconds)
    return Time(sec=int(sec), nanosec=min(int(round((seconds - sec) * 1e9)), 999_999_999))


def to_idl(msg_type: str, fields: dict[str, Any], stamp: float = 0.0) -> Any:
    """The DDS sample of taplan's plain ``fields``; a JointState's header gets ``stamp`` [s] (wall clock)."""
    if msg_type == "sensor_msgs/msg/JointState":
        return JointState(
            header=Header(stamp=_stamp(stamp)),
            name=[str(n) for n in fields.get("name", [])],
            position=[float(v) for v in fields.get("position", [])],
            velocity=[float(v) for v in fields.get("velocity", [])],
            effort=[float(v) for v in fields.get("effort", [])],
        )
    if msg_type == "geometry_msgs/msg/Pose":
        p, o = fields["position"], fields["orientation"]
        return Pose(
            position=Point(float(p["x"]), float(p["y"]), float(p["z"])),
            orientation=Quaternion(float(o["x"]), float(o["y"]), float(o["z"]), float(o["w"])),
        )
    if msg_type == "std_msgs/msg/Float32":
        return Float32(data=float(fields["data"]))
    if msg_type == INT32:
        return Int32(data=int(fields["data"]))
    if msg_type == "std_msgs/msg/Float32MultiArray":
        data = [float(v) for v in fields["data"]]
        return Float32MultiArray(layout=MultiArrayLayout(dim=[]), data=data)
    if msg_type in SENSOR_TYPES:
        return _sensor_to_idl(msg_type, fields, stamp)
    raise ConfigError(f"unsupported message type {msg_type!r}; supported: {sorted(IDL_TYPES)}")


def _sensor_to_idl(msg_type: str, fields: dict[str, Any], stamp: float) -> Any:
    header = Header(stamp=_stamp(stamp), frame_id=str(fields.get("frame_id", "")))
    body = sensor_body(msg_type, fields)
    if msg_type == IMAGE:
        return Image(header=header, **body)
    if msg_type == CAMERA_INFO:
        return CameraInfo(header=header, **{**body, "roi": RegionOfInterest(**body["roi"])})
    return PointCloud2(header=header, **{**body, "fields": [PointField(**f) for f in body["fields"]]})


def from_idl(msg_type: str, sample: Any) -> dict[str, Any]:
    """taplan's plain fields of a received DDS sample (a JointState also gets ``"stamp"`` [s])."""
    if msg_type == "sensor_msgs/msg/JointState":
        stamp = sample.header.stamp
        return {
            "name": list(sample.name),
            "position": list(sample.position),
            "velocity": list(sample.velocity),
            "effort": list(sample.effort),
            "stamp": stamp.sec + stamp.nanosec * 1e-9,
        }
    if msg_type == "geometry_msgs/msg/Pose":
        p, o = sample.position, sample.orientation
        return {"position": {"x": p.x, "y": p.y, "z": p.z}, "orientation": {"x": o.x, "y": o.y, "z": o.z, "w": o.w}}
    if msg_type == "std_msgs/msg/Float32MultiArray":
        return {"data": [float(v) for v in sample.data]}
    if msg_type == INT32:
        return {"data": int(sample.data)}
    if msg_type in SENSOR_TYPES:
        return sensor_fields(msg_type, sample)
    return {"data": float(sample.data)}
