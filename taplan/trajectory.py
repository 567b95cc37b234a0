"""Time-parameterised joint trajectories.

A :class:`Trajectory` holds samples ``times`` (N,), ``positions`` (N, n) and optionally ``velocities`` and
``accelerations`` (N, n) for named joints. Between samples it is the piecewise polynomial the samples define:

* positions only: linear (velocity steps at the samples, as a linear interpolator sends them);
* positions and velocities: cubic Hermite (continuous velocity);
* positions, velocities and accelerations: quintic Hermite (continuous acceleration);
* built with :meth:`Trajectory.from_polynomials`: any piecewise polynomial in time (e.g. the exact output of TOPP-RA,
  whose acceleration steps at its gridpoints); ``positions``/``velocities``/``accelerations`` then hold the values
  at the sample times (right-hand limits).

Outside ``[times[0], times[-1]]`` evaluation returns the boundary sample (held), as a controller holds its last
point. Files: CSV (``time`` then ``<joint>.pos``/``.vel``/``.acc`` columns), JSON, and NPZ (loaded without pickle).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from math import factorial
from pathlib import Path

import numpy as np
import numpy.typing as npt

from taplan._validation import as_positive
from taplan.errors import InvalidInputError

__all__ = ["Trajectory", "Waypoint", "concatenate"]

_TIME_TOL = 1e-12  # [s]


MAX_SAMPLES = 2e6  # samples of one uniform grid (33 min at 1 kHz; 0.9 GB for 14 joints x 4 derivatives)


@dataclass(frozen=True)
class Waypoint:
    """A trajectory point as a controller receives it (``trajectory_msgs/JointTrajectoryPoint``).

    Attributes:
        time_from_start: [s].
        positions: [rad], shape (n,).
        velocities: [rad]/[s], shape (n,), or None when the point carries none.
        accelerations: [rad]/[s]², shape (n,), or None.
    """

    time_from_start: float
    positions: np.ndarray
    velocities: np.ndarray | None = None
    accelerations: np.ndarray | None = None


class Trajectory:
    """Joint trajectory over time.

    Args:
        times: Sample times [s], strictly increasing, shape (N,), N >= 2.
        positions: [rad], shape (N, n).
        velocities: [rad]/[s], shape (N, n), or None.
        accelerations: [rad]/[s]², shape (N, n), or None (needs velocities).
        joint_names: n names; default ``joint0..``.
    """

    def __init__(
        self,
        times: npt.ArrayLike,
        positions: npt.ArrayLike,
        velocities: npt.ArrayLike | None = None,
        accelerations: npt.ArrayLike | None = None,
        joint_names: Sequence[str] | None = None,
    ) -> None:
        t = _finite(times, "times", ndim=1)
        if t.shape[0] < 2:
            raise InvalidInputError("times", t, "at least 2 samples")
        steps = np.diff(t)
        if np.any(steps <= _TIME_TOL):
            k = int(np.argmax(steps <= _TIME_TOL))
            raise InvalidInputError(
                "times", f"times[{k}]={t[k]!r}, times[{k + 1}]={t[k + 1]!r}", "strictly increasing sample times"
            )
        q = _finite(positions, "positions", ndim=2)
        if q.shape[0] != t.shape[0]:
            raise InvalidInputError("positions", f"shape {q.shape}", f"({t.shape[0]}, n): one row per time")
        v = None if velocities is None else _finite(velocities, "velocities", ndim=2)
        a = None if accelerations is None else _finite(accelerations, "accelerations", ndim=2)
        for name, arr in (("velocities", v), ("accelerations", a)):
            if arr is not None and arr.shape != q.shape:
                raise InvalidInputError(name, f"shape {arr.shape}", f"shape {q.shape}, like positions")
        if a is not None and v is None:
            raise InvalidInputError("accelerations", "given without velocities", "velocities as well")
        self._set_samples(t, q, v, a, joint_names)
        self._coefficients = _segment_coefficients(t, q, v, a)  # (N-1, d+1, n), powers of (t - t_k)
        self._polynomial = False
        self._derived: dict[int, np.ndarray] = {}

    def _set_samples(
        self,
        t: np.ndarray,
        q: np.ndarray,
        v: np.ndarray | None,
        a: np.ndarray | None,
        joint_names: Sequence[str] | None,
    ) -> None:
        """Store validated samples (read-only) and the joint names (checked)."""
        n = q.shape[1]
        names = tuple(joint_names) if joint_names is not None else tuple(f"joint{i}" for i in range(n))
        if len(names) != n or len(set(names)) != n:
            raise InvalidInputError("joint_names", names, f"{n} unique names")
        for arr in (t, q, v, a):
            if arr is not None:
                arr.setflags(write=False)
        self.times, self.positions, self.velocities, self.accelerations = t, q, v, a
        self.joint_names: tuple[str, ...] = tuple(str(x) for x in names)

    @classmethod
    def from_polynomials(
        cls,
        times: npt.ArrayLike,
        coefficients: npt.ArrayLike,
        joint_names: Sequence[str] | None = None,
        *,
        continuity_tol: float = 1e-6,
        continuous_velocity: bool = True,
    ) -> Trajectory:
        """A piecewise polynomial trajectory.

        Args:
            times: Breakpoints [s], strictly increasing, shape (N,).
            coefficients: Shape (N-1, d+1, n): segment k is ``sum_i coefficients[k, i] * (t - times[k])**i``.
            joint_names: n names; default ``joint0..``.
            continuity_tol: Largest position [rad] and velocity [rad]/[s] jump allowed between segments.
            continuous_velocity: Check velocity continuity too (False for linear interpolation).

        Raises:
            InvalidInputError: bad shapes, non-finite values, or a position/velocity jump above ``continuity_tol``.
        """
        t = _finite(times, "times", ndim=1)
        c = _finite(coefficients, "coefficients", ndim=3)
        if t.shape[0] < 2 or c.shape[0] != t.shape[0] - 1 or c.shape[1] < 1:
            raise InvalidInputError("coefficients", f"shape {c.shape}", f"({t.shape[0] - 1}, d+1, n), one per segment")
        if c.shape[1] < 4:
            c = np.concatenate([c, np.zeros((c.shape[0], 4 - c.shape[1], c.shape[2]))], axis=1)
        h = np.diff(t)
        if np.any(h <= _TIME_TOL):
            raise InvalidInputError("times", t, "strictly increasing sample times")
        ends = [_polyval(c, h, order) for order in (0, 1, 2)]  # (N-1, n) values at each segment's end
        starts = [c[:, order] * factorial(order) for order in (0, 1, 2)]  # the same at each segment's start
        checks = ((0, "position"), (1, "velocity")) if continuous_velocity else ((0, "position"),)
        for order, name in checks:
            jump = np.abs(ends[order][:-1] - starts[order][1:]) if len(h) > 1 else None
            if jump is not None and jump.size and float(np.max(jump)) > continuity_tol:
                k = int(np.argmax(np.max(jump, axis=1)))
                raise InvalidInputError(
                    "coefficients", f"{name} jump {float(np.max(jump[k])):.3g} at times[{k + 1}]", "continuous segments"
                )
        q, v, a = (np.vstack([starts[o], ends[o][-1:]]) for o in (0, 1, 2))
        traj = cls.__new__(cls)  # times and coefficients are validated: skip __init__'s Hermite coefficients
        traj._set_samples(t, q, v, a, joint_names)
        c.setflags(write=False)
        traj._coefficients = c
        traj._polynomial = True
        traj._derived = {}
        return traj

    # ------------------------------------------------------------------------------------------------ properties
    @property
    def duration(self) -> float:
        """``times[-1] - times[0]`` [s]."""
        return float(self.times[-1] - self.times[0])

    @property
    def n_joints(self) -> int:
        return int(self.positions.shape[1])

    @property
    def interpolation(self) -> str:
        """``"linear"``, ``"cubic"``, ``"quintic"`` (from the fields present) or ``"polynomial"``."""
        if self._polynomial:
            return "polynomial"
        if self.velocities is None:
            return "linear"
        return "cubic" if self.accelerations is None else "quintic"

    def __len__(self) -> int:
        return int(self.times.shape[0])

    def __repr__(self) -> str:
        return (
            f"Trajectory(samples={len(self)}, joints={self.n_joints}, duration={self.duration:.4f} s, "
            f"{self.interpolation})"
        )

    # ------------------------------------------------------------------------------------------------ evaluation
    def __call__(self, t: npt.ArrayLike, order: int = 0) -> np.ndarray:
        """Evaluate at time(s) ``t`` [s]: position (order 0), velocity (1), acceleration (2) or jerk (3).

        Returns shape (n,) for a scalar ``t``, (len(t), n) for an array.
        """
        if order not in (0, 1, 2, 3):
            raise InvalidInputError("order", order, "0, 1, 2 or 3")
        t_arr = np.asarray(t, dtype=float)
        if not np.all(np.isfinite(t_arr)):
            raise InvalidInputError("t", t, "finite times")
        flat = np.atleast_1d(t_arr).ravel()
        tc = np.clip(flat, self.times[0], self.times[-1])
        k = np.clip(np.searchsorted(self.times, tc, side="right") - 1, 0, len(self.times) - 2)
        tau = (tc - self.times[k])[:, None]
        c = self.derivative_coefficients(order)[k]  # (m, d+1-order, n)
        out = c[:, -1] * np.ones_like(tau)
        for i in range(c.shape[1] - 2, -1, -1):
            out = c[:, i] + tau * out
        outside = (flat < self.times[0]) | (flat > self.times[-1])
        if order > 0 and np.any(outside):  # held ends: report the boundary samples' own derivatives
            ends = self._boundary(order)
            out[flat < self.times[0]] = ends[0]
            out[flat > self.times[-1]] = ends[1]
        return out[0] if t_arr.ndim == 0 else out.reshape(*t_arr.shape, self.n_joints)

    @property
    def coefficients(self) -> np.ndarray:
        """Segment polynomials, shape (N-1, d+1, n): ``sum_i c[k, i] (t - times[k])**i`` on segment k."""
        return self._coefficients

    def derivative_coefficients(self, order: int) -> np.ndarray:
        """Coefficients of the ``order``-th time derivative, shape (N-1, max(d+1-order, 1), n)."""
        if order == 0:
            return self._coefficients
        if order not in self._derived:
            self._derived[order] = _derivative(self._coefficients, order)
        return self._derived[order]

    def _boundary(self, order: int) -> tuple[np.ndarray, np.ndarray]:
        zero = np.zeros(self.n_joints)
        field = {1: self.velocities, 2: self.accelerations}.get(order)
        if field is None:
            return zero, zero
        return field[0], field[-1]

    def sample(self, rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Uniform samples at ``rate`` [Hz] from ``times[0]``, the end time included.

        Returns:
            (times (m,), positions, velocities, accelerations (m, n)).
        """
        t = self.sample_times(rate)
        return t, self(t, 0), self(t, 1), self(t, 2)

    def sample_times(self, rate: float) -> np.ndarray:
        """Times ``times[0] + k / rate`` up to the end, plus the end time when it is not on the grid [s]."""
        rate = as_positive(rate, "rate")
        samples = self.duration * rate
        if not samples <= MAX_SAMPLES:  # a duration of years at 1 kHz would exhaust the memory
            raise InvalidInputError(
                "rate",
                f"{rate:g} Hz over {self.duration:.6g} s",
                f"at most {MAX_SAMPLES:.0e} samples (duration x rate)",
            )
        count = int(np.floor(samples + 1e-9))
        t = self.times[0] + np.arange(count + 1) / rate
        if self.times[-1] - t[-1] > 1e-9:
            t = np.append(t, self.times[-1])
        return t

    def resample(self, rate: float) -> Trajectory:
        """A quintic trajectory sampled at ``rate`` [Hz] (positions, velocities and accelerations)."""
        t, q, v, a = self.sample(rate)
        return Trajectory(t, q, v, a, self.joint_names)

    def waypoints(self, *, velocities: bool = True, accelerations: bool = False) -> list[Waypoint]:
        """The samples as controller waypoints, ``time_from_start`` measured from ``times[0]``.

        Args:
            velocities: Include velocities (evaluated from the interpolant when not stored).
            accelerations: Include accelerations (likewise).
        """
        v = self(self.times, 1) if velocities else None
        a = self(self.times, 2) if accelerations else None
        return [
            Waypoint(
                float(t - self.times[0]),
                self.positions[i].copy(),
                None if v is None else v[i].copy(),
                None if a is None else a[i].copy(),
            )
            for i, t in enumerate(self.times)
        ]

    @classmethod
    def from_waypoints(cls, waypoints: Sequence[Waypoint], joint_names: Sequence[str] | None = None) -> Trajectory:
        """Build from waypoints; velocities/accelerations are kept only when every waypoint has them."""
        if len(waypoints) < 2:
            raise InvalidInputError("waypoints", len(waypoints), "at least 2 waypoints")
        t = [w.time_from_start for w in waypoints]
        q = [w.positions for w in waypoints]
        v = [w.velocities for w in waypoints]
        a = [w.accelerations for w in waypoints]
        vel = None if any(x is None for x in v) else v
        acc = None if vel is None or any(x is None for x in a) else a
        return cls(t, q, vel, acc, joint_names)

    def select(self, joint_names: Sequence[str]) -> Trajectory:
        """The same trajectory restricted to (and ordered by) ``joint_names``."""
        lookup = {n: i for i, n in enumerate(self.joint_names)}
        missing = [n for n in joint_names if n not in lookup]
        if missing:
            from taplan.errors import UnknownNameError

            raise UnknownNameError("joint", missing[0], self.joint_names)
        idx = [lookup[n] for n in joint_names]
        if self._polynomial:
            return Trajectory.from_polynomials(
                self.times, self._coefficients[:, :, idx], joint_names, continuous_velocity=False
            )
        pick = lambda arr: None if arr is None else arr[:, idx]  # noqa: E731
        return Trajectory(
            self.times, self.positions[:, idx], pick(self.velocities), pick(self.accelerations), joint_names
        )

    def stretched(self, factor: float) -> Trajectory:
        """The same path ``factor`` times slower (> 1) or faster (< 1), from the same start time.

        Velocities scale by 1/factor, accelerations by 1/factor², jerks by 1/factor³, so ``factor >= 1`` keeps a
        trajectory that respects limits within them. Exact: the result is a polynomial trajectory.
        """
        factor = as_positive(factor, "factor")
        c = self.coefficients
        scale = factor ** -np.arange(c.shape[1], dtype=float)
        t0 = self.times[0]
        return Trajectory.from_polynomials(
            t0 + (self.times - t0) * factor, c * scale[None, :, None], self.joint_names, continuous_velocity=False
        )

    def shifted(self, offset: float) -> Trajectory:
        """The same trajectory with ``offset`` [s] added to every time."""
        if self._polynomial:
            return Trajectory.from_polynomials(
                self.times + offset, self._coefficients, self.joint_names, continuous_velocity=False
            )
        return Trajectory(self.times + offset, self.positions, self.velocities, self.accelerations, self.joint_names)

    # ------------------------------------------------------------------------------------------------------- I/O
    def to_dict(self) -> dict[str, object]:
        out: dict[str, object] = {
            "joint_names": list(self.joint_names),
            "times": self.times.tolist(),
            "positions": self.positions.tolist(),
        }
        if self.velocities is not None:
            out["velocities"] = self.velocities.tolist()
        if self.accelerations is not None:
            out["accelerations"] = self.accelerations.tolist()
        if self._polynomial:
            out["coefficients"] = self._coefficients.tolist()
        return out

    @classmethod
    def from_dict(cls, data: dict[str, object], *, joint_names: Sequence[str] | None = None) -> Trajectory:
        """Inverse of :meth:`to_dict`, validated by the trajectory-file contract (:mod:`taplan.io`).

        A ``coefficients`` entry makes a polynomial trajectory; samples given beside it must agree with it.
        """
        from taplan.io.trajectory_file import build_trajectory

        if not isinstance(data, dict):
            raise InvalidInputError("data", type(data).__name__, "a dict with 'joint_names', 'times', 'positions'")
        return build_trajectory(data, joint_names, source="data")

    def save(self, path: str | Path) -> Path:
        """Write to ``.csv``, ``.json`` or ``.npz`` (by suffix), exactly in every format; returns the path.

        See :mod:`taplan.io.trajectory_file` for the layouts; a polynomial trajectory keeps its coefficients.
        """
        from taplan.io import save_trajectory

        return save_trajectory(self, path)

    @classmethod
    def load(cls, path: str | Path, joint_names: Sequence[str] | None = None) -> Trajectory:
        """Read and validate a trajectory file (:func:`taplan.io.load_trajectory`).

        Args:
            path: ``.json``, ``.csv`` or ``.npz``.
            joint_names: The robot's joints; when given, every joint in the file must be one of them.
        """
        from taplan.io import load_trajectory

        return load_trajectory(path, joint_names)


