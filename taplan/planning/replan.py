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
time (bounded by ``max_time`` + 0.2 s): a loop that cannot wait that long passes ``latency`` >= that time, so that
the hand-over happens after the plan is ready.
"""

from __future__ import annotations

import math
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
            plan from the stop at ``switch``), ``"stopped"`` (no plan: the robot stops and holds).
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

    # ------------------------------------------------------------------------------------------------ queries
    def state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The commanded position [rad], velocity [rad/s] and acceleration [rad/s²] at time ``t`` (nq each); after
        the end, the final position at rest."""
        local = float(np.clip(t - self.t0, 0.0, self.trajectory.duration))
        if t - self.t0 > self.trajectory.duration:
            end = self.trajectory(self.trajectory.duration)
            return end, np.zeros_like(end), np.zeros_like(end)
        return tuple(np.asarray(self.trajectory(local, k), dtype=float) for k in range(3))  # type: ignore[return-value]

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
        stop = self._stop(switch)
        if head is not None:  # the old trajectory runs until the hand-over only if it and the stop are clear
            ahead = concatenated([p for p in (head, stop) if p is not None])
            if not verify_trajectory(self.world, ahead, floor=self.margin / 4).collision_free:
                switch, head = local, None
                stop = self._stop(switch)
        if stop is not None and not verify_trajectory(self.world, stop, floor=0.0).collision_free:
            reason += "; the stop itself is not certified collision-free (the obstacle came too fast)"
        q_stop = np.asarray((stop or self.trajectory)(stop.duration if stop else switch), dtype=float)
        pieces = [p for p in (head, stop) if p is not None]
        when = t + (switch - local)
        if self.goal is None:
            self._install(t, pieces, q_stop)
            return ReplanEvent(t, "stopped", f"{reason}; no goal", when, time.perf_counter() - begin)
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
            self._install(t, pieces, q_stop)
            self._pending = f"{reason}; retrying after: {exc}"
            return ReplanEvent(t, "stopped", f"{reason}; {exc}", when, time.perf_counter() - begin)
        self._install(t, [*pieces, plan.trajectory], q_stop)
        return ReplanEvent(t, "replanned", reason, when, time.perf_counter() - begin, plan)

    def _stop(self, at: float) -> Trajectory | None:
        """ruckig's time-optimal stop from the commanded state at ``at`` (trajectory time), or None at rest."""
        q, v, a = (np.asarray(self.trajectory(at, k), dtype=float) for k in range(3))
        if np.abs(v).max() < REST and np.abs(a).max() < REST:
            return None
        target = _stopping_point(q, v, a, self.limits)
        return state_to_state((q, v, a), (target, np.zeros_like(q), np.zeros_like(q)), self.limits)

    def _install(self, t: float, pieces: list[Trajectory], q_end: np.ndarray) -> None:
        self.t0 = t
        self.trajectory = concatenated(pieces) if pieces else _hold(q_end, self.robot.joint_names)


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
