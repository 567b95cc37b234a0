"""The TeleAvatar ``/api`` command payloads as plain Python values, and the scheduler that says when each is due.

No ROS import: each builder returns an :class:`ApiMessage` (topic, ROS message type name, plain fields), validated
with :class:`~taplan.InvalidInputError`; :mod:`taplan.ros` turns them into ROS messages at the edge. Sources: the
robot's developer guide (topics, ranges, 50-77 [Hz] arm commands, heartbeat above 1 [Hz], 10-20 [Hz] recommended)
and ``shared/reference/teleavatar/API_NOTES.md`` (§4: the two ``joint_cmd`` conventions).

``joint_cmd`` conventions:

* ``"position"`` (TeleAvatar 2): ``position`` = the desired joint angles; ``velocity`` and ``effort`` zero; the
  robot runs its own inner loop.
* ``"velocity_feedback"`` (the guide's demos and the v1 relay): ``position`` = the desired angles and
  ``velocity = clip(kp (q_des - q_measured), ±alpha · vel_limit)`` with the guide's ``fb_kp`` [7, 7, 10, 10, 10, 8,
  8] [1/s], ``alpha`` 0.3 and ``vel_limit`` [15, 15, 20, 20, 44, 33, 33] [rad]/[s] (caps [4.5, 4.5, 6, 6, 13.2,
  9.9, 9.9] [rad]/[s]).

Do not mix conventions on one robot (API_NOTES §4).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from taplan._validation import as_vector
from taplan.errors import InvalidInputError, UnknownNameError
from taplan.limits import JointLimits

__all__ = [
    "SIDES",
    "ARM_JOINT_NAMES",
    "FEEDBACK_KP",
    "FEEDBACK_ALPHA",
    "VELOCITY_LIMIT",
    "ARM_RATE_RANGE",
    "HEARTBEAT_RATE",
    "Topics",
    "ApiMessage",
    "joint_cmd",
    "feedback_velocity",
    "target_pose",
    "gripper_cmd",
    "chassis_velocity",
    "servo_cmd",
    "fsm_enable",
    "fsm_adjust",
    "parse_joint_state",
    "ManualClock",
    "CommandScheduler",
]

SIDES = ("left", "right")
ARM_JOINT_NAMES: dict[str, tuple[str, ...]] = {
    "left": tuple(f"l_joint{i}" for i in range(1, 8)),
    "right": tuple(f"r_joint{i}" for i in range(1, 8)),
}
FEEDBACK_KP = (7.0, 7.0, 10.0, 10.0, 10.0, 8.0, 8.0)  # [1/s], arm_config.yml ik_solver.vel.fb_kp
FEEDBACK_ALPHA = 0.3  # fraction of vel_limit the feedback velocity is clipped to (ff_alpha)
VELOCITY_LIMIT = (15.0, 15.0, 20.0, 20.0, 44.0, 33.0, 33.0)  # [rad]/[s], arm_config.yml vel_limit
ARM_RATE_RANGE = (50.0, 77.0)  # [Hz], the guide's recommended joint_cmd / target_pose rate
HEARTBEAT_RATE = 20.0  # [Hz], top of the guide's 10-20 Hz recommendation (the robot pauses after 1 s without)


class Topics:
    """Topic names of the robot's API mode (the developer guide, §2)."""

    ENABLE = "/api/fsm/enable"
    ADJUST = "/api/fsm/adjust"
    CHASSIS = "/api/chassis/velocity"
    SERVO = "/api/servo/cmd"

    @staticmethod
    def joint_cmd(side: str) -> str:
        return f"/api/{_side(side)}_arm/joint_cmd"

    @staticmethod
    def target_pose(side: str) -> str:
        return f"/api/{_side(side)}_arm/target_pose"

    @staticmethod
    def gripper(side: str) -> str:
        return f"/api/{_side(side)}_gripper/cmd"

    @staticmethod
    def joint_states(side: str) -> str:
        return f"/{_side(side)}_arm/joint_states"

    @staticmethod
    def current_ee_pose(side: str) -> str:
        return f"/{_side(side)}_arm/current_ee_pose"


@dataclass(frozen=True)
class ApiMessage:
    """One message to publish.

    Attributes:
        topic: ROS topic, e.g. ``/api/left_arm/joint_cmd``.
        type: ROS type: ``sensor_msgs/msg/JointState``, ``std_msgs/msg/Float32``,
            ``std_msgs/msg/Float32MultiArray`` or ``geometry_msgs/msg/Pose``.
        fields: The message fields as plain Python values: ``{"name", "position", "velocity", "effort"}`` (lists),
            ``{"data": float}``, ``{"data": list[float]}`` or ``{"position": {"x","y","z"}, "orientation":
            {"x","y","z","w"}}``.
    """

    topic: str
    type: str
    fields: dict[str, Any]


