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
    "std_msgs/msg/Float32MultiArray": (
        f"MultiArrayLayout layout\nfloat32[] data\n{_SEPARATOR}\nMSG: std_msgs/MultiArrayLayout\n"
        f"MultiArrayDimension[] dim\nuint32 data_offset\n{_SEPARATOR}\nMSG: std_msgs/MultiArrayDimension\n"
        "string label\nuint32 size\nuint32 stride\n"
    ),
}
