"""The publish/subscribe surface :class:`~taplan.ros.StreamNode` needs, for rclpy and for tests.

:class:`RosInterface` is the shape: ``create_publisher(msg_type, topic)`` returns an object with
``publish(fields)``; ``create_subscription(msg_type, topic, callback)`` calls ``callback(fields)``; ``now()`` is the
time [s]. Messages cross it as the plain field dicts of :class:`taplan.api.ApiMessage`. :class:`RclpyInterface` maps
them to ROS 2 messages on a real ``rclpy`` node (rclpy imported only there); :class:`FakeRosInterface` records
them, for tests and dry runs.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from taplan.errors import ConfigError

__all__ = [
    "RosInterface",
    "Publisher",
    "RclpyInterface",
    "FakeRosInterface",
    "FakePublisher",
    "RosUnavailableError",
    "require_rclpy",
]

MESSAGE_TYPES = {
    "sensor_msgs/msg/JointState": ("sensor_msgs.msg", "JointState"),
    "std_msgs/msg/Float32": ("std_msgs.msg", "Float32"),
    "std_msgs/msg/Float32MultiArray": ("std_msgs.msg", "Float32MultiArray"),
    "geometry_msgs/msg/Pose": ("geometry_msgs.msg", "Pose"),
}


class RosUnavailableError(ConfigError, ImportError):
    """rclpy (ROS 2) is not importable in this Python."""


def require_rclpy() -> Any:
    """Import and return ``rclpy``, or raise :class:`RosUnavailableError` saying how to get it."""
    try:
        return importlib.import_module("rclpy")
    except ImportError as exc:
        raise RosUnavailableError(
            "taplan.ros needs rclpy (ROS 2), which is not importable here: source a ROS 2 installation "
            "(e.g. `source /opt/ros/humble/setup.bash`) in the shell that runs Python, with the same Python version "
            "as ROS. Everything else in taplan (streamers, taplan.api payloads, the scheduler) works without ROS; "
            f"for tests use taplan.ros.FakeRosInterface. ({exc})"
        ) from exc


class Publisher(Protocol):
    def publish(self, fields: dict[str, Any]) -> None: ...


class RosInterface(Protocol):
    """What :class:`~taplan.ros.StreamNode` uses of ROS."""

    def create_publisher(self, msg_type: str, topic: str) -> Publisher: ...

    def create_subscription(self, msg_type: str, topic: str, callback: Callable[[dict[str, Any]], None]) -> Any: ...

    def now(self) -> float: ...


class _RclpyPublisher:
    def __init__(self, publisher: Any, factory: Callable[[dict[str, Any]], Any]) -> None:
        self._publisher = publisher
        self._factory = factory

    def publish(self, fields: dict[str, Any]) -> None:
        self._publisher.publish(self._factory(fields))


class RclpyInterface:
    """:class:`RosInterface` on an ``rclpy`` node.

    Args:
        node: An ``rclpy.node.Node``.
        qos: Queue depth (or QoS profile) of publishers and subscriptions.
        messages: Message classes by type name (``"sensor_msgs/msg/JointState"`` -> class); default: imported from
            the ROS packages on first use.
    """

    def __init__(self, node: Any, qos: Any = 10, messages: dict[str, type] | None = None) -> None:
        self.node = node
        self.qos = qos
        self._messages = dict(messages or {})

    def message_class(self, msg_type: str) -> type:
        """The ROS message class of ``msg_type`` (imported lazily)."""
        if msg_type not in self._messages:
            if msg_type not in MESSAGE_TYPES:
                raise ConfigError(f"unsupported message type {msg_type!r}; supported: {sorted(MESSAGE_TYPES)}")
            module, name = MESSAGE_TYPES[msg_type]
            try:
                self._messages[msg_type] = getattr(importlib.import_module(module), name)
            except ImportError as exc:
                raise RosUnavailableError(
                    f"cannot import {module}.{name}: source a ROS 2 installation ({exc})"
                ) from exc
        return self._messages[msg_type]

    def create_publisher(self, msg_type: str, topic: str) -> Publisher:
        cls = self.message_class(msg_type)
        return _RclpyPublisher(self.node.create_publisher(cls, topic, self.qos), lambda f: to_message(cls, f))

    def create_subscription(self, msg_type: str, topic: str, callback: Callable[[dict[str, Any]], None]) -> Any:
        cls = self.message_class(msg_type)
        return self.node.create_subscription(cls, topic, lambda msg: callback(from_message(msg_type, msg)), self.qos)

    def now(self) -> float:
        return self.node.get_clock().now().nanoseconds * 1e-9

    def spin_once(self) -> int:
        """Run the node's ready callbacks without waiting (the :class:`~taplan.ros.Runner` loop calls it)."""
        require_rclpy().spin_once(self.node, timeout_sec=0.0)
        return 0


