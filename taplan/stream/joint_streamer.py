"""Online joint streaming with ruckig: any target stream in, a smooth limit-respecting command stream out.

A :class:`JointStreamer` runs at the control period ``dt`` (e.g. 1/77 [s]). Targets arrive whenever they like
(``set_target``); each ``step()`` returns the next command. Position, velocity and acceleration stay continuous
across retargets because every new trajectory starts from the last emitted state. Limits:

* velocity, acceleration and jerk: ruckig's guarantee, from a start state that ``reset`` checks;
* position: taplan's, since the free ruckig ignores position limits. Targets are admitted into the bounds (clamped
  or rejected, see ``on_out_of_bounds``), a target velocity is reduced until its braking stop fits inside the bounds,
  the first period of every new trajectory is vouched for (the emitted state and its shortest stop inside the
  bounds, in closed form) and the trajectory's whole position range is checked before a second period of it is
  emitted (see :mod:`taplan.stream.safety`); when it leaves the bounds the streamer falls back to per-joint
  time-optimal profiles to the target at rest, then to braking. Emitted positions are clipped to the bounds (ruckig's
  accuracy, at most ``POSITION_TOLERANCE``).

Safety: with no new target for ``timeout`` [s] the streamer brakes to rest along the shortest jerk-limited stop
(ruckig's velocity interface), so a dead client never leaves the arm moving; a NaN/inf/wrong-size target raises
:class:`~taplan.StreamError` and changes nothing.
"""

from __future__ import annotations

import logging
import math
from typing import Literal

import numpy as np
import numpy.typing as npt

from taplan._validation import as_positive, as_vector
from taplan.errors import InvalidInputError, StreamError
from taplan.limits import JointLimits
from taplan.stream._ruckig import FINISHED, RuckigAdapter
from taplan.stream.safety import Watchdog, braking_distance, max_safe_velocity, stop_excursion
from taplan.stream.state import StreamState, StreamStatus

__all__ = ["JointStreamer", "POSITION_TOLERANCE"]

logger = logging.getLogger(__name__)

POSITION_TOLERANCE = 1e-7  # [rad]: slack over ruckig's position accuracy (1e-8); emitted positions are clipped
_SPEED_MARGIN = 1.0 - 1e-6  # keep admitted target speeds strictly inside the braking-room bound

_POSITION, _BRAKE = 0, 1
_array = np.array
_new_tuple = tuple.__new__


