"""Drive the arms over a :class:`~taplan.ros.RosInterface`: execute a plan or stream targets, and stop safely.

:class:`Runner` waits for ``/{side}_arm/joint_states`` of both arms, then publishes ``/api/{side}_arm/joint_cmd`` at
the arm rate (50-77 Hz) and the ``/api/fsm/enable`` heartbeat at 20 Hz, and watches the measured state:

* **Tracking.** The measured position must stay within ``tracking_error`` of the command sent one period before it
  arrived; beyond it the run is aborted.
* **Stall.** Joint states older than ``stale_periods`` (5) of the robot's measured publishing period (>= 200 ms, at
  most ``state_timeout``): the run stops, naming the stall and how old the last state is.
* **Ctrl-C / exceptions** (``KeyboardInterrupt`` or any error raised while running): the run stops.
* **An outside disable wins.** The runner reads ``/api/fsm/enable`` from every writer and ``/fsm_state``: a
  disable (<= 0) it did not send, or a PAUSE (0) after READY, ends the run at once with status ``"disabled"``
  ("disabled by another node"): no further heartbeat (it would re-enable the robot), no command, no brake (the
  robot is paused). Only a new :meth:`Runner.execute` / :meth:`Runner.stream` call enables it again.
* **No /fsm_state, no motion.** A robot that publishes no ``/fsm_state`` within ``ready_timeout`` is not driven
  (nothing moved) unless ``RunnerConfig(require_fsm=False)`` (``taplan run --no-fsm``) says to drive it unconfirmed.

Stopping is smooth: a :class:`~taplan.stream.JointStreamer` is reset to the last command's position, velocity and
acceleration and brakes to rest, jerk-limited and inside the limits; the braking commands are published at the arm
rate with the heartbeat, then the heartbeat stops (the robot keeps its last position; ``disable=True`` also sends
``/api/fsm/enable`` -1). Every command is checked against the hardware position limits before it is sent; a plan
that leaves them, or does not start at the measured position, is refused before anything moves.

The runner uses the wall clock and sleeps; everything else in taplan stays clock-free.
"""

from __future__ import annotations

import bisect
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from taplan import api
from taplan.check import Report, Thresholds, check
from taplan.clearance import SELF_CLEARANCE, check_clearance, robot_world
from taplan.errors import CollisionError, InvalidInputError, TaplanError, UnknownNameError
from taplan.limits import JointLimits
from taplan.planning.verify import check_segment
from taplan.reference.replay import JointStateSamples
from taplan.robot import Robot
from taplan.ros.interface import RosInterface
from taplan.ros.msg_definitions import FSM_STATE_TOPIC, INT32
from taplan.stream.joint_streamer import JointStreamer
from taplan.stream.state import StreamStatus
from taplan.trajectory import Trajectory

__all__ = ["RunnerConfig", "RunResult", "Runner", "RunError", "CheckFailedError", "PreSendCheck"]

logger = logging.getLogger(__name__)


STREAM_MARGIN = 0.005  # [m] a streamed command closer than this (above the clearance) to a collision stops the stream
COMMAND_VELOCITIES = ("zero", "feedforward", "feedback")
MIN_STALE = 0.2  # [s] never stale sooner: a loaded 2-core machine delays a 100 Hz stream by 130 ms (measured)
PAUSE = 0  # /fsm_state value of a paused robot (an operator's or a supervisor's disable, or no heartbeat)
READY = 2  # /fsm_state value of a robot that follows commands


class RunError(TaplanError):
    """The run cannot start (no joint states, a plan that does not start where the robot is, limits)."""


class CheckFailedError(RunError):
    """The plan fails the pre-send check (``taplan check``'s limits, the commands, collision): nothing was sent.

    Attributes:
        line: The first failing line.
        report: Every check's lines (the reports' tables and the collision line).
    """

    def __init__(self, line: str, report: str) -> None:
        super().__init__(f"pre-send check FAIL: {line}: nothing was sent")
        self.line = line
        self.report = report