def to_message(cls: type, fields: dict[str, Any]) -> Any:
    """Fill a ROS message of class ``cls`` from taplan's plain fields."""
    msg = cls()
    if "orientation" in fields:  # Pose
        for part in ("position", "orientation"):
            target = getattr(msg, part)
            for key, value in fields[part].items():
                setattr(target, key, float(value))
        return msg
    for key, value in fields.items():
        setattr(msg, key, [float(v) for v in value] if key != "name" and isinstance(value, list) else value)
    return msg


def from_message(msg_type: str, msg: Any) -> dict[str, Any]:
    """taplan's plain fields of a received ROS message."""
    if msg_type == "sensor_msgs/msg/JointState":
        return {
            "name": list(msg.name),
            "position": list(msg.position),
            "velocity": list(msg.velocity),
            "effort": list(msg.effort),
        }
    if msg_type == "geometry_msgs/msg/Pose":
        p, o = msg.position, msg.orientation
        return {"position": {"x": p.x, "y": p.y, "z": p.z}, "orientation": {"x": o.x, "y": o.y, "z": o.z, "w": o.w}}
    data = msg.data
    return {"data": list(data) if not isinstance(data, (int, float)) else float(data)}


@dataclass
class FakePublisher:
    """Records what is published: ``messages`` is a list of (time [s], fields)."""

    topic: str
    msg_type: str
    interface: FakeRosInterface
    messages: list[tuple[float, dict[str, Any]]] = field(default_factory=list)

    def publish(self, fields: dict[str, Any]) -> None:
        self.messages.append((self.interface.now(), fields))


class FakeRosInterface:
    """An in-memory :class:`RosInterface`: a manual clock, recorded publishers, and ``deliver`` for incoming
    messages (as a subscription callback would receive them)."""

    def __init__(self, start: float = 0.0) -> None:
        self.time = float(start)
        self.publishers: dict[str, FakePublisher] = {}
        self.subscriptions: dict[str, list[Callable[[dict[str, Any]], None]]] = {}

    def create_publisher(self, msg_type: str, topic: str) -> FakePublisher:
        publisher = FakePublisher(topic, msg_type, self)
        self.publishers[topic] = publisher
        return publisher

    def create_subscription(self, msg_type: str, topic: str, callback: Callable[[dict[str, Any]], None]) -> Any:
        self.subscriptions.setdefault(topic, []).append(callback)
        return callback

    def now(self) -> float:
        return self.time

    def advance(self, dt: float) -> float:
        self.time += dt
        return self.time

    def deliver(self, topic: str, fields: dict[str, Any]) -> None:
        """Hand ``fields`` to every subscription of ``topic``."""
        for callback in self.subscriptions.get(topic, []):
            callback(fields)

    def published(self, topic: str) -> list[tuple[float, dict[str, Any]]]:
        """Everything published on ``topic`` so far (empty if nothing)."""
        publisher = self.publishers.get(topic)
        return [] if publisher is None else publisher.messages
