"""Recorded demonstrations (timestamps + joint positions) into limit-respecting, jerk-limited trajectories.

Teleoperation recordings are dense (30-100 Hz), noisy, long and often near the joint limits. The pipeline:

1. **Limits.** Samples outside the position limits are clipped onto them (the clipping counts in the reported
   deviation; nothing else is clipped).
2. **Noise: a fit, not an interpolation.** All joints are fitted together by a least-squares cubic spline in
   time (``scipy.interpolate.make_lsq_spline``, C²) with adaptive knots: knots every ``INITIAL_KNOT_SPACING``
   (0.5 s), and every knot interval where some sample is still farther than ``max_deviation`` (max-norm over
   joints; and, with a robot, a hand farther than ``max_frame_deviation``) is halved while it holds at least
   ``2 MIN_SAMPLES_PER_KNOT`` (4) samples (and is at least twice ``min_knot_spacing`` long, if given). Knot
   intervals stay long (0.5 s) where the motion is smooth and shorten only at sharp features, every one averages
   two samples or more, so white noise is averaged out instead of being passed through (an interpolating spline through
   noisy samples turns the noise into jerk: 5 mrad over 33 ms is ~100 rad/s³).
3. **Path.** The fit's values and first two derivatives at its knots define a
   :class:`~taplan.timing.path.Path` parametrised by the *recording's time* (``s`` = seconds of recording) and
   bounded by the position limits (it cannot leave them, see ``path.py``; a knot value outside is clipped onto
   the bound). Its deviation from every recorded sample at the sample's own time is measured in joint space
   [rad] and, with a robot, for the hands in Cartesian space [m].
4. **Timing.** :func:`~taplan.timing.jerk_limited.jerk_limited` with ``method="path"`` (the trajectory stays on
   the path, so the deviation of step 3 is the trajectory's), rest to rest. With ``keep_timing`` the path speed
   is capped at ``ṡ <= 1``: TOPP-RA keeps the recording's timing wherever the limits allow it and slows down only
   where they do not (and to start and stop at rest); without it the path is timed time-optimally.
5. **Report.** Where the trajectory runs behind the recording (``ds/dt < 1``), the recording's intervals, the
   slowest speed there and the time added; the duration against the recording's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy.interpolate import make_lsq_spline

from taplan._validation import as_matrix, as_vector
from taplan.errors import InvalidInputError, TimingError
from taplan.limits import JointLimits
from taplan.timing.jerk_limited import JerkLimitedResult, jerk_limited
from taplan.timing.path import Path
from taplan.trajectory import Trajectory

__all__ = ["DemonstrationResult", "Slowdown", "load_recording", "time_demonstration"]

DEFAULT_MAX_DEVIATION = 0.01  # [rad] from every recorded sample
DEFAULT_MAX_FRAME_DEVIATION = 0.005  # [m] hands from their recorded positions
INITIAL_KNOT_SPACING = 0.5  # [s]
MIN_SAMPLES_PER_KNOT = 2  # samples per knot interval at least: noise is averaged, not interpolated
SLOW = 0.999  # path speed below this share of the recording's counts as a slow-down
MAX_ROUNDS = 16  # knot-halving rounds


@dataclass(frozen=True)
class Slowdown:
    """A stretch of the recording the trajectory plays slower than recorded.

    Attributes:
        start: Recording time where it begins [s from the first sample].
        end: Recording time where it ends [s].
        min_speed: Slowest playback there, as a share of the recording's speed (1 = as recorded).
        added: Time added over this stretch [s].
    """

    start: float
    end: float
    min_speed: float
    added: float


@dataclass(frozen=True)
class DemonstrationResult:
    """A recorded demonstration made limit-respecting and jerk-limited.

    Attributes:
        trajectory: The jerk-limited trajectory (rest to rest, exact polynomial pieces, ``limits.names``).
        timing: The underlying :func:`jerk_limited` result (``method="path"``).
        path: The fitted path, parametrised by recording time [s].
        waypoints: The fit's knots [s of recording]: the path's waypoints.
        deviation: Largest distance [rad] between a recorded sample (clipped into the limits) and the trajectory
            at the sample's place on the path, per joint, shape (n,).
        frame_deviation: Per hand frame, the largest distance [m] between its recorded and its planned position.
        clipped: Largest distance [rad] a recorded sample was moved to put it inside the position limits.
        recording_duration: [s].
        slowdowns: Where the trajectory runs slower than the recording (``keep_timing``), in recording time.
        keep_timing: Whether the recording's timing was kept where feasible.
        knot_spacing: The closest knots the fit was allowed [s] (0: only the samples-per-interval rule).
    """

    trajectory: Trajectory
    timing: JerkLimitedResult
    path: Path
    waypoints: np.ndarray
    deviation: np.ndarray
    frame_deviation: dict[str, float] = field(default_factory=dict)
    clipped: float = 0.0
    recording_duration: float = 0.0
    slowdowns: tuple[Slowdown, ...] = ()
    keep_timing: bool = True
    knot_spacing: float = 0.0

    @property
    def max_deviation(self) -> float:
        """Largest joint deviation [rad]."""
        return float(self.deviation.max(initial=0.0))

    @property
    def duration_ratio(self) -> float:
        """Duration over the recording's."""
        return self.trajectory.duration / self.recording_duration

    def summary(self) -> str:
        """A few lines for a report: deviation, hands, slow-downs, duration."""
        lines = [
            f"recording {self.recording_duration:.3f} s -> {self.trajectory.duration:.3f} s "
            f"({self.duration_ratio:.3f} x), fitted with {len(self.waypoints)} knots (least squares, "
            f"{MIN_SAMPLES_PER_KNOT}+ samples per knot interval)",
            f"deviation from the recording: {self.max_deviation * 1e3:.2f} mrad (max over joints and samples)"
            + (f", {self.clipped * 1e3:.2f} mrad of it clipping into the limits" if self.clipped > 0 else ""),
        ]
        for frame, value in self.frame_deviation.items():
            lines.append(f"  {frame}: {value * 1e3:.2f} mm")
        if self.keep_timing:
            added = sum(s.added for s in self.slowdowns)
            lines.append(f"slow-downs: {len(self.slowdowns)}, {added:.3f} s added")
            for s in self.slowdowns[:8]:
                lines.append(f"  {s.start:.3f}-{s.end:.3f} s: down to {s.min_speed:.2f} x, +{s.added:.3f} s")
        return "\n".join(lines)


