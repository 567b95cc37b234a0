"""Smoothness and safety check of a plan or of a controller replay.

:func:`check` measures, per joint: peak velocity, acceleration and jerk against the limits; velocity
discontinuities (the largest ``|Δv|`` between consecutive updates, and at waypoints); position-limit violations;
and two smoothness indices from the literature:

* **SPARC**, the spectral arc length of the velocity profile (Balasubramanian, Melendez-Calderon, Roby-Brami and
  Burdet, "On the analysis of movement smoothness", J. NeuroEng. Rehabil. 12:112, 2015): the negative arc length of
  the normalised Fourier magnitude spectrum up to an adaptive cut-off (10 Hz, amplitude threshold 0.05, zero
  padding 4). Closer to 0 is smoother (-1.40 for a minimum-jerk reach); NaN for a joint that does not move.
* **LDLJ**, the log dimensionless jerk of the velocity profile (Hogan and Sternad, 2009; same paper):
  ``-ln(T³ / v_peak² ∫ j(t)² dt)`` with ``T`` the duration; -ln(204.8) = -5.32 for a minimum-jerk (quintic)
  reach; more negative is less smooth.

For a stream (a :class:`~taplan.reference.Replay` or its ``joint_states`` samples) it also checks the sample
periods: gaps longer than ``gap_factor`` times the expected period and the RMS jitter of the periods. Derivatives of
a stream are finite differences between updates more than a quarter period apart (near-duplicate updates keep the
last value); the velocity peak is the larger of the reported velocities and the position differences divided
by the period, so a jump shows as a large implied velocity. A :class:`~taplan.trajectory.Trajectory` is evaluated
analytically on a uniform grid (``rate``, default 1 kHz) plus its knots.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from taplan._validation import as_positive
from taplan.errors import InvalidInputError
from taplan.limits import JointLimits
from taplan.reference.replay import JointStateSamples, Replay
from taplan.trajectory import Trajectory

__all__ = ["JointCheck", "Report", "Thresholds", "TimingCheck", "check", "ldlj", "sparc", "stream_timing"]

_STILL = 1e-9  # [rad]/[s]: a joint slower than this everywhere "does not move"

# The collision half of check(): taplan.clearance (a layer above, it certifies with the planners' conservative
# advancement) registers it when imported, which ``import taplan`` does.
_collision_check: Any = None


def register_collision_check(function: Any) -> None:
    """Called by :mod:`taplan.clearance`: ``function(subject, names, q, t, clearance, hold, notes)`` returns the
    ``ClearanceCheck`` of a checked subject or None."""
    global _collision_check
    _collision_check = function


@dataclass(frozen=True)
class Thresholds:
    """Pass/fail thresholds.

    Attributes:
        velocity_tolerance: Allowed excess over the velocity limit, as a fraction (0.0 = the limit itself).
        acceleration_tolerance: Likewise for acceleration.
        jerk_tolerance: Likewise for jerk.
        check_jerk: Whether the jerk peak can fail a joint (finite-difference jerk of a 100 Hz stream is noisy).
        velocity_step: Largest allowed ``|Δv|`` between consecutive samples [rad]/[s], per joint or scalar;
            None = acceleration limit × expected period × (1 + acceleration_tolerance).
        position_tolerance: Allowed excursion beyond the position limits [rad].
        gap_factor: A period longer than this many expected periods is a gap.
        jitter_tolerance: Largest allowed RMS deviation of the periods from the expected one, as a fraction of it.
        sparc_min: Fail a joint whose SPARC is below this (None = report only).
        ldlj_min: Fail a joint whose LDLJ is below this (None = report only).
    """

    velocity_tolerance: float = 0.0
    acceleration_tolerance: float = 0.0
    jerk_tolerance: float = 0.0
    check_jerk: bool = True
    velocity_step: float | None = None
    position_tolerance: float = 1e-9
    gap_factor: float = 1.5
    jitter_tolerance: float = 0.1
    sparc_min: float | None = None
    ldlj_min: float | None = None


@dataclass(frozen=True)
class JointCheck:
    """Metrics of one joint (SI units: [rad], [rad]/[s], [rad]/[s]², [rad]/[s]³)."""

    name: str
    peak_velocity: float
    velocity_limit: float
    peak_acceleration: float
    acceleration_limit: float
    peak_jerk: float
    jerk_limit: float
    max_velocity_step: float
    max_velocity_step_at_waypoint: float
    velocity_step_limit: float
    position_min: float
    position_max: float
    lower: float
    upper: float
    position_violation: float
    sparc: float
    ldlj: float
    failures: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        return not self.failures


@dataclass(frozen=True)
class TimingCheck:
    """Sample-period statistics of a stream [s]."""

    expected_period: float
    periods: int
    min_period: float
    max_period: float
    mean_period: float
    jitter_rms: float
    max_deviation: float
    gaps: int
    repeated: int
    failures: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        return not self.failures


@dataclass(frozen=True)
class Report:
    """The outcome of :func:`check`: per-joint metrics, timing, thresholds and pass/fail.

    ``str(report)`` (or :meth:`table`) is a table; :meth:`to_dict` / :meth:`to_json` serialise it.
    """

    subject: str
    source: str
    rate: float
    duration: float
    joints: tuple[JointCheck, ...]
    timing: TimingCheck | None
    thresholds: Thresholds
    dropped_waypoints: tuple[int, ...] = ()
    notes: tuple[str, ...] = field(default_factory=tuple)
    clearance: Any = None  # a taplan.clearance.ClearanceCheck

    @property
    def passed(self) -> bool:
        return (
            all(j.passed for j in self.joints)
            and (self.timing is None or self.timing.passed)
            and not self.dropped_waypoints
            and (self.clearance is None or self.clearance.passed)
        )

    @property
    def failures(self) -> list[str]:
        """Every failure as ``"<joint>: <reason>"`` / ``"timing: ..."`` / ``"waypoints: ..."``."""
        out = [f"{j.name}: {f}" for j in self.joints for f in j.failures]
        if self.timing is not None:
            out += [f"timing: {f}" for f in self.timing.failures]
        if self.dropped_waypoints:
            out.append(f"waypoints: dropped {list(self.dropped_waypoints)}")
        if self.clearance is not None and not self.clearance.passed:
            out.append(self.clearance.line())
        return out

    def joint(self, name: str) -> JointCheck:
        for j in self.joints:
            if j.name == name:
                return j
        from taplan.errors import UnknownNameError

        raise UnknownNameError("joint", name, [j.name for j in self.joints])

    def table(self) -> str:
        head = (
            f"{'joint':<10}{'|v|max':>9}{'v lim':>8}{'|a|max':>10}{'a lim':>8}{'|j|max':>11}{'j lim':>9}"
            f"{'|dv|max':>9}{'dv lim':>8}{'q out':>8}{'SPARC':>8}{'LDLJ':>8}  result"
        )
        lines = [
            f"check {self.subject} ({self.source}, {self.rate:g} Hz, {self.duration:.3f} s): "
            + ("PASS" if self.passed else "FAIL"),
            head,
        ]
        bounded = self.thresholds.check_jerk
        for j in self.joints:
            jerk_limit = f"{j.jerk_limit:>9.0f}" if bounded else f"{'n/b':>9}"
            lines.append(
                f"{j.name:<10}{j.peak_velocity:>9.3f}{j.velocity_limit:>8.2f}{j.peak_acceleration:>10.2f}"
                f"{j.acceleration_limit:>8.1f}{j.peak_jerk:>11.1f}{jerk_limit}{j.max_velocity_step:>9.4f}"
                f"{j.velocity_step_limit:>8.4f}{j.position_violation:>8.4f}{j.sparc:>8.3f}{j.ldlj:>8.2f}  "
                + ("ok" if j.passed else "FAIL: " + "; ".join(j.failures))
            )
        if self.timing is not None:
            t = self.timing
            lines.append(
                f"timing: expected {t.expected_period * 1e3:.3f} ms, periods {t.min_period * 1e3:.3f}.."
                f"{t.max_period * 1e3:.3f} ms (mean {t.mean_period * 1e3:.3f}), "
                f"RMS jitter {t.jitter_rms * 1e3:.3f} ms, "
                f"gaps {t.gaps}, repeated {t.repeated}: " + ("ok" if t.passed else "FAIL: " + "; ".join(t.failures))
            )
        if self.dropped_waypoints:
            lines.append(f"dropped waypoints: {list(self.dropped_waypoints)}: FAIL")
        if self.clearance is not None:
            lines.append(self.clearance.line())
        if not bounded:
            over = [j.name for j in self.joints if j.peak_jerk > j.jerk_limit]
            lines.append(
                "jerk: n/b = not bounded by this check (reported, never a pass or a fail)"
                + (f"; above the jerk limit: {', '.join(over)}" if over else "")
            )
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.table()

    def to_dict(self) -> dict[str, Any]:
        def clean(x: Any) -> Any:
            if isinstance(x, float) and not math.isfinite(x):
                return None
            if isinstance(x, dict):
                return {k: clean(v) for k, v in x.items()}
            if isinstance(x, list | tuple):
                return [clean(v) for v in x]
            return x

        return clean(
            {
                "subject": self.subject,
                "source": self.source,
                "rate": self.rate,
                "duration": self.duration,
                "passed": self.passed,
                "failures": self.failures,
                "joints": [
                    {**asdict(j), "passed": j.passed, "jerk_bounded": self.thresholds.check_jerk} for j in self.joints
                ],
                "timing": None if self.timing is None else {**asdict(self.timing), "passed": self.timing.passed},
                "thresholds": asdict(self.thresholds),
                "dropped_waypoints": list(self.dropped_waypoints),
                "notes": list(self.notes),
                "clearance": None if self.clearance is None else self.clearance.to_dict(),
            }
        )

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent)


# ------------------------------------------------------------------------------------------------- metrics
def sparc(
    velocity: npt.ArrayLike, rate: float, *, padlevel: int = 4, cutoff: float = 10.0, threshold: float = 0.05
) -> float:
    """Spectral arc length of a uniformly sampled velocity profile (Balasubramanian et al. 2015).

    Args:
        velocity: Samples [any unit], shape (m,), m >= 2.
        rate: Sample rate [Hz].
        padlevel: Zero padding: FFT length ``2**(ceil(log2(m)) + padlevel)``.
        cutoff: Maximum cut-off frequency [Hz].
        threshold: Amplitude threshold of the adaptive cut-off (fraction of the peak magnitude).

    Returns:
        SPARC (<= 0, closer to 0 is smoother), or NaN for a zero profile.
    """
    v = np.asarray(velocity, dtype=float)
    rate = as_positive(rate, "rate")
    if v.ndim != 1 or v.size < 2 or not np.all(np.isfinite(v)):
        raise InvalidInputError("velocity", f"shape {v.shape}", "a finite 1-D profile of >= 2 samples")
    return float(_sparc_columns(v[:, None], rate, padlevel, cutoff, threshold)[0])


def _sparc_columns(
    v: np.ndarray, rate: float, padlevel: int = 4, cutoff: float = 10.0, threshold: float = 0.05
) -> np.ndarray:
    """SPARC of each column of ``v`` (m, n) with one batched real FFT (same spectrum as the full FFT up to
    Nyquist, which bounds the cut-off)."""
    nfft = int(2 ** (math.ceil(math.log2(v.shape[0])) + padlevel))
    f = np.arange(nfft // 2 + 1) * (rate / nfft)
    mags = np.abs(np.fft.rfft(v, nfft, axis=0))
    out = np.full(v.shape[1], np.nan)
    for i in range(v.shape[1]):
        out[i] = _sparc_spectrum(f, mags[:, i], cutoff, threshold)
    return out


def _sparc_spectrum(f: np.ndarray, mag: np.ndarray, cutoff: float, threshold: float) -> float:
    peak = mag.max()
    if not peak > 0 or not np.isfinite(peak):  # still, or a stream whose speed overflows: no spectrum to measure
        return float("nan")
    mag = mag / peak
    sel = f <= cutoff
    f_sel, m_sel = f[sel], mag[sel]
    above = np.flatnonzero(m_sel >= threshold)
    f_sel = f_sel[above[0] : above[-1] + 1]
    m_sel = m_sel[above[0] : above[-1] + 1]
    if f_sel.size < 2:
        return 0.0
    span = f_sel[-1] - f_sel[0]
    return float(-np.sum(np.sqrt((np.diff(f_sel) / span) ** 2 + np.diff(m_sel) ** 2)))


def ldlj(velocity: npt.ArrayLike, jerk: npt.ArrayLike, rate: float) -> float:
    """Log dimensionless jerk ``-ln(T³/v_peak² ∫ j² dt)`` of uniformly sampled velocity and jerk profiles.

    Args:
        velocity: [rad]/[s], shape (m,).
        jerk: [rad]/[s]³, shape (m,).
        rate: Sample rate [Hz].

    Returns:
        LDLJ (more negative is less smooth), NaN for a zero profile, +inf for a jerk integral of zero (a
        piecewise-linear plan evaluated analytically: its jerk is impulses at the knots, not sampled).
    """
    v = np.asarray(velocity, dtype=float)
    j = np.asarray(jerk, dtype=float)
    rate = as_positive(rate, "rate")
    if v.shape != j.shape or v.ndim != 1 or v.size < 2:
        raise InvalidInputError("jerk", f"shape {j.shape}", f"the velocity's shape {v.shape}, 1-D, >= 2 samples")
    peak = float(np.max(np.abs(v)))
    if peak <= _STILL:
        return float("nan")
    duration = (v.size - 1) / rate
    integral = float(np.trapezoid(j**2, dx=1.0 / rate))
    value = duration**3 / peak**2 * integral
    return float(-np.log(value)) if value > 0 else float("inf")


# --------------------------------------------------------------------------------------------------- check
@dataclass
class _Series:
    """What the joint checks read, from a plan or from a stream: samples ``t`` (m,), ``q``/``v``/``a``/``j`` (m, n),
    the largest velocity change between samples ``dv`` and across waypoints ``dv_wp`` (n,), the peak velocity, the
    sample period, and the report's labels."""

    names: tuple[str, ...]
    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    j: np.ndarray
    dv: np.ndarray
    dv_wp: np.ndarray
    v_peak: np.ndarray
    period: float
    label: str
    source: str
    timing: TimingCheck | None = None
    dropped: tuple[int, ...] = ()
    notes: tuple[str, ...] = ()
    q_range: tuple[np.ndarray, np.ndarray] | None = None  # a plan's exact position range, when known
    a_peak: np.ndarray | None = None  # a plan's exact peak |acceleration|