class JointStreamer:
    """Turns irregular joint targets into a jerk-limited command stream at a fixed period.

    Args:
        limits: Joint limits (e.g. ``robot.planning_limits``); the streamer drives all ``limits.size`` joints in that
            order.
        dt: Control period [s], e.g. ``1 / 77``.
        timeout: Longest time without a new target [s] before braking to rest; None disables it. Default 1.0 [s],
            the robot's own heartbeat and chassis timeouts (a policy sending 16-step chunks at 30 Hz re-targets
            every ~0.53 [s]). This is a dead man's switch: a single far target is followed for at most ``timeout``
            unless it is re-sent; use ``timeout=None`` for one-shot targets (e.g. a human clicking).
        on_out_of_bounds: What ``set_target`` does with a target outside the position bounds (beyond
            ``POSITION_TOLERANCE``) or a target speed above the limit or above what the bounds allow braking from:
            ``"clamp"`` (default) admits the nearest admissible target and flags ``StreamState.target_adjusted``;
            ``"raise"`` raises :class:`~taplan.StreamError` and keeps the previous target.
        synchronization: ruckig synchronisation of the joints: ``"time"`` (all joints arrive together),
            ``"phase"`` (straight line in joint space when possible), ``"none"`` (each joint time-optimal) or
            ``"auto"`` (default): ``"none"`` for a trajectory computed while a new target arrives every period (only
            its first period is ever emitted: the next target replaces it), ``"time"`` otherwise. When such a stream
            pauses for a period, the trajectory to its last target is re-planned time-synchronised from the emitted
            state, so every trajectory followed for more than one period is time-synchronised, as with ``"time"``,
            while a target every period costs ruckig about half as much (about 8 against 19 [us] for 14 joints).
            All limits, the position bounds and continuity hold in every mode.
        initial: Optional initial position [rad], shape (n,): calls ``reset(initial)``.

    Example:
        >>> streamer = JointStreamer(robot.planning_limits, dt=1 / 77, timeout=None, initial=robot.home)
        >>> streamer.set_target(q_goal)
        >>> while not (state := streamer.step()).reached:
        ...     publish(state.position)
    """

    def __init__(
        self,
        limits: JointLimits,
        dt: float,
        *,
        timeout: float | None = 1.0,
        on_out_of_bounds: Literal["clamp", "raise"] = "clamp",
        synchronization: Literal["time", "phase", "none", "auto"] = "auto",
        initial: npt.ArrayLike | None = None,
    ) -> None:
        if not isinstance(limits, JointLimits):
            raise InvalidInputError("limits", type(limits).__name__, "a taplan.JointLimits")
        self.limits = limits
        self.dt = as_positive(dt, "dt")
        if timeout is not None:
            timeout = as_positive(timeout, "timeout")
        if on_out_of_bounds not in ("clamp", "raise"):
            raise InvalidInputError("on_out_of_bounds", on_out_of_bounds, "'clamp' or 'raise'")
        if synchronization not in ("time", "phase", "none", "auto"):
            raise InvalidInputError("synchronization", synchronization, "'time', 'phase', 'none' or 'auto'")
        self.timeout = timeout
        self.on_out_of_bounds = on_out_of_bounds
        self.synchronization = synchronization
        self._auto = synchronization == "auto"
        self._sync = "time" if self._auto else synchronization  # what trajectories followed further use
        self._provisional = False  # "auto": the last trajectory was planned unsynchronised for one period
        self.n = limits.size
        self._lower = np.array(limits.lower)
        self._upper = np.array(limits.upper)
        self._vmax = np.array(limits.velocity)
        self._amax = np.array(limits.acceleration)
        self._jmax = np.array(limits.jerk)
        self._adapter = RuckigAdapter(limits, self.dt)
        self._adapter.set_bounds(self._lower, self._upper, POSITION_TOLERANCE)
        self._watchdog = Watchdog(timeout)
        self._zeros = np.zeros(self.n)
        self._zero_list = [0.0] * self.n  # shared, never mutated
        # hot-path copies as Python floats: ruckig takes lists, and a 14-element Python loop beats small numpy calls
        self._lower_list = self._lower.tolist()
        self._upper_list = self._upper.tolist()
        self._vmax_list = self._vmax.tolist()
        self._speed_rows = _speed_rows(limits, self.dt)
        self._stop_rows = _stop_rows(self._lower_list, self._upper_list, limits.acceleration, limits.jerk)
        self._unchecked = False  # the trajectory being followed was vouched for over its first period only
        self._retargeting = False  # the last step computed a new trajectory
        self._shape = (self.n,)
        self._state: StreamState | None = None
        self._time = 0.0
        self._mode = _POSITION
        self._pending: int | None = None  # _POSITION (new target) or _BRAKE (stop request), applied at next step
        self._target_position: list[float] = self._zero_list
        self._target_velocity: list[float] = self._zero_list
        self._target_moving = False
        self._target_adjusted = False
        self._requested: tuple[list[float], list[float] | None] | None = None
        self._has_target = False
        self.last_fault: str | None = None
        if initial is not None:
            self.reset(initial)

    # ------------------------------------------------------------------ properties
    @property
    def names(self) -> tuple[str, ...]:
        """Joint names, in command order."""
        return self.limits.names

    @property
    def time(self) -> float:
        """Stream time since ``reset`` [s]."""
        return self._time

    @property
    def state(self) -> StreamState:
        """The last emitted state (after ``reset``: the initial state)."""
        if self._state is None:
            raise StreamError("the streamer has no state yet: call reset(position) with the measured position first")
        return self._state

    @property
    def target(self) -> tuple[np.ndarray, np.ndarray]:
        """The admitted target: positions [rad] and velocities [rad]/[s], shape (n,) each."""
        return np.array(self._target_position), np.array(self._target_velocity)

    @property
    def requested_target(self) -> tuple[np.ndarray, np.ndarray | None] | None:
        """The last target as requested, before admission (None before any target)."""
        if self._requested is None:
            return None
        positions, velocities = self._requested
        return np.array(positions), None if velocities is None else np.array(velocities)

    # ------------------------------------------------------------------ commands
    def reset(
        self,
        position: npt.ArrayLike,
        velocity: npt.ArrayLike | None = None,
        acceleration: npt.ArrayLike | None = None,
        *,
        clamp: bool = False,
    ) -> StreamState:
        """Start from a measured state, forgetting any target.

        Args:
            position: Measured position [rad], shape (n,), within the bounds (``clamp=True`` clamps it instead: the
                first command then differs from the measurement by the excursion).
            velocity: Measured velocity [rad]/[s], shape (n,), within the velocity limit; default zero.
            acceleration: Measured acceleration [rad]/[s]², shape (n,), within the limit; default zero.
            clamp: Clamp an out-of-bounds position instead of raising.

        Returns:
            The initial state: ``IDLE`` at rest, ``STOPPING`` when moving (the streamer brakes until a target comes).

        Raises:
            InvalidInputError: Wrong shape, non-finite values, a state outside the limits, or a motion that cannot
                stop inside the position bounds.
        """
        n = self.n
        q = as_vector(position, "position", n).copy()
        v = self._zeros.copy() if velocity is None else as_vector(velocity, "velocity", n).copy()
        a = self._zeros.copy() if acceleration is None else as_vector(acceleration, "acceleration", n).copy()
        outside = (q < self._lower - POSITION_TOLERANCE) | (q > self._upper + POSITION_TOLERANCE)
        if np.any(outside) and not clamp:
            i = int(np.flatnonzero(outside)[0])
            raise InvalidInputError(
                "position",
                f"{self.names[i]} = {q[i]:.6g} rad",
                f"within [{self._lower[i]:.6g}, {self._upper[i]:.6g}] rad (or reset(..., clamp=True))",
            )
        np.clip(q, self._lower, self._upper, out=q)
        _check_magnitude(v, self._vmax, "velocity", self.names, "rad/s")
        _check_magnitude(a, self._amax, "acceleration", self.names, "rad/s^2")
        # ruckig keeps the limits from a start state only if |a| <= sqrt(2 j (vmax - |v|)) (no unavoidable overshoot)
        reachable = np.sqrt(2.0 * self._jmax * np.maximum(self._vmax - np.abs(v), 0.0))
        bad = (np.abs(a) > reachable + 1e-9) & (np.sign(a) == np.sign(v))
        if np.any(bad):
            i = int(np.flatnonzero(bad)[0])
            raise InvalidInputError(
                "acceleration",
                f"{self.names[i]} = {a[i]:.6g} rad/s^2 at {v[i]:.6g} rad/s",
                f"|a| <= sqrt(2 jerk (vmax - |v|)) = {reachable[i]:.6g} rad/s^2, or the velocity limit is overshot",
            )
        adapter = self._adapter
        adapter.set_state(q.tolist(), v.tolist(), a.tolist())
        moving = bool(np.any(v != 0.0) or np.any(a != 0.0))
        if moving:
            adapter.set_brake()
            adapter.update()
            if adapter.leaves_bounds():
                raise InvalidInputError(
                    "velocity", v, "a motion that can stop inside the position bounds (it would overshoot them)"
                )
            adapter.set_state(q.tolist(), v.tolist(), a.tolist())
            adapter.set_brake()
            self._mode = _BRAKE
        else:
            adapter.set_position_target(q.tolist(), self._zero_list, self._sync)
            self._mode = _POSITION
        self._time = 0.0
        self._pending = None
        self._unchecked = False
        self._retargeting = False
        self._provisional = False
        self._target_position = q.tolist()
        self._target_velocity = self._zero_list
        self._target_moving = False
        self._target_adjusted = False
        self._requested = None
        self._has_target = False
        self._watchdog.clear()
        self.last_fault = None
        status = StreamStatus.STOPPING if moving else StreamStatus.IDLE
        self._state = StreamState(0.0, q, v, a, self._zeros.copy(), status)
        return self._state

    def set_target(self, positions: npt.ArrayLike, velocities: npt.ArrayLike | None = None) -> bool:
        """Aim at a new target from the next ``step()`` on (the latest call before a step wins).

        Args:
            positions: Target position [rad], shape (n,).
            velocities: Target velocity [rad]/[s], shape (n,); default zero (stop on the target). A target reached
                with a velocity is followed by a smooth stop unless a new target arrives.

        Returns:
            True when the target was adjusted to stay inside the limits (``on_out_of_bounds="clamp"``).

        Raises:
            StreamError: Wrong size, NaN or inf, or (``on_out_of_bounds="raise"``) a target outside the limits. The
                stream keeps its previous target and motion.
        """
        # Fast path (every call of a VR or pose stream): a float vector inside the bounds (and, with velocities,
        # inside the box from which a full-speed stop fits) needs no numpy work at all. NaN fails the comparisons.
        if type(positions) is np.ndarray and positions.shape == self._shape and positions.dtype.kind == "f":
            q = positions.tolist()
            if velocities is None:
                if _inside(q, self._lower_list, self._upper_list):
                    return self._admit(q, self._zero_list, None, False, False)
            elif type(velocities) is np.ndarray and velocities.shape == self._shape and velocities.dtype.kind == "f":
                v = velocities.tolist()
                if _admissible(q, v, self._speed_rows):
                    return self._admit(q, v, v, any(v), False)
        return self._set_target_checked(positions, velocities)

    def _admit(
        self,
        q: list[float],
        v: list[float],
        requested_v: list[float] | None,
        moving: bool,
        adjusted: bool,
        requested_q: list[float] | None = None,
    ) -> bool:
        self._requested = (q if requested_q is None else requested_q, requested_v)
        self._target_position = q
        self._target_velocity = v
        self._target_moving = moving
        self._target_adjusted = adjusted
        self._pending = _POSITION
        self._has_target = True
        self._watchdog.feed(self._time)
        return adjusted

    def _set_target_checked(self, positions: npt.ArrayLike, velocities: npt.ArrayLike | None) -> bool:
        """The general path of ``set_target``: validation, clamping or raising, braking-room speed caps."""
        q = _target_vector(positions, "positions", self.n)
        v = self._zeros if velocities is None else _target_vector(velocities, "velocities", self.n)
        raising = self.on_out_of_bounds == "raise"
        adjusted = False
        outside = (q < self._lower - POSITION_TOLERANCE) | (q > self._upper + POSITION_TOLERANCE)
        if np.any(outside):
            if raising:
                i = int(np.flatnonzero(outside)[0])
                raise StreamError(
                    f"target positions: {self.names[i]} = {q[i]:.6g} rad is outside "
                    f"[{self._lower[i]:.6g}, {self._upper[i]:.6g}] rad; the previous target is kept"
                )
            adjusted = True
        q_admitted = np.clip(q, self._lower, self._upper)
        if velocities is not None:
            room = np.where(v >= 0.0, self._upper - q_admitted, q_admitted - self._lower)
            # ruckig reports a moving target as reached up to one period late, having coasted on at the target
            # velocity: the braking stop must fit in the room left after that, d(|v|) + |v| dt <= room
            speed = np.abs(v)
            need = braking_distance(speed, self._amax, self._jmax) + speed * self.dt
            fast = (speed > self._vmax) | (need > room * _SPEED_MARGIN)
            if np.any(fast):
                # the cap: v1 fits the room, v2 <= v1 fits room - v1 dt, hence d(v2) + v2 dt <= room
                v1 = max_safe_velocity(room, self._amax, self._jmax)
                v2 = max_safe_velocity(room - v1 * self.dt, self._amax, self._jmax)
                speed_cap = np.where(fast, np.minimum(self._vmax, v2 * _SPEED_MARGIN), speed)
                if raising:
                    i = int(np.flatnonzero(fast)[0])
                    raise StreamError(
                        f"target velocities: {self.names[i]} = {v[i]:.6g} rad/s exceeds {speed_cap[i]:.6g} rad/s "
                        "(velocity limit, or the fastest speed that can still stop inside the bounds); "
                        "the previous target is kept"
                    )
                v = np.clip(v, -speed_cap, speed_cap)
                adjusted = True
        v_list = v.tolist()
        return self._admit(
            q_admitted.tolist(),
            v_list,
            None if velocities is None else _target_vector(velocities, "velocities", self.n).tolist(),
            any(v_list),
            adjusted,
            q.tolist(),
        )

    def stop(self) -> None:
        """Brake smoothly to rest from the next ``step()`` on (a new target resumes motion)."""
        self.state  # noqa: B018 (raises before reset)
        self._pending = _BRAKE

    def step(self) -> StreamState:
        """Advance one period ``dt`` and return the command for it.

        Raises:
            StreamError: Before ``reset``, or when even braking cannot be computed (never observed).
        """
        if self._state is None:
            raise StreamError("the streamer has no state yet: call reset(position) with the measured position first")
        adapter = self._adapter
        fault = None
        pending = self._pending
        provisional, self._provisional = self._provisional, False
        if pending is not None:
            self._pending = None
            if pending == _POSITION:
                self._mode = _POSITION
                if self._auto and self._retargeting:  # a target every period: only one period will be emitted
                    self._provisional = True
                    adapter.set_position_target(self._target_position, self._target_velocity, "none")
                else:
                    adapter.set_position_target(self._target_position, self._target_velocity, self._sync)
            else:
                self._mode = _BRAKE
                adapter.set_brake()
        elif self._mode == _POSITION:
            if self._watchdog.expired(self._time) and self._state.status is StreamStatus.MOVING:
                self._mode = _BRAKE
                adapter.set_brake()
            elif provisional:  # "auto": no new target this period: follow the last one time-synchronised
                adapter.set_position_target(self._target_position, self._target_velocity, self._sync)
        try:
            result = adapter.update()
        except StreamError as exc:
            fault = str(exc)
            result = self._brake_now()
        out = adapter.out
        new_calculation = out.new_calculation
        # each ruckig output attribute is a fresh list converted from C++: read each once
        new_position, new_velocity, new_acceleration = out.new_position, out.new_velocity, out.new_acceleration
        vouched = False
        if new_calculation:
            # Vouch for the first period: the emitted state inside the bounds with its shortest stop inside them
            # too. The trajectory's whole range is checked only if a second period of it is ever emitted (below):
            # a stream that retargets every period never pays for that check.
            # Vouching pays off only for a stream that retargets every period (the previous step computed too);
            # otherwise the whole check would merely move to the next period.
            vouched = self._unchecked = self._retargeting and _stop_fits(
                new_position, new_velocity, new_acceleration, self._stop_rows
            )
            # a new target at rest ends inside the bounds (admitted there): its end state needs no check
            if not vouched and adapter.leaves_bounds(check_end=self._mode == _BRAKE or self._target_moving):
                result = self._fallback(result)
                new_position, new_velocity, new_acceleration = out.new_position, out.new_velocity, out.new_acceleration
        elif self._unchecked:
            # following a vouched-for trajectory beyond its first period: check it whole now; on failure, restart
            # from the last emitted state (vouched for: its stop fits), as for a new trajectory
            self._unchecked = False
            if adapter.leaves_bounds(check_end=self._mode == _BRAKE or self._target_moving):
                result = self._fallback(result)
                new_calculation = True
                new_position, new_velocity, new_acceleration = out.new_position, out.new_velocity, out.new_acceleration
        self._retargeting = new_calculation
        position = _array(new_position, float)
        if not vouched:  # (a vouched-for position is inside the bounds already)
            # ruckig's slack: at most POSITION_TOLERANCE (np.clip's wrapper costs twice these two ufuncs)
            np.minimum(position, self._upper, out=position)
            np.maximum(position, self._lower, out=position)
        out.pass_to_input(adapter.inp)
        if self._mode == _POSITION:
            if result == FINISHED:
                if self._target_moving:  # reached a moving target and nothing newer: stop smoothly
                    status = StreamStatus.MOVING
                    self._mode = _BRAKE
                    adapter.set_brake()
                else:
                    status = StreamStatus.REACHED if self._has_target else StreamStatus.IDLE
            else:
                status = StreamStatus.MOVING
        else:
            status = StreamStatus.STOPPED if result == FINISHED else StreamStatus.STOPPING
        if fault is not None:
            self.last_fault = fault
        self._time = now = self._time + self.dt
        # tuple.__new__: the NamedTuple's own __new__ is a Python-level wrapper around it
        self._state = state = _new_tuple(
            StreamState,
            (
                now,
                position,
                _array(new_velocity, float),
                _array(new_acceleration, float),
                _array(out.new_jerk, float),
                status,
                new_calculation,
                self._target_adjusted,
                fault,
            ),
        )
        return state

    # ------------------------------------------------------------------ internals
    def _brake_now(self) -> int:
        self._mode = _BRAKE
        self._adapter.set_brake()
        return self._adapter.update()

    def _fallback(self, result: int) -> int:
        """The new trajectory leaves the position bounds: try safer variants from the same start state.

        Order: the target position at rest with per-joint time-optimal profiles (no synchronisation; a target
        velocity is dropped, since a moving target can require swinging out beyond the bounds), then braking.
        """
        adapter = self._adapter
        self._provisional = False  # the fallback is followed as it is
        if self._mode == _POSITION:
            adapter.set_position_target(self._target_position, self._zero_list, "none")
            result = adapter.update()
            if not adapter.leaves_bounds():
                if self._target_moving:
                    self._target_velocity = self._zero_list
                    self._target_moving = False
                    self._target_adjusted = True
                return result
            result = self._brake_now()
            if not adapter.leaves_bounds():
                return result
        logger.warning("stream: the braking trajectory leaves the position bounds; positions are clipped")
        return result


