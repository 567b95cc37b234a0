"""Pose streaming: end-effector targets for one or both arms -> differential IK -> the joint streamer.

Each period, :class:`~taplan.ik.DifferentialIK` takes one QP step from its own integrated configuration toward the
latest pose targets (velocity, acceleration, position and arm-arm collision limits hold there), and the result,
position and velocity, becomes the :class:`~taplan.stream.JointStreamer`'s target, which adds the jerk limit and the
position-bound guarantee. An unreachable pose is approached as close as the limits allow: the IK's least-squares
step stalls at the closest configuration and :attr:`PoseStreamState.unreachable` names the frames concerned.

Safety mirrors the joint streamer: with no new pose target for ``timeout`` [s] the arm brakes to rest; a malformed
target raises :class:`~taplan.StreamError` and changes nothing.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from taplan._validation import as_positive
from taplan.errors import InvalidInputError, StreamError, UnknownNameError
from taplan.ik import DifferentialIK
from taplan.ik._targets import as_transform
from taplan.limits import JointLimits
from taplan.robot import Robot
from taplan.stream.joint_streamer import JointStreamer
from taplan.stream.safety import Watchdog
from taplan.stream.state import StreamState, StreamStatus

__all__ = ["PoseStreamer", "PoseStreamState"]


class PoseStreamState(NamedTuple):
    """One command of a :class:`PoseStreamer`: the joint command plus how far the poses are.

    Attributes:
        time, position, velocity, acceleration, jerk, status, new_calculation, target_adjusted, fault: As in
            :class:`~taplan.stream.StreamState` (joint command, shape (nq,)).
        position_error: Per task frame, distance of the IK reference from its target [m].
        orientation_error: Per task frame, angle to its target [rad].
        pose_reached: Every frame within the tolerance.
        unreachable: Frames whose target is out of reach: the IK has stalled short of the tolerance (the arm holds
            the closest pose the limits allow).
    """

    time: float
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray
    status: StreamStatus
    new_calculation: bool
    target_adjusted: bool
    fault: str | None
    position_error: dict[str, float]
    orientation_error: dict[str, float]
    pose_reached: bool
    unreachable: tuple[str, ...]

    @property
    def reached(self) -> bool:
        """True when the poses are reached and the joints at rest."""
        return self.pose_reached and self.status in (StreamStatus.REACHED, StreamStatus.IDLE)


class PoseStreamer:
    """Streams end-effector pose targets (``{frame: T_root_frame}``) as joint commands at period ``dt``.

    Args:
        robot: The robot (poses are ``T_root_frame`` in its root frame, e.g. ``shoulder_base``).
        dt: Control period [s] (also the IK's step).
        frames: Task frames, e.g. ``("left_ee", "right_ee")`` or ``("left_ee",)``.
        limits: Joint limits over all the robot's joints; default ``robot.planning_limits``.
        timeout: Longest time without a pose target [s] before braking to rest; None disables it.
        tolerance: ``(position [m], orientation [rad])`` within which a pose counts as reached.
        stall_time: A pose outside the tolerance whose error has not dropped by 10 % of the tolerance over this
            long [s] is reported unreachable (the IK makes no more progress toward it).
        ik: A ready :class:`~taplan.ik.DifferentialIK` (same ``dt``, frames and limits) instead of building one.
        **ik_options: Passed to :class:`~taplan.ik.DifferentialIK` (``solver``, ``collision``, ``posture_cost``...).
    """

    def __init__(
        self,
        robot: Robot,
        dt: float,
        *,
        frames: Sequence[str] = ("left_ee", "right_ee"),
        limits: JointLimits | None = None,
        timeout: float | None = 1.0,
        tolerance: tuple[float, float] = (1e-3, 1e-2),
        stall_time: float = 0.25,
        ik: DifferentialIK | None = None,
        initial: npt.ArrayLike | None = None,
        **ik_options: Any,
    ) -> None:
        self.robot = robot
        self.dt = as_positive(dt, "dt")
        limits = robot.planning_limits if limits is None else limits
        if ik is None:
            ik = DifferentialIK(robot, dt=self.dt, limits=limits, frames=tuple(frames), **ik_options)
        elif abs(ik.dt - self.dt) > 1e-12:
            raise InvalidInputError("ik.dt", ik.dt, f"the streamer's dt {self.dt}")
        self.ik = ik
        self.frames = ik.frames
        self.tolerance = (as_positive(tolerance[0], "tolerance[0]"), as_positive(tolerance[1], "tolerance[1]"))
        self._window = max(2, round(as_positive(stall_time, "stall_time") / self.dt))
        self._scores: dict[str, deque[float]] = {f: deque(maxlen=self._window) for f in self.frames}
        self._targets: dict[str, np.ndarray] = {}
        self.joints = JointStreamer(limits, self.dt, timeout=None, on_out_of_bounds="clamp")
        self._watchdog = Watchdog(None if timeout is None else as_positive(timeout, "timeout"))
        self._active = False
        self._last_reference: np.ndarray | None = None
        self._ik_speed = 0.0
        if initial is not None:
            self.reset(initial)

    @property
    def names(self) -> tuple[str, ...]:
        """Joint names of the commands (all the robot's joints)."""
        return self.joints.names

    @property
    def limits(self) -> JointLimits:
        return self.joints.limits

    def reset(self, position: npt.ArrayLike, velocity: npt.ArrayLike | None = None) -> StreamState:
        """Start from a measured configuration [rad] (nq,) (and velocity [rad]/[s]); poses hold where they are."""
        state = self.joints.reset(position, velocity)
        self.ik.reset(state.position, state.velocity)
        self._watchdog.clear()
        self._active = False
        self._last_reference = None
        self._ik_speed = 0.0
        for scores in self._scores.values():
            scores.clear()
        self._targets.clear()
        return state

    def set_target(self, targets: Mapping[str, Any]) -> None:
        """New pose targets ``{frame: pose}`` (a subset of ``frames`` keeps the others' last targets).

        Poses: 4x4 ``T_root_frame``, ``(position [m] (3,), quaternion xyzw (4,))`` or ``(7,)``.

        Raises:
            StreamError: Unknown frame, wrong shape, NaN/inf or a non-rotation; nothing changes.
        """
        if not isinstance(targets, Mapping) or not targets:
            raise StreamError(f"pose targets: expected a non-empty mapping {{frame: pose}}, received {targets!r:.80}")
        checked = {}
        for frame, pose in targets.items():
            if frame not in self.ik.tasks:
                raise StreamError(f"{UnknownNameError('task frame', frame, self.frames)}; the target was rejected")
            try:
                checked[frame] = as_transform(pose, f"targets[{frame!r}]")
            except InvalidInputError as exc:
                raise StreamError(f"{exc}; the target was rejected and the stream keeps its last good motion") from None
        self.joints.state  # noqa: B018 (raises before reset)
        for frame, T in checked.items():  # a target that moved restarts its progress window
            previous = self._targets.get(frame)
            if previous is None or np.abs(T - previous).max() > 0.1 * self.tolerance[0]:
                self._scores[frame].clear()
            self._targets[frame] = T
        if not self._active:  # resume from where the joint stream is, with its velocity (acceleration limit state)
            state = self.joints.state
            self.ik.reset(state.position, state.velocity)
        self.ik.set_targets(checked)
        self._active = True
        self._watchdog.feed(self.joints.time)

    def stop(self) -> None:
        """Brake smoothly to rest; the next pose target resumes."""
        self._active = False
        self.joints.stop()

    def step(self) -> PoseStreamState:
        """Advance one period: one IK step (while targets are live), then one joint-streamer step."""
        joints = self.joints
        if self._active and self._watchdog.expired(joints.time):
            self.stop()
        if self._active:
            out = self.ik.step()
            reference = out.q
            self._ik_speed = float(np.max(np.abs(out.velocity)))
            last = self._last_reference
            if last is None or self._ik_speed > 0.0 or not np.array_equal(reference, last):
                joints.set_target(reference, out.velocity)
                self._last_reference = reference
        state = joints.step()
        position_error: dict[str, float] = {}
        orientation_error: dict[str, float] = {}
        unreachable: list[str] = []
        kin = self.ik.kin  # at the IK step's start configuration
        tol_p, tol_r = self.tolerance
        for frame, task in self.ik.tasks.items():
            error = task.compute_error(kin)
            e_p = float(np.linalg.norm(error[:3]))
            e_r = float(np.linalg.norm(error[3:]))
            position_error[frame] = e_p
            orientation_error[frame] = e_r
            score = max(e_p / tol_p, e_r / tol_r)  # > 1: outside the tolerance
            scores = self._scores[frame]
            scores.append(score)
            if self._active and score > 1.0 and len(scores) == self._window and scores[0] - score < 0.1:
                unreachable.append(frame)
        pose_reached = all(position_error[f] <= tol_p and orientation_error[f] <= tol_r for f in position_error)
        return PoseStreamState(
            *state,
            position_error,
            orientation_error,
            pose_reached,
            tuple(unreachable),
        )