def time_demonstration(
    times: npt.ArrayLike,
    positions: npt.ArrayLike,
    limits: JointLimits,
    *,
    max_deviation: float = DEFAULT_MAX_DEVIATION,
    keep_timing: bool = True,
    min_knot_spacing: float | None = None,
    robot: object | None = None,
    frames: tuple[str, ...] | None = None,
    max_frame_deviation: float = DEFAULT_MAX_FRAME_DEVIATION,
    base_configuration: npt.ArrayLike | None = None,
) -> DemonstrationResult:
    """A limit-respecting, jerk-limited trajectory within ``max_deviation`` of a recorded demonstration.

    Args:
        times: Sample times [s], shape (k,), non-decreasing (repeated stamps are averaged).
        positions: Joint positions [rad], shape (k, n), in ``limits.names`` order.
        limits: Joint limits (position, velocity, acceleration, jerk).
        max_deviation: Largest distance [rad] (max-norm over joints) allowed between a recorded sample and the
            trajectory, > 0.
        keep_timing: Play at the recording's speed wherever the limits allow it, slower only where they do not;
            False: as fast as the limits allow along the same path.
        min_knot_spacing: Closest knots of the fit [s], > 0, or None (then only the rule of two samples or more
            per knot interval applies): the shortest stretch of recording averaged into one polynomial piece.
        robot: A :class:`taplan.Robot` to measure (and bound) the hands' deviation in Cartesian space, or None.
        frames: Frames to measure with ``robot`` (default: the end effectors of the groups whose joints move).
        max_frame_deviation: Largest distance [m] allowed between a frame's recorded and planned positions, > 0.
        base_configuration: Full robot configuration for the joints not recorded (default ``robot.home``).

    Returns:
        The trajectory with its deviation, slow-downs and duration against the recording.

    Raises:
        InvalidInputError: malformed inputs (shapes, NaN, times going back, fewer than 2 samples).
        TimingError: the recording cannot be followed within ``max_deviation`` (noise larger than it: raise
            ``max_deviation`` or lower ``min_knot_spacing``).
    """
    if not isinstance(limits, JointLimits):
        raise InvalidInputError("limits", type(limits).__name__, "a taplan.JointLimits")
    q_raw = as_matrix(positions, "positions", (None, limits.size))
    t = as_vector(times, "times", q_raw.shape[0])
    for name, value, ok in (
        ("max_deviation", max_deviation, max_deviation > 0),
        ("min_knot_spacing", min_knot_spacing or 1.0, (min_knot_spacing or 1.0) > 0),
        ("max_frame_deviation", max_frame_deviation, max_frame_deviation > 0),
    ):
        if not (isinstance(value, int | float) and np.isfinite(value) and ok):
            raise InvalidInputError(name, value, "a finite number > 0")
    t, q_raw = _merge_repeated_stamps(t, q_raw)
    lower, upper = np.asarray(limits.lower, dtype=float), np.asarray(limits.upper, dtype=float)
    q_rec = np.clip(q_raw, lower, upper)
    clipped = float(np.max(np.abs(q_rec - q_raw)))
    s = t - t[0]
    hands = _Hands(robot, frames, limits, base_configuration) if robot is not None else None
    spacing = 0.0 if min_knot_spacing is None else float(min_knot_spacing)
    path = _fit(s, q_rec, max_deviation, hands, max_frame_deviation, limits, spacing)
    deviation = np.max(np.abs(path(s) - q_rec), axis=0)
    frame_deviation = {} if hands is None else hands.deviation(path(s), q_rec)
    worst_frame = max(frame_deviation.values(), default=0.0)
    if deviation.max() > max_deviation or worst_frame > max_frame_deviation:
        j = int(np.argmax(deviation))
        raise TimingError(
            f"the recording cannot be followed within max_deviation={max_deviation:g} rad (hands "
            f"{max_frame_deviation:g} m) by a fit with {MIN_SAMPLES_PER_KNOT}+ samples per knot interval: "
            f"{limits.names[j]} stays "
            f"{deviation[j]:.4g} rad from it (hands {worst_frame:.4g} m); the recording is noisier than that: raise "
            "max_deviation" + (" or lower min_knot_spacing" if spacing else "")
        )
    timing = jerk_limited(path, limits, method="path", max_path_speed=1.0 if keep_timing else None)
    slowdowns = _slowdowns(timing, s) if keep_timing else ()
    return DemonstrationResult(
        timing.trajectory,
        timing,
        path,
        path.ss_waypoints,
        deviation,
        frame_deviation,
        clipped,
        float(s[-1]),
        slowdowns,
        keep_timing,
        float(spacing),
    )