JOINT_STATE = "sensor_msgs/msg/JointState"
FLOAT32 = "std_msgs/msg/Float32"
FLOAT32_ARRAY = "std_msgs/msg/Float32MultiArray"
POSE = "geometry_msgs/msg/Pose"


def feedback_velocity(
    desired: npt.ArrayLike,
    measured: npt.ArrayLike,
    *,
    kp: npt.ArrayLike = FEEDBACK_KP,
    alpha: float = FEEDBACK_ALPHA,
    velocity_limit: npt.ArrayLike = VELOCITY_LIMIT,
) -> np.ndarray:
    """The guide's feedback velocity ``clip(kp (desired - measured), ±alpha · velocity_limit)`` [rad]/[s].

    Args:
        desired: Desired positions [rad], shape (7,).
        measured: Measured positions [rad], shape (7,).
        kp: Gains [1/s], shape (7,), > 0.
        alpha: Fraction of ``velocity_limit``, in (0, 1].
        velocity_limit: Velocity ceilings [rad]/[s], shape (7,), > 0.
    """
    q_des = as_vector(desired, "desired", None)
    n = q_des.size
    q = as_vector(measured, "measured", n)
    gains = as_vector(kp, "kp", n)
    caps = as_vector(velocity_limit, "velocity_limit", n)
    if np.any(gains <= 0.0):
        raise InvalidInputError("kp", gains, "gains > 0 [1/s]")
    if np.any(caps <= 0.0):
        raise InvalidInputError("velocity_limit", caps, "limits > 0 [rad/s]")
    if not (math.isfinite(alpha) and 0.0 < alpha <= 1.0):
        raise InvalidInputError("alpha", alpha, "a fraction in (0, 1]")
    cap = alpha * caps
    return np.clip(gains * (q_des - q), -cap, cap)


def joint_cmd(
    side: str,
    position: npt.ArrayLike,
    *,
    convention: Literal["position", "velocity_feedback", "feedforward"] = "position",
    measured: npt.ArrayLike | None = None,
    velocity: npt.ArrayLike | None = None,
    limits: JointLimits | None = None,
    names: Sequence[str] | None = None,
    kp: npt.ArrayLike = FEEDBACK_KP,
    alpha: float = FEEDBACK_ALPHA,
    velocity_limit: npt.ArrayLike = VELOCITY_LIMIT,
) -> ApiMessage:
    """``/api/{side}_arm/joint_cmd`` (``sensor_msgs/JointState``).

    Args:
        side: ``"left"`` or ``"right"``.
        position: Desired joint angles [rad], shape (7,), in ``names`` order.
        convention: ``"position"`` (velocity and effort zero), ``"velocity_feedback"`` (velocity from
            :func:`feedback_velocity`; needs ``measured``) or ``"feedforward"`` (the plan's own ``velocity``).
        measured: Measured joint angles [rad], shape (7,), same order (``"velocity_feedback"`` only).
        velocity: The plan's velocity [rad]/[s], shape (7,), same order (``"feedforward"`` only).
        limits: When given, ``position`` must lie within these bounds (joints looked up by name); the robot clips
            out-of-range targets silently, so taplan refuses them instead.
        names: Joint names; default ``l_joint1..7`` / ``r_joint1..7``.
        kp: Feedback gains [1/s] (``"velocity_feedback"``).
        alpha: Velocity clip fraction (``"velocity_feedback"``).
        velocity_limit: Velocity ceilings [rad]/[s] (``"velocity_feedback"``).

    Raises:
        InvalidInputError: Unknown side or convention, wrong shape, NaN/inf, a position outside ``limits``, or a
            missing ``measured``.
    """
    side = _side(side)
    names = tuple(ARM_JOINT_NAMES[side] if names is None else (str(n) for n in names))
    n = len(names)
    if n == 0 or len(set(names)) != n:
        raise InvalidInputError("names", names, "unique joint names")
    q = as_vector(position, "position", n)
    if limits is not None:
        index = limits.indices(names)
        lo, hi = limits.lower[index], limits.upper[index]
        outside = (q < lo) | (q > hi)
        if np.any(outside):
            i = int(np.flatnonzero(outside)[0])
            raise InvalidInputError("position", f"{names[i]} = {q[i]:.6g} rad", f"within [{lo[i]:.6g}, {hi[i]:.6g}]")
    if convention == "position":
        sent = [0.0] * n
    elif convention == "velocity_feedback":
        if measured is None:
            raise InvalidInputError("measured", None, "the measured positions for convention='velocity_feedback'")
        sent = feedback_velocity(q, measured, kp=kp, alpha=alpha, velocity_limit=velocity_limit).tolist()
    elif convention == "feedforward":
        if velocity is None:
            raise InvalidInputError("velocity", None, "the plan's velocities for convention='feedforward'")
        sent = as_vector(velocity, "velocity", n).tolist()
    else:
        raise InvalidInputError("convention", convention, "'position', 'velocity_feedback' or 'feedforward'")
    fields = {"name": list(names), "position": q.tolist(), "velocity": sent, "effort": [0.0] * n}
    return ApiMessage(Topics.joint_cmd(side), JOINT_STATE, fields)


