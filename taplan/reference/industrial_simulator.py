"""The ROS-Industrial ``industrial_robot_simulator`` with velocities (seed 000), replayed in model time.

The seed's ``MotionControllerSimulator`` takes ``JointTrajectoryPoint`` waypoints from a queue in a worker thread
and, at ``update_rate`` (100 Hz), moves its state to intermediate points; a ``rospy.Timer`` publishes the state on
``joint_states`` at ``pub_rate`` (10 Hz). :class:`IndustrialSimulator` reproduces it without threads or sleeping:
time is integer nanoseconds, every ``rospy.sleep`` lasts exactly its argument (simulated clock, zero computation
time) and every waypoint is in the queue at t = 0 (one ``joint_path_command`` message received while idle).

``mode="seed"`` is the code as it runs under ROS 1 (rospy/genpy ``Duration``), bug for bug:

1. **Linear branch raises.** When either end of a segment lacks velocities, the loop computes
   ``(current_joint - last_joint) / move_duration``: ``float / genpy.Duration``. ``Duration`` defines
   ``__truediv__`` (Duration / number or Duration) but no ``__rtruediv__``, so Python raises ``TypeError``. It is
   raised on the first loop iteration, after ``interpolate()`` but before any ``_move_to``, and caught by the
   worker's ``except Exception``: the waypoint is **dropped** -- no sleep, no state change, and ``last_goal_point``
   keeps the previous goal. The next waypoint's segment is then measured from that older goal (its duration spans
   both segments) and is judged again, so with positions-only waypoints every point more than one update period
   after the last reached goal is dropped and the state stays where it was.
2. **Short segments and the first point jump.** The loop runs ``while update_duration < move_duration``; a segment
   of at most one period (e.g. the usual first point with ``time_from_start = 0``) skips it, so
   ``_move_to(point, move_duration)`` sleeps the whole duration and then sets the state to the point: a jump. The
   initial ``last_goal_point`` has the initial positions, ``time_from_start = 0`` and *no velocities*, so a first
   waypoint later than one period is a linear segment and is dropped (1.).
3. **New trajectory.** A point whose ``time_from_start`` is smaller than the last reached goal's starts a new
   trajectory: ``move_duration = time_from_start``, no interpolation, sleep then jump.
4. **Durations truncate.** ``Duration(float)`` keeps ``int((x - int(x)) * 1e9)`` nanoseconds (toward zero):
   ``time_from_start`` values given in float seconds, ``update_duration = Duration(1 / update_rate)``, the
   intermediate ``time_from_start`` of ``accelerate()`` (``last + Duration(current_time)``) and float sleeps
   (``rospy.sleep(update_duration.to_sec())`` becomes ``Duration.from_sec``) all lose sub-nanosecond parts.
5. **The grid restarts at every waypoint.** Each segment is cut into ``update_duration`` steps from its own start;
   the remaining ``move_duration`` is recomputed after each step as ``goal.time_from_start -
   intermediate.time_from_start`` and the last step sleeps that remainder, so a segment that is not a multiple of
   10 ms ends with a short update, and a remainder one nanosecond above the period adds a step that leaves a 1 ns
   final sleep (two updates 1 ns apart).
6. **Hermite time in floats.** ``accelerate()`` is evaluated at ``current_time = full_duration -
   move_duration.to_sec() + update_duration.to_sec()`` (float seconds, recomputed from the truncated remainder),
   with the cubic Hermite coefficients ``a1, a2`` exactly as written (correct end conditions: it reaches the goal's
   position and velocity at ``full_duration``). Positions are reproduced bit for bit (CPython ``pow``).
7. **State after the sleep.** ``_move_to`` sleeps first and then sets positions and velocities, so the state of an
   update is the point at the *end* of its step; ``velocities`` is the point's list, empty (NaN here) for a
   waypoint without velocities. The initial velocities are ``[0] * n``.
8. **Publisher.** ``rospy.Timer(Duration(1 / pub_rate))`` fires every ``int(1e9 / (1 / period.to_sec()))`` ns
   after it starts (first call one period after ``pub_offset``); each call copies the state current at that time
   (an update at exactly the same instant is taken as already applied).

``mode="intended"`` is the same controller with its linear branch working: the step state is
``interpolate()``'s point and its velocity is the segment slope ``(goal - start) / duration``; time is exact
integer nanoseconds on the same restarting grid (``k * update_period`` from each segment start, remainder as the
last step), the first segment and a new trajectory are interpolated from the current state over their
``time_from_start`` (linearly, or along the Hermite when both ends carry velocities), and a waypoint without
velocities reports the slope of the segment that reached it (0 after a zero-length move). Positions are continuous
whenever every move lasts longer than one update period. The ``stop``/``sig_stop`` path (a second message while
moving) is not modelled; ``update_rate = 0`` (the seed's "no interpolation" setting) is rejected.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np
import numpy.typing as npt

from taplan.errors import InvalidInputError
from taplan.reference._inputs import WaypointsLike, rate, waypoint_arrays
from taplan.reference._rostime import duration_ns, duration_ns_scalar, py_pow, to_sec, to_sec_scalar
from taplan.reference.replay import JointStateSamples, Replay

__all__ = ["IndustrialSimulator"]

_JUMP, _HERMITE, _LINEAR = 0, 1, 2
_DROP_NOTE = "linear branch computes float / rospy.Duration -> TypeError, caught by _motion_worker"


class IndustrialSimulator:
    """Model of the seed's ``MotionControllerSimulator`` + ``joint_states`` publisher.

    Args:
        update_rate: Motion loop rate [Hz] (``motion_update_rate``), > 0.
        pub_rate: ``joint_states`` publish rate [Hz] (``pub_rate``), > 0.
        mode: ``"seed"`` (bug for bug) or ``"intended"`` (linear branch working, exact time).
        pub_offset: Time of the publish timer's start relative to the first waypoint [s], >= 0.
    """

    def __init__(
        self,
        update_rate: float = 100.0,
        pub_rate: float = 10.0,
        mode: Literal["seed", "intended"] = "seed",
        pub_offset: float = 0.0,
    ) -> None:
        if mode not in ("seed", "intended"):
            raise InvalidInputError("mode", mode, "'seed' or 'intended'")
        self.update_rate = rate(update_rate, "update_rate")
        self.pub_rate = rate(pub_rate, "pub_rate")
        if not (np.isfinite(pub_offset) and pub_offset >= 0):
            raise InvalidInputError("pub_offset", pub_offset, "a time >= 0 [s]")
        self.mode = mode
        self.pub_offset = float(pub_offset)
        self.update_ns = duration_ns_scalar(1.0 / self.update_rate)  # update_duration = rospy.Duration(1./rate)
        if self.update_ns <= 0:
            raise InvalidInputError("update_rate", update_rate, "a rate below 1e9 Hz")
        # rospy.sleep(update_duration.to_sec()) -> Duration.from_sec(float) under simulated time
        self.step_sleep_ns = duration_ns_scalar(to_sec_scalar(self.update_ns)) if mode == "seed" else self.update_ns
        period_ns = duration_ns_scalar(1.0 / self.pub_rate)  # rospy.Timer(rospy.Duration(1.0 / pub_rate))
        if period_ns <= 0:
            raise InvalidInputError("pub_rate", pub_rate, "a rate below 1e9 Hz")
        self.pub_period_ns = int(1e9 / (1.0 / to_sec_scalar(period_ns)))  # Timer -> Rate(1/period).sleep_dur

    def __repr__(self) -> str:
        return f"IndustrialSimulator(update_rate={self.update_rate}, pub_rate={self.pub_rate}, mode={self.mode!r})"

    def replay(
        self,
        waypoints: WaypointsLike,
        initial_positions: npt.ArrayLike | None = None,
        *,
        joint_names: Sequence[str] | None = None,
        hold: float | None = None,
    ) -> Replay:
        """Run the waypoints through the controller.

        Args:
            waypoints: A :class:`~taplan.trajectory.Trajectory` (its stored fields become the points' fields,
                ``time_from_start = t - times[0]``) or a sequence of :class:`~taplan.trajectory.Waypoint`; a
                smaller ``time_from_start`` than the previous point starts a new trajectory.
            initial_positions: State before the first point [rad], shape (n,); default the first point's positions.
            joint_names: Override the names.
            hold: How long ``joint_states`` keeps publishing after the last update [s]; default one publish period.

        Returns:
            The :class:`Replay` with ``times_ns`` (exact) and ``samples`` (``joint_states``).
        """
        w = waypoint_arrays(waypoints, joint_names)
        n = w.n_joints
        q_init = w.positions[0].copy() if initial_positions is None else _vector(initial_positions, n)
        seed = self.mode == "seed"
        u = self.update_ns
        tf_ns = duration_ns(w.times)  # time_from_start as genpy Durations

        # ---- 1. walk the queue: which segments run, which waypoints are dropped (scalar logic, no arrays)
        kinds: list[int] = []
        starts: list[int] = []  # -1 = the initial last_goal_point (initial positions, no velocities)
        goals: list[int] = []
        spans: list[int] = []
        dropped: list[int] = []
        events: list[str] = []
        last = -1
        last_tf = 0
        hv = w.has_velocities.tolist()
        tf_list = tf_ns.tolist()
        for i in range(w.size):
            tf = tf_list[i]
            new_trajectory = tf < last_tf
            span = tf if new_trajectory else tf - last_tf
            if span <= u or (seed and new_trajectory):
                kind = _JUMP
            elif (last >= 0 and hv[last]) and hv[i]:
                kind = _HERMITE
            elif seed:
                dropped.append(i)
                events.append(f"waypoint {i} dropped: {_DROP_NOTE}")
                continue
            else:
                kind = _LINEAR
            if new_trajectory:
                events.append(f"waypoint {i} starts a new trajectory")
            kinds.append(kind)
            starts.append(last)
            goals.append(i)
            spans.append(span)
            last, last_tf = i, tf

        return self._assemble(w, q_init, kinds, starts, goals, spans, dropped, events, hold)

    # ------------------------------------------------------------------------------------------------ internals
    def _assemble(
        self,
        w,  # noqa: ANN001
        q_init: np.ndarray,
        kinds: list[int],
        starts: list[int],
        goals: list[int],
        spans: list[int],
        dropped: list[int],
        events: list[str],
        hold: float | None,
    ) -> Replay:
        n = w.n_joints
        seed = self.mode == "seed"
        u = self.update_ns
        kind = np.array(kinds, dtype=np.int64)
        start = np.array(starts, dtype=np.int64)
        goal = np.array(goals, dtype=np.int64)
        span = np.array(spans, dtype=np.int64)
        S = kind.size
        interp = kind != _JUMP
        steps = np.where(interp, (span - 1) // u, 0)

        # start points of the segments (the initial point has no velocities)
        P_all = np.vstack([w.positions, q_init[None, :]])  # index -1 -> initial
        V_all = np.vstack([w.velocities, np.full((1, n), np.nan)])
        P0, V0 = P_all[start], V_all[start]
        P1, V1 = w.positions[goal], w.velocities[goal]

        # ---- 2. step grid of every interpolated segment, in bulk
        seg_of_row = np.repeat(np.arange(S), steps)
        first_row = np.cumsum(steps) - steps
        k = np.arange(seg_of_row.size) - first_row[seg_of_row] + 1
        T_row = span[seg_of_row]
        if seed:
            full = to_sec(span)  # full_duration = move_duration.to_sec()
            upd_sec = to_sec_scalar(u)
            ct = (full[seg_of_row] - to_sec(T_row - (k - 1) * u)) + upd_sec
            off = duration_ns(ct)
            bad = np.flatnonzero(off != k * u)
            if bad.size:  # float time drifted by a nanosecond somewhere: redo those segments step by step
                ct, steps, seg_of_row = self._exact_grid(span, steps, np.unique(seg_of_row[bad]), ct, seg_of_row)
                first_row = np.cumsum(steps) - steps
                k = np.arange(seg_of_row.size) - first_row[seg_of_row] + 1
                off = duration_ns(ct)
        else:
            off = k * u
            ct = off / 1e9
        rem_after = span - np.where(steps > 0, _last_offset(off, first_row, steps), 0)

        # ---- 3. one row per update: each segment's steps, then its final move (the goal point itself)
        count = steps + 1
        E = int(count.sum())
        seg_first_event = np.cumsum(count) - count
        final_event = seg_first_event + steps
        seg_of_event = np.repeat(np.arange(S), count)
        is_step = np.ones(E, dtype=bool)
        is_step[final_event] = False
        ct_event = np.zeros(E)
        ct_event[is_step] = ct
        off_event = np.zeros(E, dtype=np.int64)
        off_event[is_step] = off
        positions = np.empty((E, n))
        velocities = np.empty((E, n))
        if (kind == _HERMITE).any():
            self._hermite_rows(kind, span, P0, P1, V0, V1, seg_of_event, ct_event, positions, velocities, seed)
        if (kind == _LINEAR).any():
            rows = np.flatnonzero(kind[seg_of_event] == _LINEAR)
            s_l = seg_of_event[rows]
            d = P1[s_l] - P0[s_l]
            positions[rows] = P0[s_l] + (off_event[rows] / span[s_l])[:, None] * d
            velocities[rows] = d / (span[s_l] / 1e9)[:, None]
        positions[final_event] = P1
        v_final = V1.copy()
        if not seed:
            no_v = ~w.has_velocities[goal]
            if no_v.any():
                # the slope of the segment that reached the point, also when it took a single update (a jump
                # over a move shorter than one period); 0 only after a zero-length move
                slope = np.where((span > 0)[:, None], (P1 - P0) / np.maximum(span, 1)[:, None] * 1e9, 0.0)
                v_final[no_v] = slope[no_v]
        velocities[final_event] = v_final
        sleeps = np.full(E, self.step_sleep_ns, dtype=np.int64)
        sleeps[final_event] = np.where(interp, rem_after, span)
        times_ns = np.cumsum(sleeps)
        times = times_ns / 1e9

        jumps = final_event[kind == _JUMP]
        replay_samples = self._samples(times_ns, positions, velocities, q_init, hold, w.joint_names)
        return Replay(
            controller=f"industrial_simulator[{self.mode}]",
            joint_names=w.joint_names,
            times=times,
            positions=positions,
            velocities=velocities,
            accelerations=None,
            rate=self.update_rate,
            initial_positions=q_init,
            initial_velocities=np.zeros(n),
            waypoint_indices=goal,
            waypoint_times=times[final_event] if E else np.zeros(0),
            dropped=tuple(dropped),
            jumps=jumps,
            samples=replay_samples,
            times_ns=times_ns,
            events=tuple(events),
        )

    @staticmethod
    def _hermite_rows(
        kind: np.ndarray,
        span: np.ndarray,
        P0: np.ndarray,
        P1: np.ndarray,
        V0: np.ndarray,
        V1: np.ndarray,
        seg_of_event: np.ndarray,
        ct_event: np.ndarray,
        positions: np.ndarray,
        velocities: np.ndarray,
        seed: bool,
    ) -> None:
        """``accelerate()`` on every row of Hermite segments (rows of other segments are overwritten later)."""
        dt = to_sec(span) if seed else span / 1e9
        dt = np.where(kind == _HERMITE, dt, 1.0)
        dt2 = py_pow(dt, 2)[:, None] if seed else (dt * dt)[:, None]
        dt3 = py_pow(dt, 3)[:, None] if seed else (dt * dt * dt)[:, None]
        dtc = dt[:, None]
        herm = (kind == _HERMITE)[:, None]
        x0 = P0
        v0 = np.where(herm, V0, 0.0)
        v1 = np.where(herm, V1, 0.0)
        delta_x = P1 - x0
        dv = v1 + v0
        a1 = 6 * delta_x / dt2 - 2 * (dv + v0) / dtc
        a2 = -12 * delta_x / dt3 + 6 * dv / dt2
        if seed:  # the seed's expression order, CPython pow: bit for bit
            c = ct_event[:, None]
            c2 = py_pow(ct_event, 2)[:, None]
            c3 = py_pow(ct_event, 3)[:, None]
            x0r, v0r, a1r, a2r = x0[seg_of_event], v0[seg_of_event], a1[seg_of_event], a2[seg_of_event]
            np.add(x0r + v0r * c + a1r * c2 / 2, a2r * c3 / 6, out=positions)
            np.add(v0r + a1r * c, a2r * c2 / 2, out=velocities)
        else:  # Horner form
            c = ct_event[:, None]
            h1, h2 = (a1 / 2)[seg_of_event], (a2 / 6)[seg_of_event]
            v0r = v0[seg_of_event]
            np.add(x0[seg_of_event], c * (v0r + c * (h1 + c * h2)), out=positions)
            np.add(v0r, c * (2 * h1 + c * (3 * h2)), out=velocities)

    def _exact_grid(
        self, span: np.ndarray, steps: np.ndarray, redo: np.ndarray, ct: np.ndarray, seg_of_row: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The seed's loop, literally, for the segments in ``redo``; returns the new (ct, steps, seg_of_row)."""
        u = self.update_ns
        upd_sec = to_sec_scalar(u)
        pieces: list[np.ndarray] = []
        new_steps = steps.copy()
        first_row = np.cumsum(steps) - steps
        redo_set = set(redo.tolist())
        for sgm in range(span.size):
            if sgm not in redo_set:
                pieces.append(ct[first_row[sgm] : first_row[sgm] + steps[sgm]])
                continue
            total = int(span[sgm])
            full = to_sec_scalar(total)
            remaining = total
            values = []
            while u < remaining:
                current_time = full - to_sec_scalar(remaining) + upd_sec
                values.append(current_time)
                remaining = total - duration_ns_scalar(current_time)
            pieces.append(np.array(values, dtype=float))
            new_steps[sgm] = len(values)
        new_ct = np.concatenate(pieces) if pieces else np.zeros(0)
        return new_ct, new_steps, np.repeat(np.arange(span.size), new_steps)

    def _samples(
        self,
        times_ns: np.ndarray,
        positions: np.ndarray,
        velocities: np.ndarray,
        q_init: np.ndarray,
        hold: float | None,
        names: tuple[str, ...],
    ) -> JointStateSamples:
        period = self.pub_period_ns
        hold_ns = period if hold is None else int(duration_ns_scalar(float(hold)))
        if hold_ns < 0:
            raise InvalidInputError("hold", hold, "a time >= 0 [s]")
        offset = duration_ns_scalar(self.pub_offset)
        end = (int(times_ns[-1]) if times_ns.size else 0) + hold_ns
        count = max(0, (end - offset) // period)
        pub_ns = offset + period * np.arange(1, count + 1, dtype=np.int64)
        idx = np.searchsorted(times_ns, pub_ns, side="right") - 1
        n = q_init.size
        before = idx < 0
        q = positions[np.maximum(idx, 0)] if positions.size else np.empty((pub_ns.size, n))
        v = velocities[np.maximum(idx, 0)] if velocities.size else np.empty((pub_ns.size, n))
        if before.any():
            q[before] = q_init
            v[before] = 0.0
        return JointStateSamples(pub_ns / 1e9, q, v, self.pub_rate, pub_ns, names)


def _last_offset(off: np.ndarray, first_row: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Offset of each segment's last step (0 where a segment has no steps)."""
    idx = np.maximum(first_row + steps - 1, 0)
    return off[idx] if off.size else np.zeros_like(steps)


def _vector(value: npt.ArrayLike, n: int) -> np.ndarray:
    from taplan._validation import as_vector

    return as_vector(value, "initial_positions", n).copy()