def _inside(values: list[float], lower: list[float], upper: list[float]) -> bool:
    """``lower <= values <= upper`` elementwise (False for NaN)."""
    for x, low, high in zip(values, lower, upper, strict=True):  # noqa: SIM110 (a plain loop is faster than all())
        if not low <= x <= high:
            return False
    return True


_STOP_MARGIN = 1e-9  # [rad]: the closed-form stop matches ruckig's braking profile to ~1e-14 [rad]


def _stop_fits(
    position: list[float], velocity: list[float], acceleration: list[float], rows: list[tuple[float, ...]]
) -> bool:
    """Every joint inside the bounds and its shortest stop (:func:`stop_excursion`) inside them (False for NaN).

    A cheap screen first: the stop never moves faster than ``s = |v| + a^2 / (2 j)`` and lasts at most
    ``|a| / j + 2 amax / j + s / amax`` (jerk phases of at most ``(|a| + amax) / j`` and ``amax / j``, a hold that
    changes the velocity by at most ``s``), so its excursion is at most ``s`` times that; only a joint nearer a
    bound than this is given the exact closed form. ``rows`` come from :func:`_stop_rows`.
    """
    for p, v, a, (inner_low, inner_high, half_inv_j, inv_j, two_a_over_j, inv_a, low, high, amax, jmax) in zip(
        position, velocity, acceleration, rows, strict=True
    ):
        speed = abs(v) + a * a * half_inv_j
        reach = speed * (abs(a) * inv_j + two_a_over_j + speed * inv_a)
        if inner_low + reach <= p <= inner_high - reach:  # inside the bounds (less the margin) with the stop
            continue
        if not low <= p <= high:
            return False
        down, up = stop_excursion(v, a, amax, jmax)
        if not (p + down >= low + _STOP_MARGIN and p + up <= high - _STOP_MARGIN):
            return False
    return True


