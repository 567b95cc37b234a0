"""A simulated TeleAvatar on the other end of a :class:`~taplan.ros.RosInterface`: rehearse without the robot.

It plays the robot's API mode: subscribes ``/api/{side}_arm/joint_cmd``, ``/api/fsm/enable``,
``/api/{side}_gripper/cmd`` and ``/api/fsm/adjust``; publishes ``/{side}_arm/joint_states`` and
``/{side}_arm/current_ee_pose`` (default 100 Hz, the real robot's rate) and ``/fsm_state`` (20 Hz). The rules are
the guide's and the vendor simulator's (``API_NOTES.md`` §3-4):

* **FSM.** ``PAUSE`` (0) holds the latched position. An enable of exactly 1.0 refreshes the heartbeat (the guide:
  "send data=1.0 continuously"; any other positive value is rejected, logged and counted, and is no heartbeat); from
  ``PAUSE`` it
  resets the target to the current position and enters ``SLOW_START`` (1), where the arm moves toward commands at
  ``slow_start_speed``; ``READY`` (2) follows once both arms have commanded since enabling and stayed within
  ``ready_tolerance`` of their targets for ``ready_cycles`` 20 Hz checks. An enable <= 0 pauses at once; no enable
  for ``heartbeat_timeout`` (1 s) force-pauses. Non-finite enables are ignored.
* **Commands.** Exactly 7 finite positions; names empty (index order) or exactly the arm's 7 names in any order.
  Anything else is rejected with a log line (and counted in ``rejected``). A target outside the hardware limits is
  clipped to them and counted (``rejected["out_of_range"]``, a warning per second at most naming the joint and
  value), or refused whole with ``refuse_out_of_range``. Commands while paused are ignored.
* **Motion.** ``motion="joint"`` (default): the joint-mode model of :class:`taplan.reference.JointModeRobot`: each
  10 ms tick the arm moves to the latest target, at most the velocity ceiling times the tick.
  ``motion="interpolate"``: the seed simulator's linear branch applied to a command stream (each ``joint_cmd`` is a
  positions-only waypoint, reached along the straight line from where the arm is over the interval since the
  previous command, clamped to [one motion tick, ``max_segment``]), the velocity ceiling still applying; with
  ``state_rate=10`` it publishes like the seed. A plan whose velocities jump shows the same steps here.
* **Gripper.** Commands in [0, 1]; others are rejected.
* **Adjust.** ``/api/fsm/adjust`` 1 enters ``ADJUST`` (3, taplan's number): the arms visit ``adjust_poses`` (default
  home) at ``slow_start_speed``, commands and enables are ignored, no heartbeat is needed, and the FSM pauses on its
  own when the routine is complete; -1 leaves it (PAUSE).

Fault injection for tests: ``stall_after`` stops the joint_states after that time, as a frozen driver would.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np

from taplan import api
from taplan.errors import InvalidInputError
from taplan.robot import Robot
from taplan.ros.interface import RosInterface
from taplan.ros.msg_definitions import FSM_STATE_TOPIC, INT32

__all__ = ["FsmState", "SimConfig", "SimulatedRobot"]

logger = logging.getLogger(__name__)


class FsmState(IntEnum):
    """The robot's FSM states as published on ``/fsm_state``."""

    PAUSE = 0
    SLOW_START = 1
    READY = 2
    ADJUST = 3  # taplan's number: the guide names ADJUST MODE but not its /fsm_state value


@dataclass(frozen=True)
class SimConfig:
    """Rates and rules of the simulated robot.

    Attributes:
        state_rate: ``joint_states`` / ``current_ee_pose`` rate [Hz].
        fsm_rate: FSM check and ``/fsm_state`` rate [Hz].
        motion_rate: Motion model rate [Hz].
        heartbeat_timeout: Force pause after this long without an enable [s].
        slow_start_speed: Joint speed toward commands in SLOW_START [rad]/[s].
        ready_tolerance: Largest |q - target| to become READY [rad].
        ready_cycles: Consecutive FSM checks within tolerance to become READY.
        stall_after: Stop publishing joint states after this time [s] (fault injection), or None.
        motion: Motion model, ``"joint"`` or ``"interpolate"`` (see the module notes).
        max_segment: Longest interpolation segment of ``"interpolate"`` [s] (a command after a pause).
        refuse_out_of_range: Refuse a command outside the hardware limits instead of clipping it (both counted).
        adjust_poses: The ``/api/fsm/adjust`` routine's configurations (14,) in model order, visited in turn at
            ``slow_start_speed`` (the robot reads ``robot.adjust_pose``; default: the robot's home).
    """

    state_rate: float = 100.0
    fsm_rate: float = 20.0
    motion_rate: float = 100.0
    heartbeat_timeout: float = 1.0
    slow_start_speed: float = 0.5
    ready_tolerance: float = 0.08
    ready_cycles: int = 5
    stall_after: float | None = None
    motion: str = "joint"
    max_segment: float = 0.1
    refuse_out_of_range: bool = False
    adjust_poses: tuple[tuple[float, ...], ...] | None = None


