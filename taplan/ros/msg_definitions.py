"""The ``.msg`` texts of the message types taplan speaks, as rosbag2 stores them in MCAP schemas (``ros2msg``).

Dependencies follow the top-level definition, each after a line of 80 ``=`` and ``MSG: pkg/Name``, as ``ros2 bag
record`` writes them.
"""

from __future__ import annotations

__all__ = ["MESSAGE_DEFINITIONS", "INT32", "FSM_STATE_TOPIC"]

INT32 = "std_msgs/msg/Int32"
FSM_STATE_TOPIC = "/fsm_state"  # the robot's FSM state (std_msgs/Int32): PAUSE 0, SLOW_START 1, READY 2

_SEPARATOR = "=" * 80
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id"
_TIME = "int32 sec\nuint32 nanosec"
MESSAGE_DEFINITIONS: dict[str, str] = {
    "sensor_msgs/msg/JointState": (
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n"
        f"{_SEPARATOR}\nMSG: std_msgs/Header\n{_HEADER}\n{_SEPARATOR}\nMSG: builtin_interfaces/Time\n{_TIME}\n"
    ),
    "geometry_msgs/msg/Pose": (
        f"Point position\nQuaternion orientation\n{_SEPARATOR}\nMSG: geometry_msgs/Point\n"
        f"float64 x\nfloat64 y\nfloat64 z\n{_SEPARATOR}\nMSG: geometry_msgs/Quaternion\n"
        "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"
    ),
    "std_msgs/msg/Float32": "float32 data\n",
    INT32: "int32 data\n",
    "sensor_msgs/msg/Image": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\n"
        f"uint8[] data\n{_SEPARATOR}\nMSG: std_msgs/Header\n{_HEADER}\n{_SEPARATOR}\nMSG: builtin_interfaces/Time\n"
        f"{_TIME}\n"
    ),
    "sensor_msgs/msg/CameraInfo": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\nfloat64[9] k\n"
        "float64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\nRegionOfInterest roi\n"
        f"{_SEPARATOR}\nMSG: std_msgs/Header\n{_HEADER}\n{_SEPARATOR}\nMSG: builtin_interfaces/Time\n{_TIME}\n"
        f"{_SEPARATOR}\nMSG: sensor_msgs/RegionOfInterest\nuint32 x_offset\nuint32 y_offset\nuint32 height\n"
        "uint32 width\nbool do_rectify\n"
    ),
    "sensor_msgs/msg/PointCloud2": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nPointField[] fields\nbool is_bigendian\n"
        "uint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n"
        f"{_SEPARATOR}\nMSG: std_msgs/Header\n{_HEADER}\n{_SEPARATOR}\nMSG: builtin_interfaces/Time\n{_TIME}\n"
        f"{_SEPARATOR}\nMSG: sensor_msgs/PointField\nuint8 INT8=1\nuint8 UINT8=2\nuint8 INT16=3\nuint8 UINT16=4\n"
        "uint8 INT32=5\nuint8 UINT32=6\nuint8 FLOAT32=7\nuint8 FLOAT64=8\nstring name\nuint32 offset\n"
        "uint8 datatype\nuint32 count\n"
    ),
    "std_msgs/msg/Float32MultiArray": (
        f"MultiArrayLayout layout\nfloat32[] data\n{_SEPARATOR}\nMSG: std_msgs/MultiArrayLayout\n"
        f"MultiArrayDimension[] dim\nuint32 data_offset\n{_SEPARATOR}\nMSG: std_msgs/MultiArrayDimension\n"
        "string label\nuint32 size\nuint32 stride\n"
    ),
}
