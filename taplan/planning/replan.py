"""Re-planning in the control loop: keep a certified plan, re-plan from the commanded state when the scene or the
goal changes, hand over without an acceleration step.

A :class:`Replanner` holds one timed trajectory on the caller's clock (seconds, e.g. ``time.monotonic()`` or a
simulator's time). The control loop calls :meth:`Replanner.update` with the current time and reads the setpoint with
:meth:`Replanner.state`. ``update``:

* when the scene changed (``scene.version``), certifies the rest of the trajectory in the new scene (conservative
  advancement, :func:`~taplan.planning.verify.verify_trajectory`, at a quarter of the margin like every plan): a
  trajectory that is still clear is kept;
* when it is not, or the goal changed, hands over at ``t_switch = t + latency`` (at ``t`` when the old trajectory is
  not clear until then): from the commanded state there, ruckig's time-optimal jerk-limited stop
  (:func:`~taplan.timing.straight.state_to_state` onto its natural stopping point, so position, velocity and
  acceleration stay continuous), then :func:`~taplan.planning.plan_motion` from the stop to the goal. The stop is
  certified too; when no plan is found the robot stays stopped and the next ``update`` tries again.

The returned trajectory is therefore always: the old trajectory up to ``t_switch``, the certified stop, the
certified plan — continuous to the acceleration, within the planning limits. ``update`` blocks for the planning
time (bounded by ``max_time`` + 0.2 s): a loop that cannot wait that long calls ``update`` from another thread
(:meth:`taplan.ros.Runner.follow` does) with ``latency`` >= that time, so that the hand-over happens after the plan
is ready. :meth:`state` and the hand-over are thread-safe: a new trajectory is installed only if no state after its
hand-over time has been read yet (else the update is ``"late"`` and the next one tries again from a later time), so
the states a control loop reads never jump.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import ruckig

from taplan.errors import InvalidInputError, TaplanError
from taplan.limits import JointLimits
from taplan.planning.motion import DEFAULT_MARGIN, MotionPlan, plan_motion
from taplan.planning.verify import verify_trajectory
from taplan.robot import Robot
from taplan.scene.scene import Scene
from taplan.scene.world import CollisionWorld
from taplan.timing._polynomial import concatenated, sliced
from taplan.timing.straight import state_to_state
from taplan.trajectory import Trajectory

__all__ = ["Replanner", "ReplanEvent"]

REST = 1e-9  # [rad/s, rad/s²] a state this still needs no stop


@dataclass(frozen=True)
class ReplanEvent:
    """What one :meth:`Replanner.update` did.

    Attributes:
        time: The update's time [s] (caller's clock).
        action: ``"kept"`` (the scene changed, the rest of the plan is still certified), ``"replanned"`` (a new
            plan from the stop at ``switch``), ``"stopped"`` (no plan: the robot stops and holds), ``"late"`` (the
            plan was ready after its hand-over time had been read by :meth:`Replanner.state`: not installed, the
            next update re-plans).
        reason: Why (the scene changed and the plan came within the floor, the goal changed, the planner's error).
        switch: When the new motion takes over [s] (``"replanned"`` / ``"stopped"``), else the update's time.
        seconds: Wall time of the update [s].
        plan: The new plan (``"replanned"``), else None.
    """

    time: float
    action: str
    reason: str
    switch: float
    seconds: float
    plan: MotionPlan | None = None


class Replanner:
    """A plan that follows the scene and the goal.

    Args:
        robot: The robot.
        scene: The scene it watches (its ``version`` tells changes).
        q: The robot's configuration now [rad] (nq,), at rest.
        t: The time now on the caller's clock [s].
        limits: Joint limits of every motion (default ``robot.planning_limits``).
        margin: Path clearance [m] (:func:`~taplan.planning.plan_motion`; the trajectory is certified at a quarter).
        max_time: Budget of each plan [s].
        latency: Time [s] the old trajectory keeps running after an update before the hand-over (0: at once).
        seed: Seed of the planner's random choices.
    """

    def __init__(
        self,
        robot: Robot,
        scene: Scene,
        q: npt.ArrayLike,
        t: float = 0.0,
        *,
        limits: JointLimits | None = None,
        margin: float = DEFAULT_MARGIN,
        max_time: float = 1.0,
        latency: float = 0.0,
        seed: int = 0,
    ) -> None:
        if not (isinstance(latency, (int, float)) and math.isfinite(latency) and latency >= 0):
            raise InvalidInputError("latency", latency, "a time >= 0 [s]")
        if not (isinstance(t, (int, float)) and math.isfinite(t)):
            raise InvalidInputError("t", t, "a finite time [s]")
        self.robot = robot
        self.scene = scene
        self.world = CollisionWorld(robot, scene)
        self.limits = robot.planning_limits if limits is None else limits
        self.margin = float(margin)
        self.max_time = float(max_time)
        self.latency = float(latency)
        self.seed = int(seed)
        q0 = robot.check_configuration(q, "q")
        self.t0 = float(t)  # the trajectory's time 0 on the caller's clock
        self.trajectory = _hold(q0, robot.joint_names)
        self.goal: Any = None
        self.events: list[ReplanEvent] = []
        self._version = scene.version
        self._pending = ""  # why the next update must plan
        self._lock = threading.Lock()  # state() against a hand-over installed from another thread
        self._served = -math.inf  # the latest time state() answered for [s]: a hand-over before it is too late

    # ------------------------------------------------------------------------------------------------ queries
    def state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The commanded position [rad], velocity [rad/s] and acceleration [rad/s²] at time ``t`` (nq each); after
        the end, the final position at rest."""
        with self._lock:
            self._served = max(self._served, float(t))
            t0, trajectory = self.t0, self.trajectory
        local = float(np.clip(t - t0, 0.0, trajectory.duration))
        if t - t0 > trajectory.duration:
            end = trajectory(trajectory.duration)
            return end, np.zeros_like(end), np.zeros_like(end)
        return tuple(np.asarray(trajectory(local, k), dtype=float) for k in range(3))  # type: ignore[return-value]

    @property
    def pending(self) -> bool:
        """True when the next :meth:`update` will plan (a new goal, or a retry after a failed or late plan)."""
        return bool(self._pending)

    @property
    def end_time(self) -> float:
        """When the current trajectory ends [s] (caller's clock)."""
        return self.t0 + self.trajectory.duration

    # ------------------------------------------------------------------------------------------------ changes
    def set_goal(self, goal: npt.ArrayLike | Mapping[str, Any]) -> None:
        """A new goal (configuration or pose targets, as :func:`~taplan.planning.plan_motion`): the next
        :meth:`update` plans to it."""
        self.goal = goal
        self._pending = "the goal changed"

    def update(self, t: float) -> ReplanEvent | None:
        """Check the plan at time ``t`` [s]; re-plan when the goal changed or the scene changed so that the rest of
        the plan is no longer certified. None when nothing changed."""
        begin = time.perf_counter()
        reason = self._pending
        if not reason and self.scene.version != self._version:
            self._version = self.scene.version
            if t < self.end_time:
                rest = sliced(self.trajectory, max(t - self.t0, 0.0), self.trajectory.duration)
                check = verify_trajectory(self.world, rest, floor=self.margin / 4)
                if check.collision_free:
                    return self._record(ReplanEvent(t, "kept", "the scene changed", t, time.perf_counter() - begin))
                reason = (
                    f"the scene changed: the plan comes within {check.min_clearance * 1e3:.1f} mm "
                    f"({check.pair[0]} / {check.pair[1]})"
                )
        if not reason:
            return None
        self._version = self.scene.version
        self._pending = ""
        return self._record(self._replan(t, reason, begin))

    # ------------------------------------------------------------------------------------------------ internals
    def _record(self, event: ReplanEvent) -> ReplanEvent:
        self.events.append(event)
        return event

    def _replan(self, t: float, reason: str, begin: float) -> ReplanEvent:
        local = max(t - self.t0, 0.0)
        switch = min(local + self.latency, self.trajectory.duration)
        head = sliced(self.trajectory, local, switch) if switch > local + 1e-9 else None
        if head is not None:  # the old trajectory runs until the hand-over only if it and the stop are clear
            stop = self._stop(self.trajectory, switch)
            ahead = concatenated([p for p in (head, stop) if p is not None])
            if not verify_trajectory(self.world, ahead, floor=self.margin / 4).collision_free:
                head = None
        if head is None:  # brake at once, while the plan is computed
            switch_time, stop = self._brake_now(t)
            q_stop = np.asarray((stop or self.trajectory)(stop.duration if stop else 0.0), dtype=float)
        else:
            switch_time = t + (switch - local)
            q_stop = np.asarray((stop or self.trajectory)(stop.duration if stop else switch), dtype=float)
        if stop is not None and not verify_trajectory(self.world, stop, floor=0.0).collision_free:
            reason += "; the stop itself is not certified collision-free (the obstacle came too fast)"
        if self.goal is None:
            if head is not None and not self._install(t, [head, *([stop] if stop else [])], switch_time):
                return self._late(t, reason, switch_time, begin)
            return ReplanEvent(t, "stopped", f"{reason}; no goal", switch_time, time.perf_counter() - begin)
        try:
            plan = plan_motion(
                self.robot,
                q_stop,
                self.goal,
                world=self.world,
                limits=self.limits,
                margin=self.margin,
                max_time=self.max_time,
                seed=self.seed + len(self.events),
            )
        except TaplanError as exc:
            if head is not None and not self._install(t, [head, *([stop] if stop else [])], switch_time):
                return self._late(t, reason, switch_time, begin)
            self._pending = f"{reason}; retrying after: {exc}"
            return ReplanEvent(t, "stopped", f"{reason}; {exc}", switch_time, time.perf_counter() - begin)
        if head is None:
            self._after_stop(switch_time, stop, plan.trajectory)
        elif not self._install(t, [head, *([stop] if stop else []), plan.trajectory], switch_time):
            return self._late(t, reason, switch_time, begin)
        return ReplanEvent(t, "replanned", reason, switch_time, time.perf_counter() - begin, plan)

    def _late(self, t: float, reason: str, when: float, begin: float) -> ReplanEvent:
        """The hand-over at ``when`` was already read from the old trajectory: nothing of the plan is installed, the
        robot brakes from the latest state read (the old trajectory was not certified beyond the hand-over), the
        next update plans from there."""
        self._brake_now(t)
        self._pending = reason
        seconds = time.perf_counter() - begin
        why = f"{reason}; the plan took {seconds:.3f} s, past its hand-over at {when:.3f} s: braking, re-planning"
        return ReplanEvent(t, "late", why, when, seconds)

    def _stop(self, trajectory: Trajectory, at: float) -> Trajectory | None:
        """ruckig's time-optimal stop from ``trajectory``'s state at ``at`` (its time), or None at rest."""
        q, v, a = (np.asarray(trajectory(at, k), dtype=float) for k in range(3))
        if np.abs(v).max() < REST and np.abs(a).max() < REST:
            return None
        target = _stopping_point(q, v, a, self.limits)
        return state_to_state((q, v, a), (target, np.zeros_like(q), np.zeros_like(q)), self.limits)

    def _brake_now(self, t: float) -> tuple[float, Trajectory | None]:
        """Install ruckig's stop from the commanded state at ``t`` or at the latest time :meth:`state` answered for,
        whichever is later (no state already read changes); (when it starts on the caller's clock, the stop or
        None at rest, then a hold is installed)."""
        with self._lock:
            start = max(t, self._served)
            local = float(np.clip(start - self.t0, 0.0, self.trajectory.duration))
            stop = self._stop(self.trajectory, local)
            q = np.asarray(self.trajectory(local), dtype=float)
            self.t0, self.trajectory = start, stop if stop is not None else _hold(q, self.robot.joint_names)
        return start, stop

    def _after_stop(self, start: float, stop: Trajectory | None, plan: Trajectory) -> None:
        """Install ``plan`` after the ``stop`` installed at ``start``: right after it when the stop is still running
        (or ended no later than the latest state read), else from the latest state read (the robot rests at the
        plan's start until then)."""
        with self._lock:
            stop_end = start + (stop.duration if stop is not None else 0.0)
            if stop is not None and self._served <= stop_end + 1e-9:
                self.t0, self.trajectory = start, concatenated([stop, plan])
            else:
                self.t0, self.trajectory = max(self._served, stop_end), plan

    def _install(self, t: float, pieces: list[Trajectory], when: float) -> bool:
        """Make ``pieces`` (from time ``t``) the trajectory, unless a state after the hand-over ``when`` was read."""
        trajectory = concatenated(pieces)
        with self._lock:
            if self._served > when + 1e-9:
                return False
            self.t0, self.trajectory = t, trajectory
        return True


def _hold(q: np.ndarray, names: tuple[str, ...]) -> Trajectory:
    """A trajectory that holds ``q`` (a zero-length motion is not a trajectory: a 1 ms hold)."""
    c = np.zeros((1, 4, len(q)))
    c[0, 0] = q
    return Trajectory.from_polynomials(np.array([0.0, 1e-3]), c, names)


def _stopping_point(q: np.ndarray, v: np.ndarray, a: np.ndarray, limits: JointLimits) -> np.ndarray:
    """Where ruckig's time-optimal velocity-interface stop (zero velocity and acceleration) ends."""
    n = len(q)
    generator = ruckig.Ruckig(n)
    request = ruckig.InputParameter(n)
    request.control_interface = ruckig.ControlInterface.Velocity
    request.current_position, request.current_velocity, request.current_acceleration = (
        q.tolist(),
        v.tolist(),
        a.tolist(),
    )
    request.target_velocity, request.target_acceleration = [0.0] * n, [0.0] * n
    request.max_velocity = limits.velocity.tolist()
    request.max_acceleration = limits.acceleration.tolist()
    request.max_jerk = limits.jerk.tolist()
    motion = ruckig.Trajectory(n)
    generator.calculate(request, motion)
    return np.asarray(motion.at_time(motion.duration)[0], dtype=float)