def _stop_rows(
    lower: list[float], upper: list[float], acceleration: npt.ArrayLike, jerk: npt.ArrayLike
) -> list[tuple[float, ...]]:
    """Per joint, what :func:`_stop_fits` needs: the bounds less the margin, the screen's factors, the bounds, the
    acceleration and jerk limits (plain floats: a 14-element Python loop beats small numpy calls)."""
    return [
        (low + _STOP_MARGIN, high - _STOP_MARGIN, 0.5 / jmax, 1.0 / jmax, 2.0 * amax / jmax, 1.0 / amax, low, high)
        + (amax, jmax)
        for low, high, amax, jmax in zip(
            lower, upper, np.asarray(acceleration, float).tolist(), np.asarray(jerk, float).tolist(), strict=True
        )
    ]


def _speed_rows(limits: JointLimits, dt: float) -> list[tuple[float, ...]]:
    """Per joint, what :func:`_admissible` needs: an inner box, the bounds, the stop-distance bound and the limit.

    The stop after a target is reached with speed ``w`` covers at most ``d(w) + w dt <= w (k1 + w k2)`` with
    ``k1 = a / (2 j) + dt`` and ``k2 = 1 / (2 a)`` (the trapezoidal formula of :func:`braking_distance`, an upper
    bound in the triangular regime too, by AM-GM). Inside ``[lower + R, upper - R]`` with ``R`` that bound at the
    velocity limit (empty when the range is too short) any admissible speed fits.
    """
    rows = []
    for low, high, vmax, amax, jmax in zip(
        limits.lower.tolist(),
        limits.upper.tolist(),
        limits.velocity.tolist(),
        limits.acceleration.tolist(),
        limits.jerk.tolist(),
        strict=True,
    ):
        k1, k2 = amax / (2.0 * jmax) + dt, 1.0 / (2.0 * amax)
        reach = vmax * (k1 + vmax * k2) / _SPEED_MARGIN * (1.0 + 1e-9)
        inner = (low + reach, high - reach) if 2.0 * reach < high - low else (math.inf, -math.inf)
        rows.append((inner[0], inner[1], low, high, k1, k2, vmax))
    return rows


