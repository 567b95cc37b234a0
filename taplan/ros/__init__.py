"""ROS 2 at the edge: DDS from pip (:class:`DdsInterface`), rclpy when installed, the runner that drives the arms,
a simulated robot, rosbag2 recording and run checks, and the streaming node.

Importing this package imports neither ``rclpy`` nor ``cyclonedds``: the DDS transport loads Cyclone DDS when a
:class:`DdsInterface` is created (``pip install cyclonedds``, a core dependency), rclpy is imported only by
:func:`create_rclpy_node` and :class:`RclpyInterface`'s message lookup.
"""

from __future__ import annotations

from taplan.ros.bag import BagWriter, RecordedRun, read_run
from taplan.ros.dds import DdsInterface, DdsUnavailableError, domain_id_from_environment, loopback_config
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
from taplan.ros.run_check import RunReport, check_run
from taplan.ros.runner import RunError, Runner, RunnerConfig, RunResult
from taplan.ros.sim import FsmState, SimConfig, SimulatedRobot

__all__ = [
    "DdsInterface",
    "DdsUnavailableError",
    "loopback_config",
    "domain_id_from_environment",
    "Runner",
    "RunnerConfig",
    "RunResult",
    "RunError",
    "SimulatedRobot",
    "SimConfig",
    "FsmState",
    "BagWriter",
    "RecordedRun",
    "read_run",
    "RunReport",
    "check_run",
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