def target_pose(
    side: str,
    pose: npt.ArrayLike | None = None,
    *,
    position: npt.ArrayLike | None = None,
    quaternion: npt.ArrayLike | None = None,
    normalize: bool = True,
) -> ApiMessage:
    """``/api/{side}_arm/target_pose`` (``geometry_msgs/Pose``): either a 4x4 transform or position + quaternion.

    The frame is the robot's (the guide: "the end effector in the base frame"; see API_NOTES §7 for the open
    question of which base); taplan does not re-express it.

    Args:
        side: ``"left"`` or ``"right"``.
        pose: Homogeneous transform, shape (4, 4), translation in [m].
        position: Position [m], shape (3,) (instead of ``pose``).
        quaternion: Orientation, xyzw (ROS order), shape (4,) (instead of ``pose``).
        normalize: Normalise a quaternion whose norm is within 1e-3 of 1 (others raise).
    """
    side = _side(side)
    if pose is not None:
        if position is not None or quaternion is not None:
            raise InvalidInputError("pose", "pose with position/quaternion", "either pose or position + quaternion")
        T = np.asarray(pose, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise InvalidInputError("pose", f"array of shape {T.shape}", "a finite 4x4 homogeneous transform")
        R = T[:3, :3]
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise InvalidInputError("pose", "a non-rotation block", "an orthonormal rotation with det +1")
        p = T[:3, 3]
        xyzw = _quaternion_xyzw(R)
    else:
        if position is None or quaternion is None:
            raise InvalidInputError("pose", None, "a 4x4 pose, or both position and quaternion")
        p = as_vector(position, "position", 3)
        xyzw = as_vector(quaternion, "quaternion", 4)
        norm = float(np.linalg.norm(xyzw))
        if abs(norm - 1.0) > (1e-3 if normalize else 1e-9):
            raise InvalidInputError("quaternion", xyzw, "a unit quaternion (x, y, z, w)")
        xyzw = xyzw / norm
    fields = {
        "position": {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])},
        "orientation": {"x": float(xyzw[0]), "y": float(xyzw[1]), "z": float(xyzw[2]), "w": float(xyzw[3])},
    }
    return ApiMessage(Topics.target_pose(side), POSE, fields)


def gripper_cmd(side: str, value: float) -> ApiMessage:
    """``/api/{side}_gripper/cmd`` (``Float32``): trigger in [0, 1] (0 open with full force, 0.10 no torque, 1 close).

    The robot acts on it only while arm commands stream and the FSM is enabled (API_NOTES §7).
    """
    side = _side(side)
    data = _number(value, "value")
    if not 0.0 <= data <= 1.0:
        raise InvalidInputError("value", value, "a gripper trigger in [0, 1]")
    return ApiMessage(Topics.gripper(side), FLOAT32, {"data": data})


def chassis_velocity(vx: float, vy: float, rx: float) -> ApiMessage:
    """``/api/chassis/velocity`` (``Float32MultiArray``): normalised ``[vx, vy, rx]``, each in [-1, 1].

    The chassis stops by itself 1 [s] after the last command; send zeros to stop at once.
    """
    data = [_number(v, name) for v, name in ((vx, "vx"), (vy, "vy"), (rx, "rx"))]
    for value, name in zip(data, ("vx", "vy", "rx"), strict=True):
        if not -1.0 <= value <= 1.0:
            raise InvalidInputError(name, value, "a normalised velocity in [-1, 1]")
    return ApiMessage(Topics.CHASSIS, FLOAT32_ARRAY, {"data": data})


