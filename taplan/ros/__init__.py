"""Optional ROS 2 edge: a node that streams taplan commands to the robot's ``/api`` topics.

Importing this package never imports ``rclpy``; only :func:`create_rclpy_node` and :class:`RclpyInterface`'s message
lookup do, raising :class:`RosUnavailableError` with instructions when ROS 2 is not sourced.
"""

from __future__ import annotations

from taplan.ros.interface import (
    FakePublisher,
    FakeRosInterface,
    Publisher,
    RclpyInterface,
    RosInterface,
    RosUnavailableError,
    require_rclpy,
)
from taplan.ros.node import Streamer, StreamNode, create_rclpy_node

__all__ = [
    "StreamNode",
    "Streamer",
    "create_rclpy_node",
    "RosInterface",
    "Publisher",
    "RclpyInterface",
    "FakeRosInterface",
    "FakePublisher",
    "RosUnavailableError",
    "require_rclpy",
]