def _merge_repeated_stamps(t: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if q.shape[0] < 2:
        raise InvalidInputError("positions", f"{q.shape[0]} sample(s)", "at least 2 recorded samples")
    step = np.diff(t)
    if np.any(step < 0):
        k = int(np.argmax(step < 0))
        raise InvalidInputError("times", f"times[{k + 1}] = {t[k + 1]:.9g} < times[{k}] = {t[k]:.9g}", "non-decreasing")
    if np.all(step > 0):
        return t, q
    unique, index = np.unique(t, return_inverse=True)
    if len(unique) < 2:
        raise InvalidInputError("times", "one time stamp for every sample", "a recording lasting > 0 s")
    merged = np.zeros((len(unique), q.shape[1]))
    np.add.at(merged, index, q)
    return unique, merged / np.bincount(index)[:, None]


class _Hands:
    """Forward kinematics of the hand frames for the recorded joints (the rest held at ``base_configuration``)."""

    def __init__(self, robot: object, frames: tuple[str, ...] | None, limits: JointLimits, base: object) -> None:
        from taplan.robot import Robot

        if not isinstance(robot, Robot):
            raise InvalidInputError("robot", type(robot).__name__, "a taplan.Robot")
        self.robot = robot
        self.index = robot.indices(limits.names)
        moving = set(limits.names)
        if frames is None:
            frames = tuple(g.ee_frame for g in robot.groups.values() if moving & set(g.joint_names))
        self.frames = tuple(frames)
        for frame in self.frames:
            robot.frame_id(frame)
        self.base = robot.home.copy() if base is None else as_vector(base, "base_configuration", robot.nq)

    def positions(self, q: np.ndarray) -> np.ndarray:
        """Frame positions [m], shape (k, frames, 3)."""
        full = np.repeat(self.base[None, :], len(q), axis=0)
        full[:, self.index] = q
        out = np.empty((len(q), len(self.frames), 3))
        for i, row in enumerate(full):
            poses = self.robot.frame_poses(row, self.frames)
            for f, frame in enumerate(self.frames):
                out[i, f] = poses[frame][:3, 3]
        return out

    def distances(self, q_path: np.ndarray, q_rec: np.ndarray) -> np.ndarray:
        """Largest frame distance [m] per sample, shape (k,)."""
        return np.max(np.linalg.norm(self.positions(q_path) - self.positions(q_rec), axis=2), axis=1)

    def deviation(self, q_path: np.ndarray, q_rec: np.ndarray) -> dict[str, float]:
        d = np.linalg.norm(self.positions(q_path) - self.positions(q_rec), axis=2).max(axis=0)
        return {frame: float(v) for frame, v in zip(self.frames, d, strict=True)}


def _fit(
    s: np.ndarray,
    q_rec: np.ndarray,
    max_deviation: float,
    hands: _Hands | None,
    max_frame_deviation: float,
    limits: JointLimits,
    spacing: float,
) -> Path:
    """Least-squares cubic spline fit of the recording with adaptive knots, as a bounded :class:`Path`."""
    lower, upper = np.asarray(limits.lower, dtype=float), np.asarray(limits.upper, dtype=float)
    duration = float(s[-1])
    knots = np.linspace(0.0, duration, max(2, int(np.ceil(duration / max(INITIAL_KNOT_SPACING, spacing))) + 1))
    path = None
    for _ in range(MAX_ROUNDS):
        full = np.r_[[0.0] * 3, knots, [duration] * 3]
        try:
            spline = make_lsq_spline(s, q_rec, full, k=3)
        except (ValueError, np.linalg.LinAlgError):  # too few samples between some knots: keep the last fit
            break
        values = np.clip(spline(knots), lower, upper)
        path = Path(values, knots, bounds=(lower, upper), derivatives=(spline(knots, 1), spline(knots, 2)))
        q_path = path(s)
        error = np.max(np.abs(q_path - q_rec), axis=1) / max_deviation
        if hands is not None:
            error = np.maximum(error, hands.distances(q_path, q_rec) / max_frame_deviation)
        interval = np.clip(np.searchsorted(knots, s, side="right") - 1, 0, len(knots) - 2)
        worst = np.zeros(len(knots) - 1)
        np.maximum.at(worst, interval, error)
        count = np.bincount(interval, minlength=len(knots) - 1)
        split = np.flatnonzero((worst > 1.0) & (count >= 2 * MIN_SAMPLES_PER_KNOT) & (np.diff(knots) >= 2 * spacing))
        if split.size == 0:
            break
        # split at the middle sample, not the middle time: both halves keep half the samples
        first = np.searchsorted(interval, split)
        middle = first + count[split] // 2
        knots = np.union1d(knots, 0.5 * (s[middle - 1] + s[middle]))
    if path is None:
        raise InvalidInputError("times", f"{len(s)} samples over {duration:.4g} s", "enough samples to fit a spline")
    return path


def _slowdowns(timing: JerkLimitedResult, s: np.ndarray) -> tuple[Slowdown, ...]:
    """Stretches of recording time where the trajectory's path speed is below ``SLOW`` of the recording's."""
    t = np.linspace(0.0, timing.trajectory.duration, max(2, int(np.ceil(timing.trajectory.duration * 200)) + 1))
    sf = timing.path_position(t)
    speed = np.gradient(sf, t)
    slow = speed < SLOW
    out = []
    edges = np.flatnonzero(np.diff(np.r_[0, slow.astype(int), 0]))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        start, end = float(sf[a]), float(sf[min(b, len(t) - 1)])
        added = float(t[min(b, len(t) - 1)] - t[a]) - (end - start)
        out.append(Slowdown(start, end, float(speed[a:b].min()), max(added, 0.0)))
    return tuple(out)


_TIME_COLUMNS = ("time", "t", "timestamp", "stamp")


def load_recording(path: str, stream: str = "measured") -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """``(times [s] from the first sample, positions [rad] (k, n), joint names)`` of a recorded demonstration CSV.

    Args:
        path: A CSV whose header is a time column (``time``, ``t``, ``timestamp`` or ``stamp`` [s]) then one
            column per joint (``l_joint1`` or ``l_joint1.pos``; other ``.vel``/``.acc`` columns are ignored). A
            rosbag2 MCAP bag is read at the ROS edge by :func:`taplan.ros.bag.read_recording` (same return value);
            ``taplan plan --recorded`` takes either.
        stream: Unused for a CSV (kept so both readers take the same arguments).

    Raises:
        InvalidInputError: a missing or unreadable file, or no joint columns in it.
    """
    from pathlib import Path as FilePath

    file = FilePath(path)
    if not file.is_file():
        raise InvalidInputError("recording", str(file), "an existing .csv file")
    if file.suffix.lower() == ".mcap":
        raise InvalidInputError("recording", str(file), "a .csv (a .mcap bag: taplan.ros.bag.read_recording)")
    if file.suffix.lower() != ".csv":
        raise InvalidInputError("recording", str(file), "a .csv file (a time column, then one per joint)")
    header = [h.strip() for h in file.read_text().splitlines()[0].split(",")] if file.stat().st_size else []
    if not header or header[0].lower() not in _TIME_COLUMNS:
        raise InvalidInputError("recording", f"header {header[:3]}...", f"a first column named one of {_TIME_COLUMNS}")
    columns = [i for i, h in enumerate(header[1:], 1) if "." not in h or h.endswith(".pos")]
    if not columns:
        raise InvalidInputError("recording", f"header {header}", "one column per joint after the time column")
    try:
        table = np.loadtxt(file, delimiter=",", skiprows=1, ndmin=2)
    except ValueError as exc:
        raise InvalidInputError("recording", str(file), f"numbers in every row ({exc})") from exc
    names = tuple(header[i].removesuffix(".pos") for i in columns)
    return table[:, 0] - table[0, 0], table[:, columns], names