def servo_cmd(speed: float, enable: bool = True) -> ApiMessage:
    """``/api/servo/cmd`` (``Float32MultiArray``): the lift servo ``[speed, enable]``.

    ``enable`` False (data[1] = 0.0) cuts the servo at once (emergency stop). The guide gives no range or unit for
    ``speed``; it must be finite, and 0 when disabled. The servo zeroes its speed 1 [s] after the last command
    (send at 10 [Hz] or faster).
    """
    value = _number(speed, "speed")
    if not isinstance(enable, (bool, np.bool_)):
        raise InvalidInputError("enable", enable, "True or False")
    if not enable and value != 0.0:
        raise InvalidInputError("speed", value, "0 while the servo is disabled")
    return ApiMessage(Topics.SERVO, FLOAT32_ARRAY, {"data": [value, 1.0 if enable else 0.0]})


def fsm_enable(enable: bool = True) -> ApiMessage:
    """``/api/fsm/enable`` (``Float32``): 1.0 enables and is the heartbeat (send above 1 [Hz]), -1.0 disables."""
    if not isinstance(enable, (bool, np.bool_)):
        raise InvalidInputError("enable", enable, "True (heartbeat) or False (disable)")
    return ApiMessage(Topics.ENABLE, FLOAT32, {"data": 1.0 if enable else -1.0})


def fsm_adjust(start: bool = True) -> ApiMessage:
    """``/api/fsm/adjust`` (``Float32``): 1.0 starts the calibration / raise-arms routine, -1.0 leaves it."""
    if not isinstance(start, (bool, np.bool_)):
        raise InvalidInputError("start", start, "True (enter) or False (exit)")
    return ApiMessage(Topics.ADJUST, FLOAT32, {"data": 1.0 if start else -1.0})


def parse_joint_state(side: str, name: Sequence[str], position: Sequence[float]) -> np.ndarray:
    """Positions of one arm from a ``/{side}_arm/joint_states`` message, in ``l_joint1..7`` / ``r_joint1..7`` order.

    Matched by name when names are present (any order, extra joints ignored), else by index (the vendor client's
    way). Raises :class:`~taplan.InvalidInputError` / :class:`~taplan.UnknownNameError` when joints are missing,
    sizes disagree or values are not finite.
    """
    side = _side(side)
    expected = ARM_JOINT_NAMES[side]
    values = np.asarray(list(position), dtype=float)
    names = [str(n) for n in name]
    if names:
        if len(names) != values.size:
            raise InvalidInputError("position", f"{values.size} values for {len(names)} names", "one per name")
        lookup = {n: i for i, n in enumerate(names)}
        missing = [n for n in expected if n not in lookup]
        if missing:
            raise UnknownNameError("joint in joint_states", missing[0], names)
        q = values[[lookup[n] for n in expected]]
    else:
        if values.size < len(expected):
            raise InvalidInputError("position", f"{values.size} values", f"at least {len(expected)} positions")
        q = values[: len(expected)]
    if not np.all(np.isfinite(q)):
        raise InvalidInputError("position", q, "finite joint positions")
    return q


class ManualClock:
    """A clock you advance by hand, for tests and simulations: ``clock()`` returns the time [s]."""

    def __init__(self, start: float = 0.0) -> None:
        self.now = float(start)

    def __call__(self) -> float:
        return self.now

    def advance(self, dt: float) -> float:
        """Move the time forward by ``dt`` >= 0 [s]; returns the new time."""
        if not (math.isfinite(dt) and dt >= 0.0):
            raise InvalidInputError("dt", dt, "a time step >= 0 [s]")
        self.now += dt
        return self.now


