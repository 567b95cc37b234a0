"""ROS 2 over DDS from pip alone: a :class:`~taplan.ros.RosInterface` on Eclipse Cyclone DDS.

Cyclone DDS is the middleware ROS 2 Humble's ``rmw_cyclonedds_cpp`` runs on, and its Python binding
(``cyclonedds`` on PyPI) ships the C library in the wheel: no ROS installation, no compiler. With ROS 2's naming
(``rt/`` topic prefix, ``pkg::msg::dds_::Name_`` types, :mod:`taplan.ros.messages`) and rclpy's default QoS
(reliable, volatile, keep-last 10), a ROS 2 node on the same domain sees taplan's messages as its own.

The interface runs no thread: :meth:`DdsInterface.spin_once` takes what has arrived and calls the subscription
callbacks in the caller's loop, like ``rclpy.spin_once``.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from typing import Any, Protocol

from taplan.errors import ConfigError, InvalidInputError

__all__ = ["DdsInterface", "DdsUnavailableError", "loopback_config", "domain_id_from_environment", "Recorder"]

logger = logging.getLogger(__name__)

MAX_DOMAIN_ID = 232  # the largest id whose RTPS ports are valid (ROS 2's documented range is 0-101 and 215-232)
RELIABLE_BLOCKING = 0.1  # [s] a reliable write blocks at most this long on a full history (rclpy's default 0.1 s)
# Cyclone keeps a deleted reliable writer with unacknowledged data alive up to WriterLingerDuration (default 1 s),
# one writer after the other: after the robot side crashed, closing taplan's 3 writers took 3 s. 0.1 s still
# retransmits to a live reader (the last commands, a final disable) and bounds the exit to ~0.3 s.
WRITER_LINGER = (
    "<CycloneDDS><Domain Id='any'><Internal><WriterLingerDuration>0.1 s</WriterLingerDuration></Internal></Domain>"
    "</CycloneDDS>"
)


class DdsUnavailableError(ConfigError, ImportError):
    """The ``cyclonedds`` package is not importable."""


class Recorder(Protocol):
    """Receives every message the interface publishes or takes (e.g. :class:`taplan.ros.bag.BagWriter`)."""

    def record(
        self, topic: str, msg_type: str, fields: dict[str, Any], time_ns: int, data: bytes | None = None
    ) -> None: ...


def domain_id_from_environment(default: int = 0) -> int:
    """``ROS_DOMAIN_ID`` as ROS 2 reads it, or ``default``."""
    value = os.environ.get("ROS_DOMAIN_ID", "").strip()
    return _domain_id(value if value else default, "ROS_DOMAIN_ID")


def _domain_id(value: Any, name: str) -> int:
    try:
        domain = int(value)
    except (TypeError, ValueError):
        raise InvalidInputError(name, value, f"an integer domain id in [0, {MAX_DOMAIN_ID}]") from None
    if not 0 <= domain <= MAX_DOMAIN_ID:
        raise InvalidInputError(name, value, f"an integer domain id in [0, {MAX_DOMAIN_ID}]")
    return domain


def loopback_config() -> str:
    """A Cyclone DDS configuration that stays on 127.0.0.1: loopback interface, no multicast, unicast discovery."""
    return (
        "<CycloneDDS><Domain Id='any'><General><Interfaces><NetworkInterface address='127.0.0.1'/></Interfaces>"
        "<AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
        "<MaxAutoParticipantIndex>40</MaxAutoParticipantIndex><Peers><Peer address='127.0.0.1'/></Peers>"
        "</Discovery></Domain></CycloneDDS>"
    )


def _cyclonedds() -> Any:
    try:
        import cyclonedds.domain
        import cyclonedds.pub
        import cyclonedds.qos
        import cyclonedds.sub
        import cyclonedds.topic
        import cyclonedds.util

        from taplan.ros import messages
    except ImportError as exc:
        raise DdsUnavailableError(
            f"taplan's DDS transport needs the 'cyclonedds' package (pip install cyclonedds): {exc}"
        ) from exc
    return cyclonedds, messages


_CONFIGURED: dict[int, tuple[str, Any]] = {}  # domain id -> (config, Domain): one configuration per process


def _configure_domain(dds: Any, domain_id: int, config: str) -> None:
    existing = _CONFIGURED.get(domain_id)
    if existing is None:
        _CONFIGURED[domain_id] = (config, dds.domain.Domain(domain_id, config))
    elif existing[0] != config:
        raise ConfigError(f"DDS domain {domain_id} is already configured differently in this process")


class _Publisher:
    def __init__(self, interface: DdsInterface, writer: Any, msg_type: str, topic: str) -> None:
        self._interface = interface
        self._writer = writer
        self.msg_type = msg_type
        self.topic = topic
        self.count = 0

    def publish(self, fields: dict[str, Any]) -> None:
        interface = self._interface
        now_ns = time.time_ns()
        stamp = fields.get("stamp", now_ns * 1e-9)  # a JointState's header stamp [s]: now unless given
        sample = interface.messages.to_idl(self.msg_type, fields, stamp)
        if interface.recorder is None:
            self._writer.write(sample)
        else:  # record the bytes and the time that went on the wire, not a re-stamped copy
            data = sample.serialize()
            self._writer.write(sample)
            interface.recorder.record(self.topic, self.msg_type, fields, now_ns, data)
        self.count += 1

    def matched(self) -> int:
        """How many subscribers are matched (discovered) now."""
        return len(self._writer.get_matched_subscriptions())


class _Subscription:
    def __init__(self, reader: Any, msg_type: str, topic: str) -> None:
        self.reader = reader
        self.msg_type = msg_type
        self.topic = topic
        self.callbacks: list[Callable[[dict[str, Any]], None]] = []
        self.count = 0


class DdsInterface:
    """Publish and subscribe ROS 2 messages on a DDS domain.

    Args:
        domain_id: DDS domain (``ROS_DOMAIN_ID``); default the environment's ``ROS_DOMAIN_ID``, else 0. The
            TeleAvatar uses 29 on the robot, 0 through its bridge.
        config: Cyclone DDS XML configuration (or URI) for this domain; default ``$CYCLONEDDS_URI`` or Cyclone's
            defaults; :func:`loopback_config` keeps everything on 127.0.0.1.
        recorder: Optional recorder of every published and received message.
        history: Keep-last depth of readers and writers (rclpy's default 10).

    Raises:
        DdsUnavailableError: cyclonedds is not installed. InvalidInputError: a bad domain id.
    """

    def __init__(
        self,
        domain_id: int | None = None,
        *,
        config: str | None = None,
        recorder: Recorder | None = None,
        history: int = 10,
    ) -> None:
        dds, self.messages = _cyclonedds()
        self.domain_id = domain_id_from_environment() if domain_id is None else _domain_id(domain_id, "domain_id")
        self.recorder = recorder
        self._dds = dds
        if config is None:  # the environment's configuration (as Cyclone reads it), plus the writer linger
            config = os.environ.get("CYCLONEDDS_URI", "").strip()
        config = f"{config},{WRITER_LINGER}" if config else WRITER_LINGER
        _configure_domain(dds, self.domain_id, config)
        self.participant = dds.domain.DomainParticipant(self.domain_id)
        policy = dds.qos.Policy
        self.qos = dds.qos.Qos(
            policy.Reliability.Reliable(dds.util.duration(seconds=RELIABLE_BLOCKING)),
            policy.Durability.Volatile,
            policy.History.KeepLast(int(history)),
        )
        self._topics: dict[str, Any] = {}
        self._subscriptions: dict[str, _Subscription] = {}
        self.publishers: dict[str, _Publisher] = {}

    def _topic(self, msg_type: str, topic: str) -> Any:
        name = self.messages.dds_topic(topic)
        existing = self._topics.get(name)
        if existing is None:
            existing = self._dds.topic.Topic(self.participant, name, self.messages.idl_type(msg_type), qos=self.qos)
            self._topics[name] = existing
        return existing

    def create_publisher(self, msg_type: str, topic: str) -> _Publisher:
        """A publisher of ``msg_type`` on the ROS topic ``topic`` (one DDS writer per topic, shared)."""
        if topic not in self.publishers:
            writer = self._dds.pub.DataWriter(self.participant, self._topic(msg_type, topic), qos=self.qos)
            self.publishers[topic] = _Publisher(self, writer, msg_type, topic)
        return self.publishers[topic]

    def create_subscription(self, msg_type: str, topic: str, callback: Callable[[dict[str, Any]], None]) -> Any:
        """Call ``callback(fields)`` from :meth:`spin_once` for every message on ``topic``."""
        sub = self._subscriptions.get(topic)
        if sub is None:
            reader = self._dds.sub.DataReader(self.participant, self._topic(msg_type, topic), qos=self.qos)
            sub = self._subscriptions[topic] = _Subscription(reader, msg_type, topic)
        sub.callbacks.append(callback)
        return sub

    def spin_once(self) -> int:
        """Take every message that has arrived and hand it to its callbacks; returns how many were taken."""
        taken = 0
        recorder = self.recorder
        for sub in self._subscriptions.values():
            for sample in sub.reader.take(N=256):
                if not type(sample).__name__.endswith(sub.msg_type.rsplit("/", 1)[-1]):
                    continue  # a writer's dispose/unregister notice, no data
                fields = self.messages.from_idl(sub.msg_type, sample)
                taken += 1
                sub.count += 1
                if recorder is not None:
                    recorder.record(sub.topic, sub.msg_type, fields, time.time_ns(), sample.serialize())
                for callback in sub.callbacks:
                    callback(fields)
        return taken

    def spin_for(self, seconds: float, period: float = 0.001) -> int:
        """:meth:`spin_once` repeatedly for ``seconds`` [s]; returns how many messages were taken."""
        end = time.monotonic() + seconds
        taken = 0
        while True:
            taken += self.spin_once()
            if time.monotonic() >= end:
                return taken
            time.sleep(period)

    def now(self) -> float:
        """Monotonic time [s] (loops and timeouts; message stamps use the wall clock)."""
        return time.monotonic()

    def close(self) -> None:
        """Delete the participant (and with it every reader and writer): peers see them leave."""
        participant, self.participant = self.participant, None
        if participant is not None:
            self._subscriptions.clear()
            self.publishers.clear()
            self._topics.clear()
            participant.__del__()  # deletes its readers, writers and topics in Cyclone, now rather than at GC

    def __enter__(self) -> DdsInterface:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
