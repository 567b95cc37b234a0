"""A streaming node: a streamer and a :class:`~taplan.api.CommandScheduler` wired to the robot's topics.

Out: ``/api/{side}_arm/joint_cmd`` at the arm rate and ``/api/fsm/enable`` heartbeats. In:
``/{side}_arm/joint_states``. The node's logic is plain Python over a :class:`~taplan.ros.RosInterface`; rclpy is
needed only by :func:`create_rclpy_node`.

Life cycle:

1. Wait until every driven arm has reported a joint state, then ``streamer.reset(measured)`` (so the first command
   is where the robot is) and start publishing.
2. Every tick: heartbeat when due (only while streaming and enabled), and the next streamer command when due.
3. :meth:`StreamNode.disable` sends ``/api/fsm/enable`` -1.0 and stops the heartbeat (the robot pauses).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any, Literal, Protocol

import numpy as np

from taplan import api
from taplan.errors import InvalidInputError, UnknownNameError
from taplan.ros.interface import RclpyInterface, RosInterface, require_rclpy
from taplan.stream.state import StreamState

__all__ = ["StreamNode", "create_rclpy_node", "Streamer"]

logger = logging.getLogger(__name__)


class Streamer(Protocol):
    """What the node needs of a streamer: a :class:`~taplan.stream.JointStreamer` or a compatible object."""

    names: tuple[str, ...]
    dt: float

    def reset(self, position: Any) -> Any: ...

    def step(self) -> StreamState: ...


class StreamNode:
    """Publishes a streamer's commands to the robot and keeps the FSM enabled.

    Args:
        interface: Where to publish and subscribe (:class:`~taplan.ros.RclpyInterface`,
            :class:`~taplan.ros.FakeRosInterface`).
        streamer: Drives the joints of ``sides`` (its ``names`` must contain ``l_joint1..7`` / ``r_joint1..7``);
            its ``dt`` must equal the scheduler's arm period.
        scheduler: Says when arm commands and heartbeats are due.
        sides: Arms to drive.
        convention: ``joint_cmd`` convention (see :mod:`taplan.api`).
        state_timeout: A joint state older than this [s] is stale: ``"velocity_feedback"`` then sends zero
            velocity, and the node does not start on it.
        enable: Send heartbeats once streaming (False: only commands; the FSM is enabled by someone else).
    """

    def __init__(
        self,
        interface: RosInterface,
        streamer: Streamer,
        scheduler: api.CommandScheduler,
        *,
        sides: Sequence[str] = api.SIDES,
        convention: Literal["position", "velocity_feedback"] = "position",
        state_timeout: float = 0.5,
        enable: bool = True,
    ) -> None:
        if convention not in ("position", "velocity_feedback"):
            raise InvalidInputError("convention", convention, "'position' or 'velocity_feedback'")
        sides = tuple(sides)
        for side in sides:
            if side not in api.SIDES:
                raise UnknownNameError("side", side, api.SIDES)
        if abs(streamer.dt - scheduler.arm_period) > 1e-9:
            raise InvalidInputError(
                "streamer.dt", streamer.dt, f"the scheduler's arm period {scheduler.arm_period:.6g} s"
            )
        lookup = {n: i for i, n in enumerate(streamer.names)}
        self.indices: dict[str, np.ndarray] = {}
        for side in sides:
            missing = [n for n in api.ARM_JOINT_NAMES[side] if n not in lookup]
            if missing:
                raise UnknownNameError("streamer joint", missing[0], streamer.names)
            self.indices[side] = np.array([lookup[n] for n in api.ARM_JOINT_NAMES[side]])
        if sum(len(i) for i in self.indices.values()) != len(streamer.names):
            raise InvalidInputError("streamer.names", streamer.names, f"exactly the joints of the arms {sides}")
        self.interface = interface
        self.streamer = streamer
        self.scheduler = scheduler
        self.sides = sides
        self.convention = convention
        self.state_timeout = float(state_timeout)
        self.enabled = bool(enable)
        self.started = False
        self.last_state: StreamState | None = None
        self.measured: dict[str, tuple[float, np.ndarray]] = {}
        self.rejected_states = 0
        self._arm_publishers = {
            side: interface.create_publisher(api.JOINT_STATE, api.Topics.joint_cmd(side)) for side in sides
        }
        self._enable_publisher = interface.create_publisher(api.FLOAT32, api.Topics.ENABLE)
        for side in sides:
            interface.create_subscription(
                api.JOINT_STATE, api.Topics.joint_states(side), lambda fields, s=side: self.on_joint_state(s, fields)
            )

    def on_joint_state(self, side: str, fields: dict[str, Any]) -> None:
        """Subscription callback of ``/{side}_arm/joint_states``: remember the measured positions."""
        try:
            q = api.parse_joint_state(side, fields.get("name", []), fields.get("position", []))
        except (InvalidInputError, UnknownNameError) as exc:
            self.rejected_states += 1
            logger.warning("ignoring a %s joint state: %s", side, exc)
            return
        self.measured[side] = (self.interface.now(), q)

    def measured_position(self, now: float | None = None) -> np.ndarray | None:
        """The latest fresh measured positions in the streamer's order [rad], or None if an arm is missing/stale."""
        now = self.interface.now() if now is None else now
        q = np.empty(len(self.streamer.names))
        for side in self.sides:
            entry = self.measured.get(side)
            if entry is None or now - entry[0] > self.state_timeout:
                return None
            q[self.indices[side]] = entry[1]
        return q

    def tick(self) -> frozenset[str]:
        """Timer callback: publish what is due now; returns the channels published."""
        now = self.interface.now()
        due = self.scheduler.tick(now)
        published = set()
        if api.CommandScheduler.ARM in due:
            if not self.started:
                q = self.measured_position(now)
                if q is None:
                    return frozenset()
                self.streamer.reset(q)
                self.started = True
            state = self.streamer.step()
            self.last_state = state
            for side in self.sides:
                q_side = state.position[self.indices[side]]
                measured = None
                if self.convention == "velocity_feedback":
                    entry = self.measured.get(side)
                    fresh = entry is not None and now - entry[0] <= self.state_timeout
                    measured = entry[1] if fresh else q_side  # stale feedback: zero velocity
                message = api.joint_cmd(side, q_side, convention=self.convention, measured=measured)
                self._arm_publishers[side].publish(message.fields)
            published.add(api.CommandScheduler.ARM)
        if api.CommandScheduler.HEARTBEAT in due and self.started and self.enabled:
            self._enable_publisher.publish(api.fsm_enable(True).fields)
            published.add(api.CommandScheduler.HEARTBEAT)
        return frozenset(published)

    def disable(self) -> None:
        """Send ``/api/fsm/enable`` -1.0 (the robot pauses) and stop the heartbeat."""
        self.enabled = False
        self._enable_publisher.publish(api.fsm_enable(False).fields)


def create_rclpy_node(
    streamer: Streamer,
    *,
    node_name: str = "taplan_stream",
    arm_rate: float = 77.0,
    heartbeat_rate: float = api.HEARTBEAT_RATE,
    tick_rate: float = 500.0,
    **options: Any,
) -> tuple[Any, StreamNode]:
    """An ``rclpy`` node running a :class:`StreamNode` on a ``tick_rate`` [Hz] timer (call ``rclpy.init()`` first).

    Returns:
        ``(node, stream_node)``: spin ``node`` (``rclpy.spin(node)``); set targets on ``stream_node.streamer``.

    Raises:
        RosUnavailableError: rclpy is not installed / sourced.
    """
    rclpy = require_rclpy()
    node = rclpy.create_node(node_name)
    interface = RclpyInterface(node)
    scheduler = api.CommandScheduler(arm_rate, heartbeat_rate)
    stream_node = StreamNode(interface, streamer, scheduler, **options)
    node.create_timer(1.0 / tick_rate, stream_node.tick)
    return node, stream_node