class CommandScheduler:
    """Says, at each tick of any timer, which messages are due: one timing logic for control code and tests.

    Each channel has a rate; it is due at ``start + k / rate``. A tick at ``now`` reports a channel as due when its
    next due time has come (within 1e-9 [s]); missed slots are skipped, never sent in a burst, and the next slot is
    the first one after ``now``. Tick faster than the fastest rate (e.g. 200-1000 [Hz]) for exact rates; ticking at
    the arm rate itself works too.

    Args:
        arm_rate: Rate of ``/api/*_arm/joint_cmd`` (or ``target_pose``) [Hz], within ``arm_rate_range``. Default 77.
        heartbeat_rate: Rate of ``/api/fsm/enable`` [Hz], > 1 (the robot pauses after 1 [s] without). Default 20.
        extra: More channels, name -> rate [Hz] (e.g. ``{"gripper": 20.0, "chassis": 10.0}``).
        clock: Returns the time [s]; default: ``now`` must be passed to :meth:`tick` (no wall clock in the core).
        arm_rate_range: Admissible arm rates [Hz]; the guide's 50-77 by default.
        start: Time of the first slot of every channel [s]; default: the first tick.
    """

    ARM = "arm"
    HEARTBEAT = "heartbeat"

    def __init__(
        self,
        arm_rate: float = 77.0,
        heartbeat_rate: float = HEARTBEAT_RATE,
        *,
        extra: Mapping[str, float] | None = None,
        clock: Callable[[], float] | None = None,
        arm_rate_range: tuple[float, float] = ARM_RATE_RANGE,
        start: float | None = None,
    ) -> None:
        lo, hi = arm_rate_range
        arm_rate = _number(arm_rate, "arm_rate")
        if not lo <= arm_rate <= hi:
            raise InvalidInputError("arm_rate", arm_rate, f"a rate in [{lo:g}, {hi:g}] Hz (the guide's 50-77 Hz)")
        heartbeat_rate = _number(heartbeat_rate, "heartbeat_rate")
        if heartbeat_rate <= 1.0:
            raise InvalidInputError("heartbeat_rate", heartbeat_rate, "a rate > 1 Hz (10-20 Hz recommended)")
        rates = {self.ARM: arm_rate, self.HEARTBEAT: heartbeat_rate}
        for name, rate in (extra or {}).items():
            if name in rates:
                raise InvalidInputError("extra", name, f"a channel name other than {sorted(rates)}")
            value = _number(rate, f"extra[{name!r}]")
            if value <= 0.0:
                raise InvalidInputError(f"extra[{name!r}]", rate, "a rate > 0 Hz")
            rates[str(name)] = value
        self.rates: dict[str, float] = rates
        self.periods: dict[str, float] = {name: 1.0 / rate for name, rate in rates.items()}
        self._clock = clock
        self._start = start
        self._next_slot: dict[str, int] = dict.fromkeys(rates, 0)
        self._last_tick: float | None = None
        self.sent: dict[str, int] = dict.fromkeys(rates, 0)

    @property
    def arm_period(self) -> float:
        """Period of the arm commands [s]: use it as the streamer's ``dt``."""
        return self.periods[self.ARM]

    def tick(self, now: float | None = None) -> frozenset[str]:
        """Names of the channels due at ``now`` [s] (default: the injected clock's time)."""
        now = self._now(now)
        if self._start is None:
            self._start = now
        due = []
        start = self._start
        for name, period in self.periods.items():
            slot = self._next_slot[name]
            if now + 1e-9 >= start + slot * period:
                due.append(name)
                # next slot: the first one strictly after now (skip missed slots, no bursts)
                self._next_slot[name] = max(slot + 1, math.floor((now + 1e-9 - start) / period) + 1)
                self.sent[name] += 1
        return frozenset(due)

    def next_due(self, now: float | None = None) -> float:
        """Earliest time [s] at which some channel is due (to sleep until)."""
        self._now(now)
        start = self._start if self._start is not None else (now if now is not None else 0.0)
        return min(start + self._next_slot[name] * period for name, period in self.periods.items())

    def _now(self, now: float | None) -> float:
        if now is None:
            if self._clock is None:
                raise InvalidInputError("now", None, "a time [s] (or give the scheduler a clock)")
            now = self._clock()
        now = _number(now, "now")
        if self._last_tick is not None and now < self._last_tick:
            raise InvalidInputError("now", now, f"a time >= the previous tick {self._last_tick:.9g} s (monotonic)")
        self._last_tick = now
        return now


def _side(side: str) -> str:
    if side not in SIDES:
        raise UnknownNameError("side", side, SIDES)
    return side


def _number(value: Any, name: str) -> float:
    if isinstance(value, bool):
        raise InvalidInputError(name, value, "a finite number")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InvalidInputError(name, value, "a finite number") from None
    if not math.isfinite(number):
        raise InvalidInputError(name, value, "a finite number")
    return number


def _quaternion_xyzw(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w), w >= 0, of a rotation matrix (Shepperd's method)."""
    trace = R[0, 0] + R[1, 1] + R[2, 2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = np.array([(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s])
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = np.array([0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s])
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = np.array([(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s])
    else:
        s = 2.0 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = np.array([(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s])
    q /= np.linalg.norm(q)
    return -q if q[3] < 0.0 else q
