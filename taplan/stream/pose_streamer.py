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

import math
from collections import deque
from collections.abc import Mapping, Sequence
from operator import sub
from typing import Any, Literal, NamedTuple

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


_DEFAULT_POSTURE_COST = 1e-4  # [1/rad]: see PoseStreamer (the IK's own default, 1e-2, stops ~6 mm short)
_new_tuple = tuple.__new__
_SETTLE_SPEED = 1e-3  # [rad]/[s]: an IK step slower than this on a reached pose holds the joints at rest


class PoseStreamer:
    """Streams end-effector pose targets (``{frame: T_root_frame}``) as joint commands at period ``dt``.

    Each ``step`` runs one IK step toward the latest targets (while targets are live) and gives the IK's next
    configuration and velocity to a :class:`~taplan.stream.JointStreamer`. Once every pose is within ``tolerance``
    and the IK has come to rest (slower than 1e-3 [rad]/[s]), the joint streamer is given that configuration as a
    target at rest: the stream reports ``reached`` and skips the IK until a target changes (re-sending the same
    targets keeps the hold).

    IK options: the posture task (pull toward the configuration at ``reset``) keeps redundant arms near a known
    posture but biases the solution: with the IK's own default cost, 1e-2 per [rad], the hand settles about 6 [mm]
    from a small reachable offset, outside the default 1 [mm] tolerance. The pose streamer therefore defaults to
    ``posture_cost=1e-4``, which settles within 1e-7 [m] of reachable targets and still removes the arms' null-space
    drift; pass ``posture_cost`` to override it. Arm-arm collision avoidance stays on by default.

    Reachability: a frame is reported in ``unreachable`` when it is outside the tolerance and, over ``stall_time``,
    neither its error improved by a tenth of the tolerance nor the joints that move it travelled ``stall_motion``:
    the IK has stopped at the closest configuration the limits (joint bounds, speed, arm-arm clearance) allow. A
    detour (the error grows while the arm swings around a joint limit) is not a stall.

    Args:
        robot: The robot (poses are ``T_root_frame`` in its root frame, e.g. ``shoulder_base``).
        dt: Control period [s] (also the IK's step).
        frames: Task frames, e.g. ``("left_ee", "right_ee")`` or ``("left_ee",)``.
        limits: Joint limits over all the robot's joints; default ``robot.planning_limits``.
        timeout: Longest time without a pose target [s] before braking to rest; None disables it.
        tolerance: ``(position [m], orientation [rad])`` within which a pose counts as reached.
        stall_time: Window [s] of the unreachable test above.
        stall_motion: Joint travel [rad] over ``stall_time`` below which the IK counts as stopped.
        synchronization: The joint streamer's ruckig synchronisation. Default ``"none"``: every joint tracks its own
            IK reference (position and velocity, renewed each period) time-optimally; the IK already coordinates
            the joints, and ruckig's time synchronisation would cost twice as much per period for no benefit.
        ik: A ready :class:`~taplan.ik.DifferentialIK` (same ``dt``, frames and limits) instead of building one.
        initial: Optional initial configuration [rad] (nq,): calls ``reset(initial)``.
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
        stall_motion: float = 0.02,
        synchronization: Literal["time", "phase", "none", "auto"] = "none",
        ik: DifferentialIK | None = None,
        initial: npt.ArrayLike | None = None,
        **ik_options: Any,
    ) -> None:
        self.robot = robot
        self.dt = as_positive(dt, "dt")
        limits = robot.planning_limits if limits is None else limits
        if ik is None:
            ik_options.setdefault("posture_cost", _DEFAULT_POSTURE_COST)
            ik = DifferentialIK(robot, dt=self.dt, limits=limits, frames=tuple(frames), **ik_options)
        elif abs(ik.dt - self.dt) > 1e-12:
            raise InvalidInputError("ik.dt", ik.dt, f"the streamer's dt {self.dt}")
        self.ik = ik
        self.frames = ik.frames
        self.tolerance = (as_positive(tolerance[0], "tolerance[0]"), as_positive(tolerance[1], "tolerance[1]"))
        self.stall_motion = as_positive(stall_motion, "stall_motion")
        self._window = max(2, round(as_positive(stall_time, "stall_time") / self.dt))
        model = robot.model
        self._frame_ids = {f: robot.frame_id(f) for f in self.frames}
        self._frame_joints = {f: _index(_supporting_joints(model, fid)) for f, fid in self._frame_ids.items()}
        # per frame: (score, positions of the joints that move it) over the last `window` steps
        self._history: dict[str, deque[tuple[float, list[float]]]] = {
            f: deque(maxlen=self._window) for f in self.frames
        }
        # per frame: the top 3 rows of the target's 4x4, row-major (12 floats: rotation and position [m])
        self._targets: dict[str, list[float]] = {}
        self._restart_distance = 0.1 * self.tolerance[0]  # [m]: a target that moves more restarts its stall window
        self.joints = JointStreamer(
            limits, self.dt, timeout=None, on_out_of_bounds="clamp", synchronization=synchronization
        )
        self._watchdog = Watchdog(None if timeout is None else as_positive(timeout, "timeout"))
        self._active = False
        self._holding = False
        if initial is not None:
            self.reset(initial)

    @property
    def names(self) -> tuple[str, ...]:
        """Joint names of the commands (all the robot's joints)."""
        return self.joints.names

    @property
    def limits(self) -> JointLimits:
        """The joint limits the commands respect."""
        return self.joints.limits

    def reset(self, position: npt.ArrayLike, velocity: npt.ArrayLike | None = None) -> StreamState:
        """Start from a measured configuration [rad] (nq,) (and velocity [rad]/[s]); poses hold where they are."""
        state = self.joints.reset(position, velocity)
        self.ik.reset(state.position, state.velocity)
        self._watchdog.clear()
        self._active = False
        self._holding = False
        for history in self._history.values():
            history.clear()
        self._targets.clear()
        return state

    def set_target(self, targets: Mapping[str, Any]) -> None:
        """New pose targets ``{frame: pose}`` (a subset of ``frames`` keeps the others' last targets).

        Poses: 4x4 ``T_root_frame``, ``(position [m] (3,), quaternion xyzw (4,))`` or ``(7,)``.

        Raises:
            StreamError: Unknown frame, wrong shape, NaN/inf or a non-rotation; nothing changes.
        """
        if not (type(targets) is dict or isinstance(targets, Mapping)) or not targets:
            raise StreamError(f"pose targets: expected a non-empty mapping {{frame: pose}}, received {targets!r:.80}")
        frame_ids = self._frame_ids
        checked: dict[str, np.ndarray] = {}  # frame -> validated 4x4 (a copy: the caller may reuse its array)
        flats = []
        for frame, pose in targets.items():
            if frame not in frame_ids:
                raise StreamError(f"{UnknownNameError('task frame', frame, self.frames)}; the target was rejected")
            flat = _fast_transform(pose, self._targets.get(frame))
            if flat is None:
                try:
                    T = as_transform(pose, f"targets[{frame!r}]")
                except InvalidInputError as exc:
                    raise StreamError(
                        f"{exc}; the target was rejected and the stream keeps its last good motion"
                    ) from None
                flat = T[:3].ravel().tolist()
            else:
                T = pose.copy()
            checked[frame] = T
            flats.append((frame, flat))
        state = self.joints.state  # raises before reset
        stored = self._targets
        far = self._restart_distance
        for frame, flat in flats:
            previous = stored.get(frame)
            if previous != flat:
                self._holding = False  # any change resumes tracking
                if (  # a target that moved (any entry of its top rows) restarts its progress window
                    previous is None
                    or abs(flat[3] - previous[3]) > far  # (the translation first: a moving target stops here)
                    or abs(flat[7] - previous[7]) > far
                    or abs(flat[11] - previous[11]) > far
                    or max(map(abs, map(sub, flat, previous))) > far
                ):
                    self._history[frame].clear()
                stored[frame] = flat
        if not self._active:  # resume from where the joint stream is, with its velocity (acceleration limit state)
            self.ik.reset(state.position, state.velocity)
            self._holding = False
        self.ik.set_targets(checked)
        self._active = True
        self._watchdog.feed(self.joints.time)

    def stop(self) -> None:
        """Brake smoothly to rest; the next pose target resumes."""
        self._active = False
        self._holding = False
        self.joints.stop()

    def step(self) -> PoseStreamState:
        """Advance one period: one IK step (while targets are live), then one joint-streamer step."""
        joints = self.joints
        if self._active and self._watchdog.expired(joints.time):
            self.stop()
        ik_velocity = None
        if self._active and not self._holding:  # holding a reached pose: nothing to solve until a target changes
            out = self.ik.step()
            ik_velocity = out.velocity
            joints.set_target(out.q, ik_velocity)
        # errors at the IK step's start configuration (its kinematics are evaluated there; while holding, at the
        # held configuration)
        errors = self.ik.step_errors()
        tol_p, tol_r = self.tolerance
        position_error: dict[str, float] = {}
        orientation_error: dict[str, float] = {}
        pose_reached = True
        for frame in self._targets:
            e_p, e_r = errors[frame]
            position_error[frame] = e_p
            orientation_error[frame] = e_r
            if e_p > tol_p or e_r > tol_r:
                pose_reached = False
        unreachable: tuple[str, ...] = ()
        if self._active and not pose_reached:
            unreachable = self._stalled(position_error, orientation_error)
        if (
            self._active
            and not self._holding
            and pose_reached
            and self._targets
            and ik_velocity is not None
            and not np.any(np.abs(ik_velocity) > _SETTLE_SPEED)
        ):
            joints.set_target(self.ik.kin.q)  # hold the reached configuration at rest
            self._holding = True
        # tuple.__new__: the NamedTuple's own __new__ is a Python-level wrapper around it
        state = joints.step()
        return _new_tuple(PoseStreamState, (*state, position_error, orientation_error, pose_reached, unreachable))

    def _stalled(self, position_error: dict[str, float], orientation_error: dict[str, float]) -> tuple[str, ...]:
        """Frames outside the tolerance whose error and joints have not moved over the stall window."""
        tol_p, tol_r = self.tolerance
        q = self.ik.kin.q.tolist()
        stalled = []
        for frame, e_p in position_error.items():
            score = max(e_p / tol_p, orientation_error[frame] / tol_r)  # > 1: outside the tolerance
            history = self._history[frame]
            joints = self._frame_joints[frame]
            joints_q = q[joints] if type(joints) is slice else [q[i] for i in joints]
            history.append((score, joints_q))
            if score <= 1.0 or len(history) < self._window:
                continue
            first_score, first_q = history[0]
            if first_score - score < 0.1 and max(map(abs, map(sub, joints_q, first_q))) < self.stall_motion:
                stalled.append(frame)
        return tuple(stalled)


def _index(indices: np.ndarray) -> list[int] | slice:
    """A slice for contiguous indices (cheaper to take from a list), else the indices."""
    if indices.size and np.array_equal(indices, np.arange(indices[0], indices[0] + indices.size)):
        return slice(int(indices[0]), int(indices[0]) + indices.size)
    return indices.tolist()


def _supporting_joints(model: Any, frame_id: int) -> np.ndarray:
    """Configuration indices (1-DoF joints) of the joints that move a frame."""
    joint = model.frames[frame_id].parentJoint
    return np.array([model.joints[j].idx_q for j in model.supports[joint] if j > 0], dtype=int)


def _fast_transform(pose: Any, previous: list[float] | None = None) -> list[float] | None:
    """The top 3 rows (12 floats) of a float 4x4 proper rigid transform; None when it needs the full check.

    One ``tolist`` and plain float arithmetic: finiteness (the sum of finite floats is finite), the last row, an
    orthonormal rotation (row products within 1e-6, as :func:`~taplan.ik._targets.as_transform`) and det > 0. A
    rotation equal to the one of ``previous`` (an accepted target's top rows) was checked already: only the
    translation's finiteness is left (a target that moves without turning).
    """
    if type(pose) is not np.ndarray or pose.shape != (4, 4) or pose.dtype != np.float64:
        return None
    r0, r1, r2, last = pose.tolist()
    if last != [0.0, 0.0, 0.0, 1.0]:
        return None
    if (
        previous is not None
        and r0[0] == previous[0]  # (cheap first test: a turning target fails here)
        and r0[:3] == previous[0:3]
        and r1[:3] == previous[4:7]
        and r2[:3] == previous[8:11]
    ):
        return r0 + r1 + r2 if math.isfinite(r0[3] + r1[3] + r2[3]) else None
    if not math.isfinite(sum(r0) + sum(r1) + sum(r2)):
        return None
    a, b, c = r0[0], r0[1], r0[2]
    d, e, f = r1[0], r1[1], r1[2]
    g, h, i = r2[0], r2[1], r2[2]
    if (
        abs(a * a + b * b + c * c - 1.0) > 1e-6
        or abs(d * d + e * e + f * f - 1.0) > 1e-6
        or abs(g * g + h * h + i * i - 1.0) > 1e-6
        or abs(a * d + b * e + c * f) > 1e-6
        or abs(a * g + b * h + c * i) > 1e-6
        or abs(d * g + e * h + f * i) > 1e-6
        or a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) <= 0.0
    ):
        return None
    return r0 + r1 + r2
