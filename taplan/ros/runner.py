"""Drive the arms over a :class:`~taplan.ros.RosInterface`: execute a plan or stream targets, and stop safely.

:class:`Runner` waits for ``/{side}_arm/joint_states`` of both arms, then publishes ``/api/{side}_arm/joint_cmd`` at
the arm rate (50-77 Hz) and the ``/api/fsm/enable`` heartbeat at 20 Hz, and watches the measured state:

* **Tracking.** The measured position must stay within ``tracking_error`` of the command sent one period earlier;
  beyond it the run is aborted.
* **Stall.** No joint state for ``state_timeout`` (200 ms): the run stops.
* **Ctrl-C / exceptions** (``KeyboardInterrupt`` or any error raised while running): the run stops.

Stopping is smooth: a :class:`~taplan.stream.JointStreamer` is reset to the last command's position, velocity and
acceleration and brakes to rest, jerk-limited and inside the limits; the braking commands are published at the arm
rate with the heartbeat, then the heartbeat stops (the robot keeps its last position; ``disable=True`` also sends
``/api/fsm/enable`` -1). Every command is checked against the hardware position limits before it is sent; a plan
that leaves them, or does not start at the measured position, is refused before anything moves.

The runner uses the wall clock and sleeps; everything else in taplan stays clock-free.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from taplan import api
from taplan.errors import InvalidInputError, TaplanError, UnknownNameError
from taplan.limits import JointLimits
from taplan.robot import Robot
from taplan.ros.interface import RosInterface
from taplan.ros.msg_definitions import FSM_STATE_TOPIC, INT32
from taplan.stream.joint_streamer import JointStreamer
from taplan.stream.state import StreamStatus
from taplan.trajectory import Trajectory

__all__ = ["RunnerConfig", "RunResult", "Runner", "RunError"]

logger = logging.getLogger(__name__)


READY = 2  # /fsm_state value of a robot that follows commands


class RunError(TaplanError):
    """The run cannot start (no joint states, a plan that does not start where the robot is, limits)."""


@dataclass(frozen=True)
class RunnerConfig:
    """How the runner drives the robot.

    Attributes:
        rate: ``joint_cmd`` rate [Hz], in the guide's 50-77.
        heartbeat_rate: ``/api/fsm/enable`` rate [Hz].
        state_timeout: Stop when no joint state arrived for this long [s].
        tracking_error: Abort when |measured - commanded| exceeds this [rad] on any joint.
        start_tolerance: A plan must start within this of the measured position [rad].
        wait_timeout: How long to wait for the first joint states [s].
        ready_timeout: How long to hold the measured position with heartbeats until ``/fsm_state`` reports READY
            [s]; a robot that publishes no ``/fsm_state`` is driven after this wait, with a warning.
        settle_time: After a plan's end, keep commanding its last point up to this long until the arm is within
            ``goal_tolerance`` [s].
        goal_tolerance: [rad].
        disable: Send ``/api/fsm/enable`` -1 at the end (the robot pauses) instead of only stopping the heartbeat.
    """

    rate: float = 77.0
    heartbeat_rate: float = api.HEARTBEAT_RATE
    state_timeout: float = 0.2
    tracking_error: float = 0.15
    start_tolerance: float = 0.05
    wait_timeout: float = 5.0
    ready_timeout: float = 3.0
    settle_time: float = 1.0
    goal_tolerance: float = 0.01
    disable: bool = False


@dataclass
class RunResult:
    """What happened.

    Attributes:
        status: ``"completed"``, ``"stopped"`` (stall, Ctrl-C, an error: braked to rest) or ``"aborted"`` (tracking
            error: braked to rest).
        reason: Why it ended.
        sent_times: Times of the commands [s] from the start, shape (k,).
        sent: Commanded positions [rad], shape (k, 14), model order.
        measured_times: Receive times of joint states [s], shape (m,).
        measured: Measured positions [rad], shape (m, 14).
        heartbeats: Number of heartbeats sent.
        max_tracking_error: Largest |measured - previous command| seen [rad].
        final_error: |measured - last command| at the end [rad] (max over joints), NaN if unknown.
        rejected_states: Joint states that were malformed (names, lengths, NaN) or out of order.
    """

    status: str
    reason: str
    sent_times: np.ndarray
    sent: np.ndarray
    measured_times: np.ndarray
    measured: np.ndarray
    heartbeats: int
    max_tracking_error: float
    final_error: float
    rejected_states: int

    def save(self, path: Any) -> None:
        """Write the sent and measured streams to ``path`` (.npz)."""
        np.savez(
            path,
            sent_times=self.sent_times,
            sent=self.sent,
            measured_times=self.measured_times,
            measured=self.measured,
            status=self.status,
            reason=self.reason,
        )


@dataclass
class _Log:
    sent_times: list[float] = field(default_factory=list)
    sent: list[np.ndarray] = field(default_factory=list)
    measured_times: list[float] = field(default_factory=list)
    measured: list[np.ndarray] = field(default_factory=list)


class _StopRequestError(Exception):
    def __init__(self, status: str, reason: str) -> None:
        super().__init__(reason)
        self.status = status
        self.reason = reason


class Runner:
    """Sends commands to both arms and watches the measured state.

    Args:
        interface: Transport with ``spin_once()`` (:class:`~taplan.ros.DdsInterface`).
        robot: The model (joint order, hardware limits for the command check).
        limits: Limits of the smooth stop (default ``robot.planning_limits``).
        config: Rates and thresholds.
        clock: Monotonic time [s]; ``sleep`` waits. Injected for tests.
        on_progress: Called with ``(time [s], duration [s] or None)`` about once per second.
        monitors: Called every period while moving; one that returns a reason (a string) stops the run smoothly
            with that reason (e.g. :meth:`taplan.ros.perception_link.PerceptionLink.monitor`: a broken camera
            stream).
    """

    def __init__(
        self,
        interface: Any,
        robot: Robot,
        limits: JointLimits | None = None,
        config: RunnerConfig | None = None,
        *,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        on_progress: Callable[[float, float | None], None] | None = None,
        monitors: tuple[Callable[[], str | None], ...] = (),
    ) -> None:
        self.interface: RosInterface = interface
        self.monitors = tuple(monitors)
        self.robot = robot
        self.config = config or RunnerConfig()
        self.limits = robot.planning_limits if limits is None else limits
        lo, hi = api.ARM_RATE_RANGE
        if not lo <= self.config.rate <= hi:
            raise InvalidInputError("rate", self.config.rate, f"a rate in [{lo:g}, {hi:g}] Hz")
        self.period = 1.0 / self.config.rate
        self.clock = clock
        self.sleep = sleep
        self.on_progress = on_progress
        self.indices = {side: robot.indices(api.ARM_JOINT_NAMES[side]) for side in api.SIDES}
        self._latest: dict[str, tuple[float, np.ndarray]] = {}
        self._stamps: dict[str, float] = {}
        self.rejected_states = 0
        self._commands = {s: interface.create_publisher(api.JOINT_STATE, api.Topics.joint_cmd(s)) for s in api.SIDES}
        self._enable = interface.create_publisher(api.FLOAT32, api.Topics.ENABLE)
        self.fsm_state: int | None = None
        interface.create_subscription(INT32, FSM_STATE_TOPIC, self._on_fsm)
        for side in api.SIDES:
            interface.create_subscription(api.JOINT_STATE, api.Topics.joint_states(side), self._on_state(side))

    # ------------------------------------------------------------------------------------------------- inputs
    def _on_fsm(self, fields: dict[str, Any]) -> None:
        self.fsm_state = int(fields.get("data", -1))

    def _on_state(self, side: str) -> Callable[[dict[str, Any]], None]:
        def callback(fields: dict[str, Any]) -> None:
            try:
                q = api.parse_joint_state(side, fields.get("name", []), fields.get("position", []))
            except (InvalidInputError, UnknownNameError) as exc:
                self.rejected_states += 1
                logger.warning("ignoring a /%s_arm/joint_states message: %s", side, exc)
                return
            stamp = fields.get("stamp")
            if stamp is not None and stamp > 0 and stamp < self._stamps.get(side, -np.inf):
                self.rejected_states += 1
                logger.warning("ignoring a /%s_arm/joint_states message stamped before the previous one", side)
                return
            if stamp is not None:
                self._stamps[side] = stamp
            self._latest[side] = (self.clock(), q)

        return callback

    def measured(self) -> tuple[float, np.ndarray] | None:
        """(age of the older arm's state [s], positions (14,)) or None before both arms reported."""
        if any(side not in self._latest for side in api.SIDES):
            return None
        q = np.empty(self.robot.nq)
        oldest = np.inf
        for side, (t, qs) in self._latest.items():
            q[self.indices[side]] = qs
            oldest = min(oldest, t)
        return self.clock() - oldest, q

    def wait_for_state(self) -> np.ndarray:
        """Spin until both arms have reported; the measured positions (14,) [rad].

        Raises:
            RunError: Nothing arrived within ``wait_timeout``.
        """
        end = self.clock() + self.config.wait_timeout
        while True:
            self.interface.spin_once()  # type: ignore[attr-defined]
            state = self.measured()
            if state is not None and state[0] <= self.config.state_timeout:
                return state[1]
            if self.clock() >= end:
                missing = [s for s in api.SIDES if s not in self._latest]
                raise RunError(
                    f"no joint states from {missing or 'both arms (stale)'} within {self.config.wait_timeout:g} s: "
                    "is the robot (or `taplan sim`) running on this ROS_DOMAIN_ID?"
                )
            self.sleep(0.002)

    def arm(self, hold: np.ndarray) -> None:
        """Enable the robot: heartbeats and ``hold`` commands at the arm rate until ``/fsm_state`` is READY (2).

        Raises:
            RunError: The FSM reported a state but not READY within ``ready_timeout``.
        """
        self._check_commands(hold[None, :])
        end = self.clock() + self.config.ready_timeout
        next_beat = next_command = self.clock()
        while True:
            now = self.clock()
            self.interface.spin_once()  # type: ignore[attr-defined]
            if self.fsm_state == READY:
                return
            state = self.measured()
            if state is None or state[0] > self.config.state_timeout:
                raise RunError("joint states stopped while enabling the robot: nothing was moved")
            if now >= end:
                if self.fsm_state is None:
                    logger.warning("no /fsm_state within %.1f s: driving without it", self.config.ready_timeout)
                    return
                raise RunError(f"the robot's FSM is in state {self.fsm_state}, not READY (2), after enabling")
            if now >= next_beat:
                self._enable.publish(api.fsm_enable(True).fields)
                next_beat = now + 1.0 / self.config.heartbeat_rate
            if now >= next_command:
                for side in api.SIDES:
                    self._commands[side].publish(api.joint_cmd(side, hold[self.indices[side]]).fields)
                next_command = now + self.period
            self.sleep(0.002)

    # ---------------------------------------------------------------------------------------------- execution
    def execute(self, trajectory: Trajectory) -> RunResult:
        """Run ``trajectory`` (its joints by name; other joints hold their measured positions) at the arm rate."""
        start_q = self.wait_for_state()
        names = trajectory.joint_names
        unknown = [n for n in names if n not in self.robot.joint_names]
        if unknown:
            raise UnknownNameError("trajectory joint", unknown[0], self.robot.joint_names)
        index = self.robot.indices(names)
        times = np.arange(0.0, trajectory.duration + 1e-12, self.period)
        if times[-1] < trajectory.duration:
            times = np.append(times, trajectory.duration)
        commands = np.repeat(start_q[None, :], len(times), axis=0)
        commands[:, index] = trajectory(times + trajectory.times[0])
        self._check_commands(commands)
        offset = np.abs(commands[0] - start_q)
        if offset.max() > self.config.start_tolerance:
            j = int(np.argmax(offset))
            raise RunError(
                f"the plan starts {offset[j]:.4f} rad from the measured {self.robot.joint_names[j]} "
                f"(tolerance {self.config.start_tolerance:g} rad): plan from the robot's current state"
            )
        self.arm(start_q)
        velocity = np.zeros_like(commands)
        acceleration = np.zeros_like(commands)
        velocity[:, index] = trajectory(times + trajectory.times[0], 1)
        acceleration[:, index] = trajectory(times + trajectory.times[0], 2)
        return self._drive(lambda k: (commands[k], velocity[k], acceleration[k]) if k < len(times) else None)

    def stream(
        self,
        targets: Callable[[float], Any],
        duration: float,
        *,
        streamer: Any = None,
    ) -> RunResult:
        """Stream live targets for ``duration`` [s] through a jerk-limited streamer, at the arm rate.

        ``targets(t)`` is called every period with the time since the start [s] and returns a new target, or None
        to keep the previous one: joint positions (14,) in model order [rad] for the default
        :class:`~taplan.stream.JointStreamer`, or ``{frame: T_root_frame}`` for a
        :class:`~taplan.stream.PoseStreamer` passed as ``streamer`` (same ``dt`` as the arm period). A target the
        streamer refuses (a :class:`~taplan.TaplanError`: NaN, wrong shape) is logged and skipped.
        """
        if not (isinstance(duration, (int, float)) and np.isfinite(duration) and duration > 0):
            raise InvalidInputError("duration", duration, "a positive time [s]")
        start_q = self.wait_for_state()
        if streamer is None:
            streamer = JointStreamer(self.limits, self.period, timeout=None)
            initial = streamer.reset(start_q, clamp=True)
        else:
            if abs(streamer.dt - self.period) > 1e-9:
                raise InvalidInputError("streamer.dt", streamer.dt, f"the arm period {self.period:.6g} s")
            initial = streamer.reset(start_q)
        self.arm(np.asarray(initial.position))
        steps = int(np.ceil(duration / self.period))

        def command(k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
            if k >= steps:
                return None
            target = targets(k * self.period)
            if target is not None:
                try:
                    streamer.set_target(target)
                except TaplanError as exc:
                    logger.warning("skipping a target: %s", exc)
            state = streamer.step()
            return state.position, state.velocity, state.acceleration

        return self._drive(command)

    def _check_commands(self, commands: np.ndarray) -> None:
        lower, upper = self.robot.limits.lower, self.robot.limits.upper
        over = np.maximum(commands - upper, lower - commands)
        if np.any(over > 1e-9):
            k, j = np.unravel_index(int(np.argmax(over)), over.shape)
            raise RunError(
                f"command {k} puts {self.robot.joint_names[j]} at {commands[k, j]:.6g} rad, outside the hardware "
                f"limits [{lower[j]:.6g}, {upper[j]:.6g}]: nothing was sent"
            )

    def _publish(self, q: np.ndarray, now: float, log: _Log) -> None:
        self._check_commands(q[None, :])
        for side in api.SIDES:
            self._commands[side].publish(api.joint_cmd(side, q[self.indices[side]]).fields)
        log.sent_times.append(now)
        log.sent.append(q.copy())

    def _drive(self, command: Callable[[int], tuple[np.ndarray, np.ndarray, np.ndarray] | None]) -> RunResult:
        cfg = self.config
        log = _Log()
        t0 = self.clock()
        next_beat = t0
        beats = 0
        worst = 0.0
        previous: np.ndarray | None = None
        state = (np.zeros(0),) * 3
        k = 0
        settle_until: float | None = None
        last_progress = t0
        status, reason = "completed", "plan finished"
        try:
            while True:
                now = self.clock()
                self.interface.spin_once()  # type: ignore[attr-defined]
                for monitor in self.monitors:
                    why = monitor()
                    if why:
                        raise _StopRequestError("stopped", f"{why}: stopping")
                measured = self.measured()
                if measured is not None:
                    age, q_meas = measured
                    if not log.measured_times or log.measured_times[-1] != self._latest_time():
                        log.measured_times.append(self._latest_time() - t0)
                        log.measured.append(q_meas)
                    if age > cfg.state_timeout:
                        raise _StopRequestError("stopped", f"no joint states for {age * 1e3:.0f} ms: stopping")
                    if previous is not None:
                        error = float(np.max(np.abs(q_meas - previous)))
                        worst = max(worst, error)
                        if error > cfg.tracking_error:
                            raise _StopRequestError(
                                "aborted",
                                f"tracking error {error:.3f} rad > {cfg.tracking_error:g} rad: aborting",
                            )
                if now >= next_beat:
                    self._enable.publish(api.fsm_enable(True).fields)
                    beats += 1
                    next_beat += 1.0 / cfg.heartbeat_rate
                    if next_beat < now:
                        next_beat = now + 1.0 / cfg.heartbeat_rate
                if now >= t0 + k * self.period:
                    nxt = command(k)
                    if nxt is None:
                        if settle_until is None:
                            settle_until = now + cfg.settle_time
                        if measured is not None and float(np.max(np.abs(measured[1] - state[0]))) <= cfg.goal_tolerance:
                            break
                        if now >= settle_until:
                            reason = f"plan finished; not within {cfg.goal_tolerance:g} rad after {cfg.settle_time:g} s"
                            break
                        self._publish(state[0], now - t0, log)
                    else:
                        state = nxt
                        previous = log.sent[-1] if log.sent else None
                        self._publish(state[0], now - t0, log)
                    k += 1
                if self.on_progress is not None and now - last_progress >= 1.0:
                    last_progress = now
                    self.on_progress(now - t0, None)
                self.sleep(min(0.001, max(0.0, t0 + k * self.period - self.clock())))
        except _StopRequestError as stop:
            status, reason = stop.status, stop.reason
            logger.warning(reason)
            beats += self._brake(state, log, t0)
        except KeyboardInterrupt:
            status, reason = "stopped", "interrupted (Ctrl-C): stopping"
            logger.warning(reason)
            beats += self._brake(state, log, t0)
        except Exception as exc:  # any failure while moving ends in a smooth stop, then propagates as a result
            status, reason = "stopped", f"{type(exc).__name__}: {exc}: stopping"
            logger.error(reason)
            beats += self._brake(state, log, t0)
        if cfg.disable:
            self._enable.publish(api.fsm_enable(False).fields)
        final = self.measured()
        last = log.sent[-1] if log.sent else None
        final_error = float(np.max(np.abs(final[1] - last))) if final is not None and last is not None else np.nan
        n = self.robot.nq
        return RunResult(
            status,
            reason,
            np.asarray(log.sent_times),
            np.asarray(log.sent).reshape(-1, n),
            np.asarray(log.measured_times),
            np.asarray(log.measured).reshape(-1, n),
            beats,
            worst,
            final_error,
            self.rejected_states,
        )

    def _latest_time(self) -> float:
        return max(t for t, _ in self._latest.values())

    def _brake(self, state: tuple[np.ndarray, np.ndarray, np.ndarray], log: _Log, t0: float) -> int:
        """Brake from the last command to rest, jerk-limited, publishing at the arm rate; returns heartbeats sent."""
        if state[0].size == 0:
            return 0
        streamer = JointStreamer(self.limits, self.period, timeout=None)
        position, velocity, acceleration = (np.asarray(x, dtype=float) for x in state)
        velocity = np.clip(velocity, -self.limits.velocity, self.limits.velocity)
        acceleration = np.clip(acceleration, -self.limits.acceleration, self.limits.acceleration)
        try:
            streamer.reset(position, velocity, acceleration, clamp=True)
        except TaplanError:  # a state the planning limits cannot brake: hold the last command instead
            logger.error("cannot brake within the planning limits from the last command; holding it")
            return 0
        streamer.stop()
        beats = 0
        next_beat = self.clock()
        for _ in range(int(10.0 / self.period)):
            tick = self.clock()
            step = streamer.step()
            try:
                self._publish(step.position, tick - t0, log)
            except TaplanError as exc:
                logger.error("braking command refused: %s", exc)
                break
            if tick >= next_beat:
                self._enable.publish(api.fsm_enable(True).fields)
                beats += 1
                next_beat = tick + 1.0 / self.config.heartbeat_rate
            if step.status in (StreamStatus.STOPPED, StreamStatus.IDLE, StreamStatus.REACHED):
                break
            self.sleep(max(0.0, tick + self.period - self.clock()))
        return beats
