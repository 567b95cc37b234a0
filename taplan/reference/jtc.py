"""ros2_control ``joint_trajectory_controller`` (Humble) as a reference model.

At every update (``update_rate``, ticks at ``k / update_rate`` from t = 0) the controller samples its active
trajectory (``joint_trajectory_controller/src/trajectory.cpp``, Humble):

* **Interpolation by fields present** on *both* ends of a segment: positions only -> linear (velocity = slope,
  acceleration 0); positions + velocities -> cubic Hermite; positions + velocities + accelerations -> quintic
  Hermite. (Accelerations without velocities on both ends match none of Humble's branches and output zeros; the
  model reproduces that.) ``interpolation="none"`` forwards the *next* waypoint as the command (and the state
  before the trajectory until its first point is due).
* **First segment from the current state.** A goal (``header.stamp`` zero) starts at the first update at or after
  its arrival; that update stores the current state (positions and velocities, as read from an ideal position/
  velocity interface: the previous command) as the point before the trajectory, so the first segment runs from the
  current state to the first point. A first point with ``time_from_start = 0`` is commanded immediately (a jump if
  it differs from the current state).
* **A new goal replaces the old one** from the current state at its first update; the old goal's remaining points
  are never reached (listed in ``events``).
* **After the last point** the last point is held, with its velocities/accelerations (zero when absent).

Float ``time_from_start`` values are rounded to whole nanoseconds (``builtin_interfaces/Duration``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np
import numpy.typing as npt

from taplan._validation import as_vector
from taplan.errors import InvalidInputError
from taplan.reference._inputs import WaypointArrays, WaypointsLike, rate, waypoint_arrays
from taplan.reference.replay import Replay

__all__ = ["JointTrajectoryController"]

_LIN, _CUBIC, _QUINTIC, _ZERO = 0, 1, 2, 3


class JointTrajectoryController:
    """Model of ros2_control's JointTrajectoryController (Humble).

    Args:
        update_rate: Controller update rate [Hz].
        interpolation: ``"splines"`` (default) or ``"none"``.
    """

    def __init__(self, update_rate: float = 100.0, interpolation: Literal["splines", "none"] = "splines") -> None:
        if interpolation not in ("splines", "none"):
            raise InvalidInputError("interpolation", interpolation, "'splines' or 'none'")
        self.update_rate = rate(update_rate, "update_rate")
        self.period_ns = int(round(1e9 / self.update_rate))
        if self.period_ns <= 0:
            raise InvalidInputError("update_rate", update_rate, "a rate below 1e9 Hz")
        self.interpolation = interpolation

    def __repr__(self) -> str:
        return f"JointTrajectoryController(update_rate={self.update_rate}, interpolation={self.interpolation!r})"

    def replay(
        self,
        goals: WaypointsLike | Sequence[tuple[float, WaypointsLike]],
        initial_positions: npt.ArrayLike | None = None,
        initial_velocities: npt.ArrayLike | None = None,
        *,
        joint_names: Sequence[str] | None = None,
        hold: float | None = None,
    ) -> Replay:
        """Command stream of the controller.

        Args:
            goals: One trajectory (received at t = 0), or ``[(arrival_time, trajectory), ...]`` with increasing
                arrival times [s]; each trajectory is a :class:`~taplan.trajectory.Trajectory` or a sequence of
                :class:`~taplan.trajectory.Waypoint`.
            initial_positions: State before the first goal [rad], shape (n,); default the first point's.
            initial_velocities: [rad]/[s], shape (n,); default zeros.
            joint_names: Override the names.
            hold: Time to keep updating after the last point [s]; default one update period.

        Returns:
            The :class:`Replay` of the commanded positions, velocities and accelerations at every update.
        """
        pairs = _goal_list(goals)
        arrays = [waypoint_arrays(g, joint_names) for _, g in pairs]
        n = arrays[0].n_joints
        names = arrays[0].joint_names
        for k, w in enumerate(arrays):
            if w.n_joints != n:
                raise InvalidInputError(f"goals[{k}]", f"{w.n_joints} joints", f"{n} joints like goals[0]")
        q0 = (
            arrays[0].positions[0].copy()
            if initial_positions is None
            else as_vector(initial_positions, "initial_positions", n)
        )
        v0 = np.zeros(n) if initial_velocities is None else as_vector(initial_velocities, "initial_velocities", n)
        P = self.period_ns
        arrival_ns = [int(np.ceil(round(t * 1e9) / P)) * P for t, _ in pairs]
        end_ns = arrival_ns[-1] + int(np.round(arrays[-1].times[-1] * 1e9))
        hold_ns = P if hold is None else int(round(float(hold) * 1e9))
        ticks = np.arange(0, end_ns + hold_ns + 1, P, dtype=np.int64)
        E = ticks.size
        pos = np.empty((E, n))
        vel = np.empty((E, n))
        acc = np.empty((E, n))
        before = ticks < arrival_ns[0]
        pos[before], vel[before], acc[before] = q0, v0, 0.0
        events: list[str] = []
        wp_idx: list[int] = []
        wp_times: list[float] = []
        offset = 0
        for g, w in enumerate(arrays):
            start = arrival_ns[g]
            stop = arrival_ns[g + 1] if g + 1 < len(arrays) else ticks[-1] + 1
            rows = np.flatnonzero((ticks >= start) & (ticks < stop))
            k0 = int(rows[0]) if rows.size else E
            if k0 > 0:  # current state = the previous command (ideal interfaces)
                cur_q, cur_v = pos[k0 - 1].copy(), vel[k0 - 1].copy()
            else:
                cur_q, cur_v = q0, v0
            point_ns = start + np.round(w.times * 1e9).astype(np.int64)
            if rows.size:
                self._sample(w, start, point_ns, cur_q, cur_v, ticks[rows], pos, vel, acc, rows)
            reached = point_ns < stop
            for i in np.flatnonzero(reached):
                wp_idx.append(offset + int(i))
                wp_times.append(point_ns[i] / 1e9)
            if not reached.all():
                events.append(f"goal {g}: points {np.flatnonzero(~reached).tolist()} pre-empted by goal {g + 1}")
            offset += w.size
        return Replay(
            controller=f"jtc[{self.interpolation}]",
            joint_names=names,
            times=ticks / 1e9,
            positions=pos,
            velocities=vel,
            accelerations=acc,
            rate=self.update_rate,
            initial_positions=q0.copy(),
            initial_velocities=v0.copy(),
            waypoint_indices=np.array(wp_idx, dtype=int),
            waypoint_times=np.array(wp_times),
            times_ns=ticks,
            events=tuple(events),
        )

    def _sample(
        self,
        w: WaypointArrays,
        start: int,
        point_ns: np.ndarray,
        cur_q: np.ndarray,
        cur_v: np.ndarray,
        t: np.ndarray,
        pos: np.ndarray,
        vel: np.ndarray,
        acc: np.ndarray,
        rows: np.ndarray,
    ) -> None:
        n = w.n_joints
        # knots: the state before the trajectory (positions + velocities, no accelerations), then the points
        kt = np.concatenate([[start], point_ns])
        kq = np.vstack([cur_q, w.positions])
        kv = np.vstack([cur_v, w.velocities])
        ka = np.vstack([np.full(n, np.nan), w.accelerations])
        hv = np.concatenate([[True], w.has_velocities])
        ha = np.concatenate([[False], w.has_accelerations])
        seg = np.searchsorted(kt, t, side="right") - 1  # >= 0 since t >= start
        last = kt.size - 1
        done = seg >= last
        active = ~done
        if done.any():
            r = rows[done]
            pos[r] = kq[last]
            vel[r] = kv[last] if hv[last] else 0.0
            acc[r] = ka[last] if ha[last] else 0.0
        if not active.any():
            return
        r = rows[active]
        s = seg[active]
        if self.interpolation == "none":
            nxt = np.where(s == 0, 0, s + 1)  # before the first point: the state before; else the next point
            pos[r] = kq[nxt]
            vel[r] = np.where(hv[nxt][:, None], kv[nxt], np.nan)
            acc[r] = np.where(ha[nxt][:, None], ka[nxt], np.nan)
            return
        coeffs, kinds = _coefficients(kt, kq, kv, ka, hv, ha)
        c = coeffs[s]  # (m, 6, n)
        tau = ((t[active] - kt[s]) / 1e9)[:, None]
        pos[r] = c[:, 0] + tau * (c[:, 1] + tau * (c[:, 2] + tau * (c[:, 3] + tau * (c[:, 4] + tau * c[:, 5]))))
        vel[r] = c[:, 1] + tau * (2 * c[:, 2] + tau * (3 * c[:, 3] + tau * (4 * c[:, 4] + tau * 5 * c[:, 5])))
        acc[r] = 2 * c[:, 2] + tau * (6 * c[:, 3] + tau * (12 * c[:, 4] + tau * 20 * c[:, 5]))


def _coefficients(
    kt: np.ndarray, kq: np.ndarray, kv: np.ndarray, ka: np.ndarray, hv: np.ndarray, ha: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Polynomial coefficients (S, 6, n) in powers of (t - t_k) [s], chosen per segment by the fields present."""
    S = kt.size - 1
    n = kq.shape[1]
    h = (np.diff(kt) / 1e9)[:, None]
    both_v = hv[:-1] & hv[1:]
    both_a = ha[:-1] & ha[1:]
    kinds = np.where(both_v & both_a, _QUINTIC, np.where(both_v, _CUBIC, np.where(both_a, _ZERO, _LIN)))
    c = np.zeros((S, 6, n))
    q0, q1 = kq[:-1], kq[1:]
    dq = q1 - q0
    hz = np.where(h > 0, h, 1.0)
    nonzero = (h > 0)[:, 0]
    lin = kinds == _LIN
    c[lin, 0] = q0[lin]
    c[lin & nonzero, 1] = (dq / hz)[lin & nonzero]
    cub = kinds == _CUBIC
    if cub.any():
        v0, v1 = kv[:-1], kv[1:]
        c[cub, 0] = q0[cub]
        c[cub, 1] = v0[cub]
        m = cub & nonzero
        c[m, 2] = ((3 * dq - (2 * v0 + v1) * hz) / hz**2)[m]
        c[m, 3] = ((-2 * dq + (v0 + v1) * hz) / hz**3)[m]
    qui = kinds == _QUINTIC
    if qui.any():
        v0, v1, a0, a1 = kv[:-1], kv[1:], ka[:-1], ka[1:]
        c[qui, 0] = q0[qui]
        c[qui, 1] = v0[qui]
        c[qui, 2] = (a0 / 2)[qui]
        m = qui & nonzero
        c[m, 3] = ((20 * dq - (8 * v1 + 12 * v0) * hz - (3 * a0 - a1) * hz**2) / (2 * hz**3))[m]
        c[m, 4] = ((-30 * dq + (14 * v1 + 16 * v0) * hz + (3 * a0 - 2 * a1) * hz**2) / (2 * hz**4))[m]
        c[m, 5] = ((12 * dq - 6 * (v1 + v0) * hz + (a1 - a0) * hz**2) / (2 * hz**5))[m]
    return c, kinds


def _goal_list(goals: object) -> list[tuple[float, WaypointsLike]]:
    from taplan.trajectory import Trajectory, Waypoint

    if isinstance(goals, Trajectory):
        return [(0.0, goals)]
    items = list(goals)  # type: ignore[call-overload]
    if not items:
        raise InvalidInputError("goals", "an empty sequence", "a trajectory or (arrival_time, trajectory) pairs")
    if isinstance(items[0], Waypoint):
        return [(0.0, items)]  # type: ignore[list-item]
    out: list[tuple[float, WaypointsLike]] = []
    last = -np.inf
    for k, item in enumerate(items):
        if not (isinstance(item, tuple) and len(item) == 2):
            raise InvalidInputError(f"goals[{k}]", item, "(arrival_time [s], trajectory)")
        t = float(item[0])
        if not np.isfinite(t) or t < 0 or t <= last:
            raise InvalidInputError(f"goals[{k}][0]", item[0], "finite arrival times >= 0, strictly increasing")
        last = t
        out.append((t, item[1]))
    return out