def _admissible(q: list[float], v: list[float], rows: list[tuple[float, ...]]) -> bool:
    """Target positions inside the bounds and speeds within the limit whose stop fits (False for NaN, or unsure)."""
    for x, w, (inner_low, inner_high, low, high, k1, k2, vmax) in zip(q, v, rows, strict=True):
        if inner_low <= x <= inner_high and -vmax <= w <= vmax:
            continue
        if w >= 0.0:
            if not (w <= vmax and low <= x and w * (k1 + w * k2) <= (high - x) * _SPEED_MARGIN):
                return False
        elif not (-w <= vmax and x <= high and -w * (k1 - w * k2) <= (x - low) * _SPEED_MARGIN):
            return False
    return True


def _target_vector(value: npt.ArrayLike, name: str, size: int) -> np.ndarray:
    try:
        return as_vector(value, f"target {name}", size).copy()
    except InvalidInputError as exc:
        raise StreamError(f"{exc}; the target was rejected and the stream keeps its last good motion") from None


def _check_magnitude(values: np.ndarray, limit: np.ndarray, name: str, names: tuple[str, ...], unit: str) -> None:
    over = np.abs(values) > limit * (1.0 + 1e-12)
    if np.any(over):
        i = int(np.flatnonzero(over)[0])
        raise InvalidInputError(name, f"{names[i]} = {values[i]:.6g} {unit}", f"|{name}| <= {limit[i]:.6g} {unit}")