def _finite(value: npt.ArrayLike, name: str, ndim: int) -> np.ndarray:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidInputError(name, value, "a numeric array") from None
    if array.ndim != ndim:
        raise InvalidInputError(name, f"array of shape {array.shape}", f"a {ndim}-D array")
    if not np.all(np.isfinite(array)):
        raise InvalidInputError(name, "values with NaN or inf", "finite values")
    return array


def _polyval(c: np.ndarray, tau: np.ndarray, order: int) -> np.ndarray:
    """Evaluate the ``order``-th derivative of per-segment polynomials ``c`` (m, d+1, n) at ``tau`` (m,)."""
    d = _derivative(c, order) if order else c
    out = d[:, -1].copy()
    for i in range(d.shape[1] - 2, -1, -1):
        out = d[:, i] + tau[:, None] * out
    return out


def _derivative(c: np.ndarray, order: int) -> np.ndarray:
    """Coefficients of the ``order``-th derivative of ``c`` (m, d+1, n) in the same power basis."""
    degree = c.shape[1] - 1
    if order > degree:
        return np.zeros((c.shape[0], 1, c.shape[2]))
    k = np.arange(order, degree + 1)
    factor = np.ones(k.shape)
    for j in range(order):
        factor = factor * (k - j)
    return c[:, order:] * factor[None, :, None]