def check(
    subject: Replay | JointStateSamples | Trajectory,
    limits: JointLimits | None = None,
    *,
    rate: float | None = None,
    thresholds: Thresholds | None = None,
    waypoint_times: npt.ArrayLike | None = None,
    source: str = "updates",
    name: str | None = None,
    clearance: Any = "auto",
    hold: npt.ArrayLike | None = None,
) -> Report:
    """Check a plan or a replay against joint limits and for smoothness.

    Args:
        subject: A :class:`~taplan.trajectory.Trajectory` (evaluated analytically), a
            :class:`~taplan.reference.Replay` (its update stream, or its ``joint_states`` samples with
            ``source="samples"``) or :class:`~taplan.reference.JointStateSamples`.
        limits: Joint limits, matched by name; default the bundled TeleAvatar's hardware limits.
        rate: Expected sample rate [Hz]: a Trajectory's evaluation grid (default 1000), a stream's nominal rate
            (default the replay's).
        thresholds: Pass/fail thresholds (default :class:`Thresholds`).
        waypoint_times: Times of the waypoints [s] (default the Trajectory's knots / the replay's reached points).
        source: ``"updates"`` or ``"samples"`` for a Replay.
        name: Label of the subject in the report.
        clearance: Collision check (:func:`taplan.clearance.check_clearance`, always on by default; registered by
            :mod:`taplan.clearance`, which ``import taplan`` imports): ``"auto"``
            checks the bundled TeleAvatar's own bodies when every joint of the subject is one of its joints (a
            note says when it is skipped because they are not); a :class:`~taplan.robot.Robot` or a
            :class:`~taplan.scene.CollisionWorld` (with a scene: its obstacles too) is used as given; None skips it.
            A Trajectory is certified continuously, a stream along the segments between its samples.
        hold: Positions [rad] (nq,) of the robot's joints the subject does not drive (default its home).

    Returns:
        The :class:`Report`.
    """
    th = thresholds or Thresholds()
    if isinstance(subject, Trajectory):
        series = _plan_series(subject, rate, waypoint_times, name)
    elif isinstance(subject, (Replay, JointStateSamples)):
        series = _stream_series(subject, rate, waypoint_times, source, name, th)
    else:
        raise InvalidInputError("subject", type(subject).__name__, "a Trajectory, Replay or JointStateSamples")
    joints = _joint_checks(series, _limits(limits, series.names), th)
    notes = list(series.notes)
    clearance_check = None
    if clearance is not None:
        if _collision_check is None:
            notes.append("collision: not checked (taplan.clearance is not imported)")
        else:
            clearance_check = _collision_check(subject, tuple(series.names), series.q, series.t, clearance, hold, notes)
    return Report(
        subject=series.label,
        source=series.source,
        rate=1.0 / series.period,
        duration=float(series.t[-1] - series.t[0]),
        joints=tuple(joints),
        timing=series.timing,
        thresholds=th,
        dropped_waypoints=series.dropped,
        notes=tuple(notes),
        clearance=clearance_check,
    )