@dataclass(frozen=True)
class PreSendCheck:
    """What :meth:`Runner.check_plan` found: the plan as ``taplan check`` judges it (``plan``), the commands the
    runner would send at its rate (``commands``, hardware limits, velocity steps at the command period) and the
    clearance of the robot's own bodies plus the scene (``clearance``)."""

    plan: Any
    commands: Any
    clearance: Any

    @property
    def passed(self) -> bool:
        return bool(self.plan.passed and self.commands.passed and self.clearance.passed)

    @property
    def failures(self) -> list[str]:
        out = [f"plan: {f}" for f in self.plan.failures]
        out += [f"commands: {f}" for f in self.commands.failures]
        if not self.clearance.passed:
            out.append(self.clearance.line())
        return out

    def table(self) -> str:
        return "\n".join([self.plan.table(), self.commands.table(), self.clearance.line()])


@dataclass(frozen=True)
class RunnerConfig:
    """How the runner drives the robot.

    Attributes:
        rate: ``joint_cmd`` rate [Hz], in the guide's 50-77.
        heartbeat_rate: ``/api/fsm/enable`` rate [Hz].
        state_timeout: Stop when no joint state arrived for this long [s] (the ceiling; see ``stale_periods``).
        stale_periods: Stop when the joint states are older than this many of the robot's measured publishing
            periods (at least ``MIN_STALE``, 200 ms): a stall is named by its age, before the tracking
            error it causes. ``inf`` leaves ``state_timeout`` alone to decide (``taplan run --state-timeout``).
        tracking_error: Abort when |measured - commanded| exceeds this [rad] on any joint.
        start_tolerance: A plan must start within this of the measured position [rad].
        wait_timeout: How long to wait for the first joint states [s].
        ready_timeout: How long to hold the measured position with heartbeats until ``/fsm_state`` reports READY
            [s]. A robot that publishes no ``/fsm_state`` (the guide does not list it) is refused after this wait
            (nothing moved) unless ``require_fsm`` is False.
        command_velocity: What ``JointState.velocity`` of each command carries: ``"zero"`` (default),
            ``"feedforward"`` (the plan's or streamer's velocity at the command) or ``"feedback"`` (the guide's P form
            ``clip(kp (q_cmd - q_measured), ±0.3 v_max)``, :func:`taplan.api.feedback_velocity`). Zero is the default
            because the v2 robot and the vendor simulator read ``position`` only (API_NOTES §4: "Clients send
            velocity and effort as zeros"), so any other value is information the robot ignores, and the P form is
            the v1 relay's velocity command: on a robot that does read it, it would add a second, unplanned
            controller. ``taplan sim`` reads positions only under all three; ``taplan check`` of a bag judges
            the commanded positions (their finite differences), never the velocity field.
        require_fsm: Drive only a robot whose ``/fsm_state`` reported READY. False (``taplan run --no-fsm``)
            drives a robot without ``/fsm_state`` after ``ready_timeout``, unconfirmed, with a warning; an outside
            disable is then seen only on ``/api/fsm/enable``.
        settle_time: After a plan's end, keep commanding its last point up to this long until the arm is within
            ``goal_tolerance`` [s].
        goal_tolerance: [rad].
        disable: Send ``/api/fsm/enable`` -1 at the end (the robot pauses) instead of only stopping the heartbeat.
    """

    rate: float = 77.0
    heartbeat_rate: float = api.HEARTBEAT_RATE
    state_timeout: float = 0.2
    stale_periods: float = 5.0
    tracking_error: float = 0.15
    start_tolerance: float = 0.05
    wait_timeout: float = 5.0
    ready_timeout: float = 3.0
    settle_time: float = 1.0
    goal_tolerance: float = 0.01
    disable: bool = False
    require_fsm: bool = True
    command_velocity: str = "zero"

    def __post_init__(self) -> None:
        for name in (
            "rate",
            "heartbeat_rate",
            "state_timeout",
            "tracking_error",
            "start_tolerance",
            "wait_timeout",
            "ready_timeout",
            "goal_tolerance",
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (0 < value < float("inf")):
                raise InvalidInputError(name, value, "a positive, finite number")
        periods = self.stale_periods
        if isinstance(periods, bool) or not isinstance(periods, (int, float)) or not periods > 0:
            raise InvalidInputError("stale_periods", periods, "a positive number of periods (inf: state_timeout only)")
        if not (isinstance(self.settle_time, (int, float)) and 0 <= self.settle_time < float("inf")):
            raise InvalidInputError("settle_time", self.settle_time, "a time >= 0 [s]")


@dataclass
class RunResult:
    """What happened.

    Attributes:
        status: ``"completed"``, ``"stopped"`` (stall, Ctrl-C, an error: braked to rest), ``"aborted"`` (tracking
            error: braked to rest) or ``"disabled"`` (another node disabled the robot: no command and no heartbeat
            was sent after it was seen).
        reason: Why it ended.
        sent_times: Times of the commands [s] from the start, shape (k,).
        sent: Commanded positions [rad], shape (k, 14), model order.
        measured_times: Receive times of joint states [s], shape (m,).
        measured: Measured positions [rad], shape (m, 14).
        heartbeats: Number of heartbeats sent.
        max_tracking_error: Largest |measured - the command sent one period before it arrived| seen [rad].
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
        """Write the sent and measured streams to ``path`` (.npz; missing directories are created)."""
        from taplan.io.paths import output_path

        np.savez(
            output_path(path, "path", suffixes=(".npz",)),
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
        world: The :class:`~taplan.scene.CollisionWorld` every plan and streamed command is checked against
            (default the robot's own bodies; pass one with a scene to add its obstacles).
        clearance: Required clearance of the world's pairs [m] (default
            :data:`~taplan.clearance.SELF_CLEARANCE`).
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
        world: Any = None,
        clearance: float = SELF_CLEARANCE,
    ) -> None:
        self.interface: RosInterface = interface
        self.monitors = tuple(monitors)
        self.world = robot_world(robot if world is None else world)
        self.presend: PreSendCheck | None = None  # the last plan's pre-send check
        self.clearance = float(clearance)
        self.robot = robot
        self.config = config or RunnerConfig()
        self.limits = robot.planning_limits if limits is None else limits
        lo, hi = api.ARM_RATE_RANGE
        if not lo <= self.config.rate <= hi:
            raise InvalidInputError("rate", self.config.rate, f"a rate in [{lo:g}, {hi:g}] Hz")
        if self.config.command_velocity not in COMMAND_VELOCITIES:
            raise InvalidInputError("command_velocity", self.config.command_velocity, f"one of {COMMAND_VELOCITIES}")
        self.period = 1.0 / self.config.rate
        self.clock = clock
        self.sleep = sleep
        self.on_progress = on_progress
        self.indices = {side: robot.indices(api.ARM_JOINT_NAMES[side]) for side in api.SIDES}
        self._latest: dict[str, tuple[float, np.ndarray]] = {}
        self._stamps: dict[str, float] = {}
        self.rejected_states = 0
        self.last_rejection = ""
        self._rejection_logged = -np.inf
        self._state_period: dict[str, float] = {}
        self._commands = {s: interface.create_publisher(api.JOINT_STATE, api.Topics.joint_cmd(s)) for s in api.SIDES}
        self._enable = interface.create_publisher(api.FLOAT32, api.Topics.ENABLE)
        self.fsm_state: int | None = None
        self.outside_disable: str | None = None  # why another node's disable ended the run, once seen
        self._own_disables = 0  # our own -1s still to come back on /api/fsm/enable (a reader sees local writers)
        self._watch_fsm = False  # READY seen in this run: a PAUSE from now on was not caused by us
        interface.create_subscription(INT32, FSM_STATE_TOPIC, self._on_fsm)
        interface.create_subscription(api.FLOAT32, api.Topics.ENABLE, self._on_enable)
        for side in api.SIDES:
            interface.create_subscription(api.JOINT_STATE, api.Topics.joint_states(side), self._on_state(side))

    # ------------------------------------------------------------------------------------------------- inputs
    def _on_fsm(self, fields: dict[str, Any]) -> None:
        self.fsm_state = int(fields.get("data", -1))
        if self._watch_fsm and self.fsm_state == PAUSE and self.outside_disable is None:
            self.outside_disable = "disabled by another node: the robot's FSM went to PAUSE (0) while taplan drove it"

    def _on_enable(self, fields: dict[str, Any]) -> None:
        """``/api/fsm/enable`` from every writer: a disable (<= 0) that is not ours ends the run."""
        value = float(fields.get("data", np.nan))
        if not np.isfinite(value) or value > 0:
            return
        if self._own_disables > 0:
            self._own_disables -= 1
            return
        if self.outside_disable is None:
            self.outside_disable = f"disabled by another node (/api/fsm/enable {value:g})"

    def _send_disable(self) -> None:
        self._own_disables += 1
        self._enable.publish(api.fsm_enable(False).fields)

    def _on_state(self, side: str) -> Callable[[dict[str, Any]], None]:
        def callback(fields: dict[str, Any]) -> None:
            try:
                q = api.parse_joint_state(side, fields.get("name", []), fields.get("position", []))
            except (InvalidInputError, UnknownNameError) as exc:
                self._reject_state(side, str(exc))
                return
            stamp = fields.get("stamp")
            if stamp is not None and stamp > 0 and stamp < self._stamps.get(side, -np.inf):
                self._reject_state(side, "stamped before the previous one")
                return
            if stamp is not None:
                self._stamps[side] = stamp
            now = self.clock()
            previous = self._latest.get(side)
            if previous is not None and now > previous[0]:  # the robot's publishing period, smoothed
                gap = now - previous[0]
                old = self._state_period.get(side)
                self._state_period[side] = gap if old is None else 0.9 * old + 0.1 * min(gap, 4 * old)
            self._latest[side] = (now, q)

        return callback

    def _reject_state(self, side: str, why: str) -> None:
        """Count a rejected joint state; warn once a second at most (a stream of bad messages is one line)."""
        self.rejected_states += 1
        self.last_rejection = f"/{side}_arm/joint_states: {why}"
        now = self.clock()
        if now - self._rejection_logged >= 1.0:
            self._rejection_logged = now
            logger.warning("ignoring %s (%d rejected so far)", self.last_rejection, self.rejected_states)

    def stale_after(self) -> float:
        """How old the joint states may get [s]: ``stale_periods`` of the robot's measured publishing period
        (at least ``MIN_STALE``), at most ``state_timeout``."""
        if len(self._state_period) < len(api.SIDES):
            return self.config.state_timeout
        period = max(self._state_period.values())
        return min(self.config.state_timeout, max(MIN_STALE, self.config.stale_periods * period))

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
                if self.rejected_states:
                    raise RunError(
                        f"no joint states from {missing or 'both arms (stale)'} within {self.config.wait_timeout:g} "
                        f"s that taplan could use: {self.rejected_states} arrived and were rejected (last: "
                        f"{self.last_rejection})"
                    )
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
        self.interface.spin_once()  # type: ignore[attr-defined]
        self.outside_disable = None  # a new command from the user: an earlier disable is not this run's
        self._watch_fsm = False
        end = self.clock() + self.config.ready_timeout
        next_beat = next_command = self.clock()
        while True:
            now = self.clock()
            self.interface.spin_once()  # type: ignore[attr-defined]
            if self.outside_disable is not None:
                raise RunError(f"{self.outside_disable} while enabling: nothing was moved")
            if self.fsm_state == READY:
                self._watch_fsm = True
                return
            state = self.measured()
            if state is None or state[0] > self.config.state_timeout:
                raise RunError("joint states stopped while enabling the robot: nothing was moved")
            if now >= end:
                if self.fsm_state is None:
                    if self.config.require_fsm:
                        raise RunError(
                            f"the robot published no /fsm_state within {self.config.ready_timeout:g} s, so taplan "
                            "cannot confirm it follows: nothing was moved (--no-fsm drives it unconfirmed)"
                        )
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
        """Run ``trajectory`` (its joints by name; other joints hold their measured positions) at the arm rate.

        Nothing is sent before :meth:`check_plan` passes.

        Raises:
            CheckFailedError: The plan fails the pre-send check (nothing was sent).
            RunError: No joint states, or the plan does not start at the measured position.
        """
        start_q = self.wait_for_state()
        presend = self.presend = self.check_plan(trajectory, start_q)
        if not presend.passed:
            raise CheckFailedError(presend.failures[0], presend.table())
        index = self.robot.indices(trajectory.joint_names)
        times, commands = self._command_grid(trajectory, start_q)
        self._require_start_at(commands[0], start_q, "the plan", "plan from the robot's current state")
        self.arm(start_q)
        velocity = np.zeros_like(commands)
        acceleration = np.zeros_like(commands)
        velocity[:, index] = trajectory(times + trajectory.times[0], 1)
        acceleration[:, index] = trajectory(times + trajectory.times[0], 2)
        return self._drive(lambda k: (commands[k], velocity[k], acceleration[k]) if k < len(times) else None)

    def _require_start_at(self, first: np.ndarray, measured: np.ndarray, what: str, remedy: str) -> None:
        """RunError unless ``first`` (nq,) [rad] is within ``start_tolerance`` of the ``measured`` positions."""
        offset = np.abs(first - measured)
        if offset.max() > self.config.start_tolerance:
            j = int(np.argmax(offset))
            raise RunError(
                f"{what} starts {offset[j]:.4f} rad from the measured {self.robot.joint_names[j]} "
                f"(tolerance {self.config.start_tolerance:g} rad): {remedy}"
            )

    def _command_grid(self, trajectory: Trajectory, hold: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The command times [s] from the start and the commands (k, nq) the runner sends for ``trajectory``."""
        names = trajectory.joint_names
        unknown = [n for n in names if n not in self.robot.joint_names]
        if unknown:
            raise UnknownNameError("trajectory joint", unknown[0], self.robot.joint_names)
        times = np.arange(0.0, trajectory.duration + 1e-12, self.period)
        if times[-1] < trajectory.duration:
            times = np.append(times, trajectory.duration)
        commands = np.repeat(np.asarray(hold, dtype=float)[None, :], len(times), axis=0)
        commands[:, self.robot.indices(names)] = trajectory(times + trajectory.times[0])
        return times, commands

    def check_plan(self, trajectory: Trajectory, hold: np.ndarray | None = None) -> PreSendCheck:
        """Everything ``taplan check`` applies, before anything is sent.

        * the plan itself against the hardware limits (:func:`taplan.check.check`: velocity, acceleration, jerk,
          velocity steps, positions), as ``taplan check FILE`` does;
        * the commands at the arm rate (what the robot's position loop receives): their finite-difference
          velocity, acceleration, jerk and velocity steps against the hardware limits at the command period, and
          the positions;
        * the clearance of the robot's own bodies (and the scene of ``world``), certified along the whole plan.

        Args:
            trajectory: The plan (joints by name).
            hold: Positions [rad] (nq,) of the joints the plan does not drive (default the robot's home).
        """
        hold = self.robot.home if hold is None else np.asarray(hold, dtype=float)
        names = trajectory.joint_names
        plan_report = check(trajectory, self.robot.limits.subset(names), name="plan", clearance=None)
        times, commands = self._command_grid(trajectory, hold)
        if len(times) < 2:  # a plan shorter than one period: the command stream holds its only point
            times, commands = np.append(times, self.period), np.vstack([commands, commands])
        samples = JointStateSamples(
            times, commands, np.full_like(commands, np.nan), self.config.rate, None, self.robot.joint_names
        )
        # the commands' limits and steps; their timing (a shorter last period to end on the plan's end) is not theirs
        # to judge: the runner's own timing is measured while it runs
        untimed = Thresholds(jitter_tolerance=math.inf, gap_factor=math.inf)
        stream_report: Report = check(
            samples, self.robot.limits, thresholds=untimed, name=f"commands at {self.config.rate:g} Hz", clearance=None
        )
        clearance = check_clearance(trajectory, self.world, hold=hold, floor=self.clearance)
        return PreSendCheck(plan_report, stream_report, clearance)

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
        joint_targets = isinstance(streamer, JointStreamer)
        last = [np.asarray(initial.position, dtype=float)]  # the last command (the start of a new target's path)

        def command(k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
            if k >= steps:
                return None
            target = targets(k * self.period)
            if target is not None:
                try:
                    if joint_targets:
                        self._check_target(target, last[0])
                    streamer.set_target(target)
                except TaplanError as exc:
                    logger.warning("skipping a target: %s", exc)
            state = streamer.step()
            self._guard(state.position)
            last[0] = np.asarray(state.position, dtype=float)
            return state.position, state.velocity, state.acceleration

        return self._drive(command, f"streamed for {duration:g} s")

    def follow(
        self,
        replanner: Any,
        duration: float,
        *,
        updates: Callable[[float], None] | None = None,
    ) -> RunResult:
        """Execute a :class:`~taplan.planning.Replanner`'s trajectory while it re-plans, at the arm rate.

        Re-planning in the loop: the replanner's clock is this run's, in seconds from the first command (build it
        with ``t=0.0`` at the measured position, :meth:`wait_for_state`, and a goal). A planning thread calls
        ``updates(t)`` (the caller's scene and goal changes: they happen in the thread that plans, never under a
        running planner) and then ``replanner.update(t)``, once per period; the command loop reads
        ``replanner.state(t)`` for each command and keeps its rate while a plan is computed. Give the replanner a
        ``latency`` of at least its ``max_time`` + 0.2 s (the planner's budget tolerance): the hand-over then
        happens after the plan is ready; a plan that is late is not used (the replanner brakes and plans again).
        The run ends when the trajectory has ended with nothing left to plan, after ``duration`` [s], or as every
        run ends (a stall, Ctrl-C, an error in the planning thread: braked to rest).

        Raises:
            RunError: No joint states, or the replanner's trajectory does not start at the measured position.
        """
        import threading

        if not (isinstance(duration, (int, float)) and np.isfinite(duration) and duration > 0):
            raise InvalidInputError("duration", duration, "a positive time [s]")
        start_q = self.wait_for_state()
        first = np.asarray(replanner.state(0.0)[0], dtype=float)
        self._require_start_at(first, start_q, "the replanner", "build it at the robot's current state")
        self.arm(start_q)
        stop = threading.Event()
        begin: list[float] = []  # the clock at the first command: the replanner's time 0
        busy = threading.Event()  # the planning thread is between updates(t) and the end of replanner.update(t)
        failures: list[BaseException] = []
        finished: list[bool] = []  # non-empty once a command after the trajectory's end was sent

        def planning() -> None:
            while not stop.is_set():
                busy.set()
                try:
                    t = self.clock() - begin[0]
                    if updates is not None:
                        updates(t)
                    replanner.update(t)
                except Exception as exc:  # noqa: BLE001 (reported by the command loop, which brakes)
                    failures.append(exc)
                    return
                finally:
                    busy.clear()
                stop.wait(self.period)

        worker = threading.Thread(target=planning, name="taplan-replanner", daemon=True)

        def command(k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
            t = k * self.period
            if not begin:
                begin.append(self.clock())
                worker.start()
            if failures:
                raise RunError(f"re-planning failed: {failures[0]}")
            ended = t > replanner.end_time and not replanner.pending and not busy.is_set()
            if t > duration or (ended and finished):
                return None
            if ended:
                finished.append(True)  # one command after the end: the final position itself, at rest
            q, v, a = replanner.state(t)
            return np.asarray(q, dtype=float), np.asarray(v, dtype=float), np.asarray(a, dtype=float)

        try:
            return self._drive(command, "followed the replanner to the end")
        finally:
            stop.set()
            if worker.is_alive():
                worker.join(timeout=replanner.max_time + 5.0)

    def _check_target(self, target: Any, current: np.ndarray) -> None:
        """A joint target in collision, or whose straight joint-space path from the current command is not certified
        clear (:func:`~taplan.planning.check_segment`), is refused: the streamer keeps its previous target."""
        q = np.asarray(target, dtype=float)
        if q.shape != (self.robot.nq,) or not np.all(np.isfinite(q)):
            return  # the streamer names the shape or NaN
        q = np.clip(q, self.limits.lower, self.limits.upper)  # where the streamer's clamp puts it
        d, pair = self.world.min_distance(q)
        if d <= self.clearance:
            raise CollisionError("target", pair, -d, self.clearance)
        segment = check_segment(self.world, np.asarray(current, dtype=float), q, 2 * self.clearance)
        if not segment.valid:
            raise CollisionError("the path to the target", segment.pair, -segment.clearance, self.clearance)

    def _guard(self, position: np.ndarray) -> None:
        """Stop the stream before a command closer than ``STREAM_MARGIN`` to a collision is sent.

        The last line of defence behind :meth:`_check_target` (a pose streamer's IK, or a joint stream that
        curves off the straight path): the brake then starts from the last command sent, which was at least
        ``STREAM_MARGIN`` clear; the brake itself (a few periods at the streamer's limits) is not certified.
        """
        d, pair = self.world.min_distance(position)
        if d <= self.clearance + STREAM_MARGIN:
            raise _StopRequestError(
                "stopped",
                f"the next streamed command puts {pair[0]} {d * 1e3:.1f} mm from {pair[1]} (required "
                f"{(self.clearance + STREAM_MARGIN) * 1e3:.0f} mm): stopping before a collision",
            )

    def _check_commands(self, commands: np.ndarray) -> None:
        lower, upper = self.robot.limits.lower, self.robot.limits.upper
        over = np.maximum(commands - upper, lower - commands)
        if np.any(over > 1e-9):
            k, j = np.unravel_index(int(np.argmax(over)), over.shape)
            raise RunError(
                f"command {k} puts {self.robot.joint_names[j]} at {commands[k, j]:.6g} rad, outside the hardware "
                f"limits [{lower[j]:.6g}, {upper[j]:.6g}]: nothing was sent"
            )

    def _publish(self, q: np.ndarray, now: float, log: _Log, velocity: np.ndarray | None = None) -> None:
        self._check_commands(q[None, :])
        mode = self.config.command_velocity
        measured = self.measured() if mode == "feedback" else None
        for side in api.SIDES:
            index = self.indices[side]
            if mode == "feedforward" and velocity is not None:
                message = api.joint_cmd(side, q[index], convention="feedforward", velocity=velocity[index])
            elif mode == "feedback" and measured is not None:
                message = api.joint_cmd(side, q[index], convention="velocity_feedback", measured=measured[1][index])
            else:  # "zero", a hold (no plan velocity) or no measurement yet
                message = api.joint_cmd(side, q[index])
            self._commands[side].publish(message.fields)
        log.sent_times.append(now)
        log.sent.append(q.copy())

    def _drive(
        self, command: Callable[[int], tuple[np.ndarray, np.ndarray, np.ndarray] | None], done: str = "plan finished"
    ) -> RunResult:
        cfg = self.config
        log = _Log()
        t0 = self.clock()
        next_beat = t0
        beats = 0
        worst = 0.0
        state = (np.zeros(0),) * 3
        k = 0
        settle_until: float | None = None
        last_progress = t0
        status, reason = "completed", done
        last_stamp: float | None = None  # receive time of the last joint state logged
        try:
            while True:
                now = self.clock()
                self.interface.spin_once()  # type: ignore[attr-defined]
                if self.outside_disable is not None:
                    raise _StopRequestError("disabled", self.outside_disable)
                for monitor in self.monitors:
                    why = monitor()
                    if why:
                        raise _StopRequestError("stopped", f"{why}: stopping")
                measured = self.measured()
                if measured is not None:
                    age, q_meas = measured
                    fresh = self._latest_time() != last_stamp
                    if fresh:
                        last_stamp = self._latest_time()
                        log.measured_times.append(last_stamp - t0)
                        log.measured.append(q_meas)
                    stale = self.stale_after()
                    if age > stale:
                        raise _StopRequestError("stopped", self._stall_reason(age))
                    if log.sent:
                        # the measurement against the command sent one period before it arrived, not before now:
                        # late states of a stalled robot show their age, not a tracking error they did not have
                        arrived = now - age - t0
                        k_cmd = bisect.bisect_right(log.sent_times, arrived - self.period) - 1
                        error = float(np.max(np.abs(q_meas - log.sent[k_cmd]))) if k_cmd >= 0 else 0.0
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
                            reason = f"{done}; not within {cfg.goal_tolerance:g} rad after {cfg.settle_time:g} s"
                            break
                        self._publish(state[0], now - t0, log, np.zeros_like(state[0]))
                    else:
                        state = nxt
                        self._publish(state[0], now - t0, log, state[1])
                    k += 1
                if self.on_progress is not None and now - last_progress >= 1.0:
                    last_progress = now
                    self.on_progress(now - t0, None)
                self.sleep(min(0.001, max(0.0, t0 + k * self.period - self.clock())))
        except _StopRequestError as stop:
            status, reason = stop.status, stop.reason
            logger.warning(reason)
            if status != "disabled":  # disabled from outside: not one more command or heartbeat
                beats += self._brake(state, log, t0)
        except KeyboardInterrupt as exc:  # Ctrl-C, or a signal the CLI turned into one (its name in args)
            status, reason = "stopped", f"interrupted ({exc.args[0] if exc.args else 'Ctrl-C'}): stopping"
            logger.warning(reason)
            beats += self._brake(state, log, t0)
        except Exception as exc:  # any failure while moving ends in a smooth stop, then propagates as a result
            status, reason = "stopped", f"{type(exc).__name__}: {exc}: stopping"
            logger.error(reason)
            beats += self._brake(state, log, t0)
        if self.outside_disable is not None and status != "disabled":
            status, reason = "disabled", f"{self.outside_disable} (while stopping: {reason})"
        if cfg.disable:
            self._send_disable()
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

    def _stall_reason(self, age: float) -> str:
        period = max(self._state_period.values(), default=float("nan"))
        reason = f"no joint states for {age:.2f} s (they stopped; the robot published every {period * 1e3:.0f} ms)"
        if self.rejected_states:
            reason += f"; {self.rejected_states} were rejected (last: {self.last_rejection})"
        return reason + ": stopping"

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
            self.interface.spin_once()  # type: ignore[attr-defined]
            if self.outside_disable is not None:  # another node disabled the robot: stop commanding at once
                logger.warning(self.outside_disable)
                break
            step = streamer.step()
            try:
                self._publish(step.position, tick - t0, log, np.asarray(step.velocity, dtype=float))
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