def concatenate(trajectories: Sequence[Trajectory], *, continuity_tol: float = 1e-6) -> Trajectory:
    """Join trajectories end to start into one (each later one is shifted to start where the previous ends).

    Args:
        trajectories: At least one trajectory, same joint names; each starts at the previous one's final position
            and velocity (within ``continuity_tol``).
        continuity_tol: Largest position [rad] / velocity [rad]/[s] jump allowed at a junction.

    Returns:
        A polynomial trajectory (exact: every piece keeps its own polynomials).
    """
    if len(trajectories) == 0:
        raise InvalidInputError("trajectories", 0, "at least one trajectory")
    first = trajectories[0]
    times = [first.times]
    coefficients = [first.coefficients]
    degree = max(tr.coefficients.shape[1] for tr in trajectories)
    end = first.times[-1]
    for i, tr in enumerate(trajectories[1:], start=1):
        if tr.joint_names != first.joint_names:
            raise InvalidInputError(f"trajectories[{i}]", tr.joint_names, f"joint names {first.joint_names}")
        shifted = tr.times - tr.times[0] + end
        times.append(shifted[1:])
        coefficients.append(tr.coefficients)
        end = shifted[-1]
    padded = [np.pad(c, ((0, 0), (0, degree - c.shape[1]), (0, 0))) for c in coefficients]
    smooth = all(tr.interpolation != "linear" for tr in trajectories)
    try:
        return Trajectory.from_polynomials(
            np.concatenate(times),
            np.concatenate(padded),
            first.joint_names,
            continuity_tol=continuity_tol,
            continuous_velocity=smooth,
        )
    except InvalidInputError as exc:
        expected = "each trajectory starting where the previous ends"
        raise InvalidInputError("trajectories", exc.received, expected) from None


def _segment_coefficients(t: np.ndarray, q: np.ndarray, v: np.ndarray | None, a: np.ndarray | None) -> np.ndarray:
    h = np.diff(t)[:, None]
    dq = np.diff(q, axis=0)
    c = np.zeros((len(t) - 1, 6, q.shape[1]))
    c[:, 0] = q[:-1]
    if v is None:
        c[:, 1] = dq / h
        return c
    v0, v1 = v[:-1], v[1:]
    c[:, 1] = v0
    if a is None:
        c[:, 2] = (3 * dq - (2 * v0 + v1) * h) / h**2
        c[:, 3] = (-2 * dq + (v0 + v1) * h) / h**3
        return c
    a0, a1 = a[:-1], a[1:]
    c[:, 2] = a0 / 2
    c[:, 3] = (20 * dq - (8 * v1 + 12 * v0) * h - (3 * a0 - a1) * h**2) / (2 * h**3)
    c[:, 4] = (-30 * dq + (14 * v1 + 16 * v0) * h + (3 * a0 - 2 * a1) * h**2) / (2 * h**4)
    c[:, 5] = (12 * dq - 6 * (v1 + v0) * h + (a1 - a0) * h**2) / (2 * h**5)
    return c