def _plan_series(
    subject: Trajectory, rate: float | None, waypoint_times: npt.ArrayLike | None, name: str | None
) -> _Series:
    """A plan evaluated analytically on a uniform grid plus its knots; ``|Δv|`` across each knot from the
    polynomials on either side."""
    grid_rate = as_positive(1000.0 if rate is None else rate, "rate")
    # the grid, the knots and the instants just before them (a derivative's value as its segment ends)
    t = np.union1d(np.union1d(subject.sample_times(grid_rate), subject.times), subject.times[1:] - 1e-9)
    q, v, a, j = (subject(t, k) for k in range(4))
    # peaks between grid points, found by successive parabolic interpolation: every value is the trajectory's own
    # at some instant, so a plan beyond a limit between two samples fails and no plan fails for a value it lacks
    q_low, q_high = _extremes(subject, t, q, 0)
    v_low, v_high = _extremes(subject, t, v, 1)
    a_low, a_high = _extremes(subject, t, a, 2)
    if waypoint_times is not None:
        _times(waypoint_times)  # validated; a plan's velocity steps are measured at its knots, below
    eps = 1e-9
    inner = subject.times[1:-1]
    n = len(subject.joint_names)
    dv_wp = np.abs(subject(inner + eps, 1) - subject(inner - eps, 1)).max(axis=0) if inner.size else np.zeros(n)
    dv = np.maximum(np.abs(np.diff(v, axis=0)).max(axis=0), dv_wp)
    label = name or repr(subject)
    v_peak = np.maximum(np.abs(v_low), np.abs(v_high))
    series = _Series(subject.joint_names, t, q, v, a, j, dv, dv_wp, v_peak, 1.0 / grid_rate, label, "trajectory")
    series.q_range = (q_low, q_high)
    series.a_peak = np.maximum(np.abs(a_low), np.abs(a_high))
    return series