MOTIONS = ("joint", "interpolate")


class _Every:
    """Due every ``1/rate`` seconds from the first call, skipping missed slots."""

    def __init__(self, rate: float) -> None:
        self.period = 1.0 / rate
        self.next: float | None = None

    def due(self, now: float) -> bool:
        if self.next is None:
            self.next = now
        if now + 1e-9 < self.next:
            return False
        self.next = max(self.next + self.period, now - self.period / 2)
        return True


class SimulatedRobot:
    """The TeleAvatar's API mode over ``interface``: call :meth:`step` often (>= the motion rate).

    Args:
        interface: Transport (:class:`~taplan.ros.DdsInterface`, or a fake for tests).
        robot: Kinematic model (hardware limits, end-effector frames ``left_ee`` / ``right_ee``).
        config: Rates and rules.
        initial: Initial joint positions [rad], shape (14,), model order; default ``robot.home``.
    """

    def __init__(
        self,
        interface: RosInterface,
        robot: Robot,
        config: SimConfig | None = None,
        initial: Any = None,
    ) -> None:
        self.interface = interface
        self.robot = robot
        self.config = config or SimConfig()
        if self.config.motion not in MOTIONS:
            raise InvalidInputError("config.motion", self.config.motion, f"one of {MOTIONS}")
        if not (math.isfinite(self.config.max_segment) and self.config.max_segment > 0):
            raise InvalidInputError("config.max_segment", self.config.max_segment, "a duration > 0 [s]")
        self.q = robot.home.copy() if initial is None else robot.check_configuration(initial, "initial").copy()
        self.v = np.zeros_like(self.q)
        self.target = self.q.copy()
        self.lower, self.upper = robot.limits.lower, robot.limits.upper
        self.speed = np.asarray(robot.limits.velocity, dtype=float)
        self.fsm = FsmState.PAUSE
        self.last_enable: float | None = None
        self.commanded = dict.fromkeys(api.SIDES, False)
        self.ready_count = 0
        self.gripper = dict.fromkeys(api.SIDES, 0.0)
        self.rejected: dict[str, int] = {}
        self.transitions: list[tuple[float, FsmState, str]] = []
        self.indices = {side: robot.indices(api.ARM_JOINT_NAMES[side]) for side in api.SIDES}
        self.started: float | None = None
        self._last_motion: float | None = None
        # "interpolate": per arm, (segment start positions, start time, duration), and the last command's time
        self._segments: dict[str, tuple[np.ndarray, float, float]] = {}
        self._last_command: dict[str, float] = {}
        self._out_of_range_logged = -math.inf
        self._state_timer = _Every(self.config.state_rate)
        self._fsm_timer = _Every(self.config.fsm_rate)
        self._motion_timer = _Every(self.config.motion_rate)
        self._states = {s: interface.create_publisher(api.JOINT_STATE, api.Topics.joint_states(s)) for s in api.SIDES}
        self._poses = {s: interface.create_publisher(api.POSE, api.Topics.current_ee_pose(s)) for s in api.SIDES}
        self._fsm_publisher = interface.create_publisher(INT32, FSM_STATE_TOPIC)
        for side in api.SIDES:
            interface.create_subscription(api.JOINT_STATE, api.Topics.joint_cmd(side), self._on_command(side))
            interface.create_subscription(api.FLOAT32, api.Topics.gripper(side), self._on_gripper(side))
        interface.create_subscription(api.FLOAT32, api.Topics.ENABLE, self.on_enable)
        interface.create_subscription(api.FLOAT32, api.Topics.ADJUST, self.on_adjust)
        poses = self.config.adjust_poses or (tuple(robot.home),)
        self.adjust_poses = [robot.check_configuration(p, "config.adjust_poses").copy() for p in poses]
        self._adjust_next = 0

    # ------------------------------------------------------------------------------------------------ callbacks
    def _reject(self, reason: str, topic: str, detail: str) -> None:
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
        logger.warning("rejected %s: %s", topic, detail)

    def _on_command(self, side: str) -> Any:
        return lambda fields: self.on_joint_cmd(side, fields)

    def _on_gripper(self, side: str) -> Any:
        return lambda fields: self.on_gripper(side, fields)

    def on_joint_cmd(self, side: str, fields: dict[str, Any]) -> None:
        """``/api/{side}_arm/joint_cmd``: validate, clip to the hardware limits, set the target."""
        topic = api.Topics.joint_cmd(side)
        expected = api.ARM_JOINT_NAMES[side]
        names = [str(n) for n in fields.get("name", [])]
        try:
            q = np.asarray(fields.get("position", []), dtype=float)
        except (TypeError, ValueError):
            self._reject("malformed", topic, "positions are not numbers")
            return
        if q.shape != (len(expected),):
            self._reject("length", topic, f"{q.size} positions, expected exactly {len(expected)}")
            return
        if names:
            if sorted(names) != sorted(expected) or len(set(names)) != len(names):
                self._reject("names", topic, f"names {names}, expected the 7 names {list(expected)} in any order")
                return
            q = q[[names.index(n) for n in expected]]
        if not np.all(np.isfinite(q)):
            self._reject("not_finite", topic, f"non-finite positions {q.tolist()}")
            return
        if self.fsm in (FsmState.PAUSE, FsmState.ADJUST):  # the adjust routine owns the arms
            key = "paused" if self.fsm == FsmState.PAUSE else "adjusting"
            self.rejected[key] = self.rejected.get(key, 0) + 1
            return
        index = self.indices[side]
        over = np.maximum(q - self.upper[index], self.lower[index] - q)
        if np.any(over > 1e-9):
            j = int(np.argmax(over))
            self.rejected["out_of_range"] = self.rejected.get("out_of_range", 0) + 1
            now = self.interface.now()
            if now - self._out_of_range_logged >= 1.0:  # a stream of them: one line a second, the count says how many
                self._out_of_range_logged = now
                action = "refused" if self.config.refuse_out_of_range else "clipped"
                logger.warning(
                    "%s %s: %s at %.6g rad, outside the hardware limits [%.6g, %.6g] (%d so far)",
                    action,
                    topic,
                    api.ARM_JOINT_NAMES[side][j],
                    q[j],
                    self.lower[index][j],
                    self.upper[index][j],
                    self.rejected["out_of_range"],
                )
            if self.config.refuse_out_of_range:
                return
        self.target[index] = np.clip(q, self.lower[index], self.upper[index])
        self.commanded[side] = True
        if self.config.motion == "interpolate":
            now = self.interface.now()
            tick = 1.0 / self.config.motion_rate
            since = now - self._last_command.get(side, -math.inf)
            self._segments[side] = (self.q[index].copy(), now, min(max(since, tick), self.config.max_segment))
            self._last_command[side] = now

    def on_enable(self, fields: dict[str, Any]) -> None:
        """``/api/fsm/enable``: heartbeat (exactly 1.0), pause (<= 0); other values are rejected and counted."""
        value = float(fields.get("data", math.nan))
        now = self.interface.now()
        if not math.isfinite(value):
            self._reject("not_finite", api.Topics.ENABLE, f"enable {value}")
            return
        if value > 0 and value != 1.0:
            self._reject("enable_value", api.Topics.ENABLE, f"enable {value:g}: the heartbeat is exactly 1.0")
            return
        if value <= 0:
            self.last_enable = None
            self._enter(FsmState.PAUSE, now, "disabled")
            return
        if self.fsm == FsmState.ADJUST:  # the guide: enable after the routine has finished (it pauses on its own)
            self._reject("adjusting", api.Topics.ENABLE, "enable during the adjust routine")
            return
        self.last_enable = now
        if self.fsm == FsmState.PAUSE:
            self.target = self.q.copy()
            self._segments.clear()
            self.commanded = dict.fromkeys(api.SIDES, False)
            self.ready_count = 0
            self._enter(FsmState.SLOW_START, now, "enabled")

    def on_adjust(self, fields: dict[str, Any]) -> None:
        """``/api/fsm/adjust``: 1 starts the adjust routine (the arms visit ``adjust_poses`` at the slow-start speed,
        then the FSM pauses on its own); -1 leaves it (PAUSE); other values are rejected."""
        value = float(fields.get("data", math.nan))
        now = self.interface.now()
        if value == 1.0:
            self._adjust_next = 0
            self._segments.clear()
            self.target = self.adjust_poses[0].copy()
            self.last_enable = None
            self._enter(FsmState.ADJUST, now, "adjust requested")
        elif value == -1.0:
            if self.fsm == FsmState.ADJUST:
                self._enter(FsmState.PAUSE, now, "adjust cancelled")
        else:
            self._reject("adjust_value", api.Topics.ADJUST, f"adjust {value:g}: expected 1 (start) or -1 (stop)")

    def on_gripper(self, side: str, fields: dict[str, Any]) -> None:
        """``/api/{side}_gripper/cmd``: a trigger value in [0, 1]."""
        value = float(fields.get("data", math.nan))
        if not (math.isfinite(value) and 0.0 <= value <= 1.0):
            self._reject("gripper_range", api.Topics.gripper(side), f"{value}, expected a value in [0, 1]")
            return
        self.gripper[side] = value

    def _enter(self, state: FsmState, now: float, reason: str) -> None:
        if state != self.fsm:
            if state == FsmState.PAUSE:
                self.target = self.q.copy()
                self.v[:] = 0.0
                self._segments.clear()
            logger.info("fsm %s -> %s (%s)", self.fsm.name, state.name, reason)
            self.fsm = state
            self.transitions.append((now, state, reason))

    # ---------------------------------------------------------------------------------------------------- loop
    def start(self, period: float = 0.0005) -> Callable[[], None]:
        """Run the robot on a daemon thread (``interface.spin_once()`` then :meth:`step`, every ``period`` [s]).

        For rehearsals in one process; ``taplan sim`` runs it in its own. Returns ``stop()``, which joins the
        thread and closes the interface.
        """
        done = threading.Event()

        def loop() -> None:
            while not done.is_set():
                self.interface.spin_once()  # type: ignore[attr-defined]
                self.step()
                time.sleep(period)

        thread = threading.Thread(target=loop, name="taplan-sim", daemon=True)
        thread.start()

        def stop() -> None:
            done.set()
            thread.join(timeout=5.0)
            close = getattr(self.interface, "close", None)
            if close is not None:
                close()

        return stop

    def step(self, now: float | None = None) -> None:
        """Advance the motion, the FSM and the publishers to ``now`` [s] (default the interface's time)."""
        now = self.interface.now() if now is None else float(now)
        if self.started is None:
            self.started = now
        if self._motion_timer.due(now):
            self._move(now)
        if self._fsm_timer.due(now):
            self._check_fsm(now)
            self._fsm_publisher.publish({"data": int(self.fsm)})
        stalled = self.config.stall_after is not None and now - self.started >= self.config.stall_after
        if self._state_timer.due(now) and not stalled:
            self._publish_states()

    def _move(self, now: float) -> None:
        dt = 0.0 if self._last_motion is None else now - self._last_motion
        self._last_motion = now
        if dt <= 0.0 or self.fsm == FsmState.PAUSE:
            self.v[:] = 0.0
            return
        cap = self.speed if self.fsm == FsmState.READY else np.full_like(self.q, self.config.slow_start_speed)
        desired = self.target.copy() if self._segments else self.target
        for side, (start, t0, duration) in self._segments.items():
            index = self.indices[side]
            fraction = min(1.0, max(0.0, (now - t0) / duration))
            desired[index] = start + fraction * (self.target[index] - start)
        step = np.clip(desired - self.q, -cap * dt, cap * dt)
        self.q = self.q + step
        self.v = step / dt

    def _check_fsm(self, now: float) -> None:
        if self.fsm == FsmState.PAUSE:
            return
        if self.fsm == FsmState.ADJUST:  # no heartbeat needed: the routine runs on its own, then pauses
            if float(np.max(np.abs(self.q - self.target))) <= 1e-3:
                self._adjust_next += 1
                if self._adjust_next >= len(self.adjust_poses):
                    self._enter(FsmState.PAUSE, now, "adjust complete")
                else:
                    self.target = self.adjust_poses[self._adjust_next].copy()
            return
        if self.last_enable is None or now - self.last_enable > self.config.heartbeat_timeout:
            self.last_enable = None
            self._enter(FsmState.PAUSE, now, f"no heartbeat for {self.config.heartbeat_timeout:g} s: force pause")
            return
        if self.fsm == FsmState.SLOW_START:
            close = float(np.max(np.abs(self.q - self.target))) <= self.config.ready_tolerance
            self.ready_count = self.ready_count + 1 if close and all(self.commanded.values()) else 0
            if self.ready_count >= self.config.ready_cycles:
                self._enter(FsmState.READY, now, "commands tracked")

    def _publish_states(self) -> None:
        poses = self.robot.frame_poses(self.q, ("left_ee", "right_ee"))
        for side in api.SIDES:
            index = self.indices[side]
            names = list(api.ARM_JOINT_NAMES[side])
            fields = {
                "name": names,
                "position": self.q[index].tolist(),
                "velocity": self.v[index].tolist(),
                "effort": [0.0] * len(names),
            }
            self._states[side].publish(fields)
            self._poses[side].publish(_pose_fields(poses[f"{side}_ee"]))


def _pose_fields(T: np.ndarray) -> dict[str, Any]:
    import pinocchio as pin

    x, y, z, w = pin.Quaternion(T[:3, :3]).coeffs()
    p = T[:3, 3]
    return {
        "position": {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])},
        "orientation": {"x": float(x), "y": float(y), "z": float(z), "w": float(w)},
    }


def check_rate(rate: float, name: str) -> float:
    """A positive finite rate [Hz]."""
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
        raise InvalidInputError(name, rate, "a rate > 0 Hz")
    return float(rate)