_REFINE_STEPS = 4
_MAX_CANDIDATES = 20_000  # local extrema refined per quantity (the largest first)


def _extremes(subject: Trajectory, t: np.ndarray, y: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Per joint the smallest and largest value of derivative ``order`` of ``subject``: its samples ``y`` at ``t``,
    each interior local extremum refined by successive parabolic interpolation inside its neighbouring samples."""
    low, high = y.min(axis=0), y.max(axis=0)
    if len(t) < 3:
        return low, high
    for sign in (1.0, -1.0):
        z = sign * y
        rows, cols = np.nonzero((z[1:-1] >= z[:-2]) & (z[1:-1] >= z[2:]))
        rows = rows + 1
        if rows.size > _MAX_CANDIDATES:
            keep = np.argsort(z[rows, cols])[-_MAX_CANDIDATES:]
            rows, cols = rows[keep], cols[keep]
        if rows.size == 0:
            continue
        a, b, c = t[rows - 1], t[rows], t[rows + 1]
        fa, fb, fc = z[rows - 1, cols], z[rows, cols], z[rows + 1, cols]
        pick = np.arange(rows.size)
        for _ in range(_REFINE_STEPS):
            num = (b - a) ** 2 * (fb - fc) - (b - c) ** 2 * (fb - fa)
            den = (b - a) * (fb - fc) - (b - c) * (fb - fa)
            with np.errstate(divide="ignore", invalid="ignore"):
                x = np.where(den != 0, b - 0.5 * num / den, b)
            x = np.clip(np.nan_to_num(x, nan=0.0), a, c)
            fx = sign * subject(x, order)[pick, cols]
            better, left = fx > fb, x < b
            # the new point becomes the middle when it is higher; otherwise it closes the bracket on its side
            a, fa = (
                np.where(better & ~left, b, np.where(~better & left, x, a)),
                np.where(better & ~left, fb, np.where(~better & left, fx, fa)),
            )
            c, fc = (
                np.where(better & left, b, np.where(~better & ~left, x, c)),
                np.where(better & left, fb, np.where(~better & ~left, fx, fc)),
            )
            b, fb = np.where(better, x, b), np.where(better, fx, fb)
        best = np.full(y.shape[1], -np.inf)
        np.maximum.at(best, cols, fb)
        if sign > 0:
            high = np.maximum(high, best)
        else:
            low = np.minimum(low, -best)
    return low, high


def _stream_samples(
    subject: Replay | JointStateSamples, rate: float | None, source: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, float]:
    """``(t, q, reported v, reported a or None, nominal rate)`` of a replay's updates or samples, or of samples."""
    if isinstance(subject, JointStateSamples):
        stream_rate = subject.rate if rate is None else as_positive(rate, "rate")
        return subject.times, subject.positions, subject.velocities, None, stream_rate
    if source == "samples":
        if subject.samples is None:
            raise InvalidInputError("source", source, "'updates' (this replay has no joint_states samples)")
        s = subject.samples
        return s.times, s.positions, s.velocities, None, s.rate if rate is None else as_positive(rate, "rate")
    if source != "updates":
        raise InvalidInputError("source", source, "'updates' or 'samples'")
    t = np.concatenate([[0.0], subject.times])
    q = np.vstack([subject.initial_positions, subject.positions])
    v_rep = np.vstack([subject.initial_velocities, subject.velocities])
    a_rep = None
    if subject.accelerations is not None:
        a_rep = np.vstack([np.zeros(subject.n_joints), subject.accelerations])
    return t, q, v_rep, a_rep, subject.rate if rate is None else as_positive(rate, "rate")


def _stream_series(
    subject: Replay | JointStateSamples,
    rate: float | None,
    waypoint_times: npt.ArrayLike | None,
    source: str,
    name: str | None,
    th: Thresholds,
) -> _Series:
    """A stream's derivatives by finite differences between updates, its timing, and ``|Δv|`` at waypoints."""
    t, q, v_rep, a_rep, stream_rate = _stream_samples(subject, rate, source)
    if isinstance(subject, Replay):
        names = subject.joint_names
        dropped = tuple(subject.dropped)
        wp = subject.waypoint_times if waypoint_times is None else _times(waypoint_times)
        label = name or subject.controller
        notes = tuple(subject.events[:5])
        src = source
    else:
        names = subject.joint_names or tuple(f"joint{i}" for i in range(q.shape[1]))
        dropped, notes, src = (), (), "samples"
        wp = np.zeros(0) if waypoint_times is None else _times(waypoint_times)
        label = name or "joint_states"
    period = 1.0 / stream_rate
    if len(t) < 2:
        raise InvalidInputError("subject", f"{len(t)} samples", "a stream of at least 2 samples")
    if np.any(np.diff(t) < 0) or not np.all(np.isfinite(t)):
        raise InvalidInputError("times", "non-monotonic or non-finite sample times", "non-decreasing times")
    if not np.all(np.isfinite(q)):
        raise InvalidInputError("positions", "NaN or inf", "finite positions")
    stamps = subject.times if isinstance(subject, Replay) and src == "updates" else t
    timing = _timing(np.diff(stamps), period, th) if len(stamps) >= 2 else None
    # updates closer than a quarter period are merged (last value wins): a near-duplicate update is not a
    # sample a robot can follow, and differences over nanoseconds would swamp the derivatives
    keep = np.append(np.diff(t) > 0.25 * period, True)
    t, q = t[keep], q[keep]
    v_rep = v_rep[keep]
    if len(t) < 2:  # nothing moved in time (e.g. every waypoint dropped): hold the state one period
        t = np.append(t, t[-1] + period)
        q = np.vstack([q, q[-1:]])
        v_rep = np.vstack([v_rep, np.zeros_like(v_rep[-1:])])
        if a_rep is not None:
            a_rep = np.vstack([a_rep[keep], np.zeros_like(a_rep[-1:])])
            keep = np.ones(len(t), dtype=bool)
    h = np.diff(t)[:, None]
    v_fd = np.vstack([np.zeros((1, q.shape[1])), np.diff(q, axis=0) / h])
    v = np.where(np.isfinite(v_rep), v_rep, v_fd)
    a = a_rep[keep] if a_rep is not None else np.vstack([np.zeros((1, q.shape[1])), np.diff(v, axis=0) / h])
    j = np.vstack([np.zeros((1, q.shape[1])), np.diff(a, axis=0) / h])
    v_peak = np.maximum(np.abs(v).max(axis=0), np.abs(v_fd).max(axis=0))
    dv_all = np.abs(np.diff(v, axis=0))
    dv = dv_all.max(axis=0)
    dv_wp = np.zeros(q.shape[1])
    if wp.size:
        k = np.clip(np.searchsorted(t, wp - 1e-12), 1, len(t) - 1)
        dv_wp = np.maximum(dv_all[k - 1], dv_all[np.minimum(k, len(dv_all) - 1)]).max(axis=0)
    return _Series(tuple(names), t, q, v, a, j, dv, dv_wp, v_peak, period, label, src, timing, dropped, notes)


def _joint_checks(s: _Series, lim: JointLimits, th: Thresholds) -> list[JointCheck]:
    """Per joint: peaks against the limits, velocity steps, position excursion, SPARC and LDLJ on a uniform grid."""
    step_limit = (
        lim.acceleration * s.period * (1 + th.acceleration_tolerance)
        if th.velocity_step is None
        else np.broadcast_to(np.asarray(th.velocity_step, dtype=float), (len(s.names),))
    )
    t_u = np.arange(s.t[0], s.t[-1] + 1e-12, s.period)
    if t_u.size < 2:
        t_u = np.array([s.t[0], s.t[-1]])
    v_u = np.column_stack([np.interp(t_u, s.t, s.v[:, i]) for i in range(len(s.names))])
    sparcs = _sparc_columns(v_u, 1.0 / s.period)
    joints = []
    for i, joint in enumerate(s.names):
        moving = np.max(np.abs(s.v[:, i])) > _STILL
        sp = float(sparcs[i]) if moving else float("nan")
        lj = ldlj(v_u[:, i], np.interp(t_u, s.t, s.j[:, i]), 1.0 / s.period) if moving else float("nan")
        low, high = s.q_range if s.q_range is not None else (s.q.min(axis=0), s.q.max(axis=0))
        qmin, qmax = float(low[i]), float(high[i])
        violation = max(0.0, float(lim.lower[i]) - qmin, qmax - float(lim.upper[i]))
        a_peak = float(s.a_peak[i]) if s.a_peak is not None else float(np.abs(s.a[:, i]).max())
        peaks = (float(s.v_peak[i]), a_peak, float(np.abs(s.j[:, i]).max()))
        step = max(s.dv[i], s.dv_wp[i])
        fails = _failures(peaks, step, violation, sp, lj, lim, i, float(step_limit[i]), th)
        joints.append(
            JointCheck(
                joint,
                peaks[0],
                float(lim.velocity[i]),
                peaks[1],
                float(lim.acceleration[i]),
                peaks[2],
                float(lim.jerk[i]),
                float(s.dv[i]),
                float(s.dv_wp[i]),
                float(step_limit[i]),
                qmin,
                qmax,
                float(lim.lower[i]),
                float(lim.upper[i]),
                violation,
                sp,
                lj,
                tuple(fails),
            )
        )
    return joints


def _failures(
    peaks: tuple[float, float, float],
    step: float,
    violation: float,
    sp: float,
    lj: float,
    lim: JointLimits,
    i: int,
    step_limit: float,
    th: Thresholds,
) -> list[str]:
    """Why joint ``i`` fails (empty: it passes)."""
    fails = []
    if peaks[0] > lim.velocity[i] * (1 + th.velocity_tolerance) + 1e-12:
        fails.append(f"velocity {peaks[0]:.4g} > {lim.velocity[i]:.4g}")
    if peaks[1] > lim.acceleration[i] * (1 + th.acceleration_tolerance) + 1e-12:
        fails.append(f"acceleration {peaks[1]:.4g} > {lim.acceleration[i]:.4g}")
    if th.check_jerk and peaks[2] > lim.jerk[i] * (1 + th.jerk_tolerance) + 1e-12:
        fails.append(f"jerk {peaks[2]:.4g} > {lim.jerk[i]:.4g}")
    if step > step_limit + 1e-12:
        fails.append(f"velocity step {step:.4g} > {step_limit:.4g}")
    if violation > th.position_tolerance:
        fails.append(f"position limit exceeded by {violation:.4g}")
    if th.sparc_min is not None and np.isfinite(sp) and sp < th.sparc_min:
        fails.append(f"SPARC {sp:.3f} < {th.sparc_min}")
    if th.ldlj_min is not None and np.isfinite(lj) and lj < th.ldlj_min:
        fails.append(f"LDLJ {lj:.3f} < {th.ldlj_min}")
    return fails


def stream_timing(times: npt.ArrayLike, rate: float, thresholds: Thresholds | None = None) -> TimingCheck:
    """Period statistics of a stream's sample times [s] against its nominal ``rate`` [Hz] (jitter, gaps, repeats).

    Raises:
        InvalidInputError: fewer than 2 times, or times that are not finite and non-decreasing.
    """
    t = _times(times)
    if t.size < 2 or np.any(np.diff(t) < 0):
        raise InvalidInputError("times", f"{t.size} times", "at least 2 finite, non-decreasing times")
    return _timing(np.diff(t), 1.0 / as_positive(rate, "rate"), thresholds or Thresholds())


def _timing(periods: np.ndarray, expected: float, th: Thresholds) -> TimingCheck:
    dev = periods - expected
    gaps = int(np.sum(periods > th.gap_factor * expected))
    repeated = int(np.sum(periods < 0.25 * expected))
    jitter = float(np.sqrt(np.mean(dev**2)))
    fails = []
    if gaps:
        fails.append(f"{gaps} gap(s) > {th.gap_factor:g} x {expected * 1e3:.3f} ms (max {periods.max() * 1e3:.3f} ms)")
    if jitter > th.jitter_tolerance * expected:
        fails.append(f"RMS jitter {jitter * 1e3:.3f} ms > {th.jitter_tolerance * expected * 1e3:.3f} ms")
    return TimingCheck(
        expected_period=expected,
        periods=int(periods.size),
        min_period=float(periods.min()),
        max_period=float(periods.max()),
        mean_period=float(periods.mean()),
        jitter_rms=jitter,
        max_deviation=float(np.abs(dev).max()),
        gaps=gaps,
        repeated=repeated,
        failures=tuple(fails),
    )


def _times(values: npt.ArrayLike) -> np.ndarray:
    t = np.asarray(values, dtype=float).ravel()
    if not np.all(np.isfinite(t)):
        raise InvalidInputError("waypoint_times", values, "finite times [s]")
    return t


def _limits(limits: JointLimits | None, names: Sequence[str]) -> JointLimits:
    if limits is None:
        from taplan.robot import teleavatar_limits

        limits = teleavatar_limits()
    if not isinstance(limits, JointLimits):
        raise InvalidInputError("limits", type(limits).__name__, "a taplan.JointLimits")
    if tuple(limits.names) == tuple(names):
        return limits
    return limits.subset(names)
