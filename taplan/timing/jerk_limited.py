"""Jerk-limited trajectories through waypoints: TOPP-RA followed by a moving-average filter of the path timing.

Method (documented)
-------------------
Let ``s(t)`` be a TOPP-RA timing of the path (piecewise-constant path acceleration, rest to rest, duration ``T``).
The path timing is filtered with a moving average of width ``w``:

.. math::

    s_f(t) = \\frac{1}{w} \\int_{t-w}^{t} s(\\tau)\\, d\\tau, \\qquad
    \\dot s_f = \\frac{s(t) - s(t-w)}{w}, \\quad \\ddot s_f = \\frac{\\dot s(t) - \\dot s(t-w)}{w}, \\quad
    \\dddot s_f = \\frac{\\ddot s(t) - \\ddot s(t-w)}{w}

with ``s`` held at 0 before the start and at the end after ``T``. Then ``s_f`` is monotone, runs from rest to rest in
``T + w``, its path acceleration is continuous and its path jerk bounded; ``q(s_f(t))`` follows the *same geometric
path* (so it passes through every waypoint) with continuous joint acceleration (the spline is C²), zero acceleration
at both ends and bounded jerk. This is the FIR-filter construction of Biagiotti & Melchiorri ("FIR filters for online
trajectory planning with time- and frequency-domain specifications", 2012) applied to the path parameter; for a
single joint at rest-to-rest it reproduces the time-optimal jerk-limited duration ``T + a/j`` when
``w = a/j``.

``s_f`` is a cubic in ``t`` between breakpoints (TOPP-RA's gridpoint times, the same shifted by ``w``, and the times
the filtered timing crosses a waypoint), so ``q(s_f(t))`` is an exact degree-9 polynomial there. Its peaks of
velocity, acceleration and jerk are computed exactly and any excess is removed by uniform time scaling (velocity
/c, acceleration /c², jerk /c³). Where the filtered result exceeds a limit, the TOPP-RA limits of the
gridpoints feeding that stretch are tightened locally and TOPP-RA is solved again (a few rounds); a few filter
widths are tried each round and the shortest verified result is kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from taplan.errors import InvalidInputError
from taplan.limits import JointLimits
from taplan.timing._polynomial import compose_quadratic, max_abs_derivative, time_scaled
from taplan.timing.path import Path
from taplan.timing.toppra_retime import (
    DEFAULT_POINTS_PER_SEGMENT,
    LIMIT_MARGIN,
    PathProfile,
    as_path,
    check_path_positions,
    grid_for,
    time_optimal_profile,
)
from taplan.trajectory import Trajectory

__all__ = ["jerk_limited", "JerkLimitedResult", "filter_profile"]

DEFAULT_WIDTH_FACTORS = (1.5, 2.0, 2.5)  # x max_j(a_j / j_j)
DEFAULT_JERK_FRACTION = 1.0  # share of the jerk limit left to the speed-only term q''' sd^3
DEFAULT_REPAIRS = 5
TIGHTEN_EXPONENT = 0.8  # partial step: limits scaled by 1 / ratio**0.8 per repair round (full steps over-tighten)
_BISECTIONS = 60


@dataclass(frozen=True)
class JerkLimitedResult:
    """A jerk-limited trajectory and how it was obtained.

    Attributes:
        trajectory: The trajectory (polynomial, starts at t = 0).
        topp_duration: Duration of the TOPP-RA (velocity/acceleration only) timing under the full limits [s].
        width: Moving-average width used [s].
        time_scale: Uniform time scaling applied after filtering (>= 1).
    """

    trajectory: Trajectory
    topp_duration: float
    width: float
    time_scale: float

    @property
    def duration_ratio(self) -> float:
        """Duration over the TOPP-RA duration."""
        return self.trajectory.duration / self.topp_duration


class _Timing:
    """Evaluate a piecewise-constant-acceleration timing s(t), held before 0 and after T."""

    def __init__(self, profile: PathProfile) -> None:
        self.t = profile.times
        self.s = profile.gridpoints
        self.sd = profile.sd
        self.u = profile.sdd
        dt = np.diff(self.t)
        area = self.s[:-1] * dt + self.sd[:-1] * dt**2 / 2 + self.u * dt**3 / 6
        self.S = np.concatenate([[0.0], np.cumsum(area)])  # integral of s from 0 to t_i

    def eval(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(integral of s, s, sd, sdd (right limit)) at times t."""
        T = self.t[-1]
        tc = np.clip(t, 0.0, T)
        i = np.clip(np.searchsorted(self.t, tc, side="right") - 1, 0, len(self.u) - 1)
        tau = tc - self.t[i]
        s = self.s[i] + self.sd[i] * tau + self.u[i] * tau**2 / 2
        sd = self.sd[i] + self.u[i] * tau
        sdd = self.u[i].copy()
        S = self.S[i] + self.s[i] * tau + self.sd[i] * tau**2 / 2 + self.u[i] * tau**3 / 6
        before, after = t < 0.0, t >= T
        S = np.where(before, 0.0, np.where(after, self.S[-1] + self.s[-1] * (t - T), S))
        s = np.where(before, self.s[0], np.where(after, self.s[-1], s))
        sd = np.where(before | after, 0.0, sd)
        sdd = np.where(before | after, 0.0, sdd)
        return S, s, sd, sdd


def _filtered_coefficients(timing: _Timing, w: float, b: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Cubic coefficients (m, 4) of s_f on pieces [b, b + h], ascending powers of (t - b).

    Evaluated at each piece's midpoint (never on a breakpoint, where the right/left limits of the path acceleration
    would be ambiguous in floating point), then re-expanded about the piece start.
    """
    mid = b + h / 2
    S1, s1, sd1, sdd1 = timing.eval(mid)
    S0, s0, sd0, sdd0 = timing.eval(mid - w)
    s_start = timing.s[0]
    c0 = s_start + (S1 - S0 - s_start * w) / w  # s is held at s_start before 0
    c1, c2, c3 = (s1 - s0) / w, (sd1 - sd0) / (2 * w), (sdd1 - sdd0) / (6 * w)
    d = -h / 2  # p(x) with x = tau - h/2: expand sum c_i (tau + d)^i
    return np.column_stack([c0 + d * (c1 + d * (c2 + d * c3)), c1 + d * (2 * c2 + 3 * d * c3), c2 + 3 * d * c3, c3])


def filter_profile(profile: PathProfile, width: float, joint_names: tuple[str, ...] | None = None) -> Trajectory:
    """The exact joint trajectory ``q(s_f(t))`` of the moving-average-filtered timing (rest-to-rest profile).

    Args:
        profile: A TOPP-RA timing with zero path speed at both ends.
        width: Filter width w [s] > 0; the duration grows by w.
        joint_names: Names for the trajectory.
    """
    w = float(width)
    timing = _Timing(profile)
    T = profile.duration
    b = np.unique(np.concatenate([profile.times, profile.times + w]))
    b = b[np.concatenate([[True], np.diff(b) > 1e-12])]
    h = np.diff(b)
    c = _filtered_coefficients(timing, w, b[:-1], h)
    # times where the filtered timing crosses a waypoint (the spline's knots): extra breakpoints
    ss = profile.path.ss_waypoints[1:-1]
    s_lo = c[:, 0]
    s_hi = c[:, 0] + h * (c[:, 1] + h * (c[:, 2] + h * c[:, 3]))
    seg = np.searchsorted(s_hi, ss, side="left")
    seg = np.clip(seg, 0, len(h) - 1)
    inside = (s_lo[seg] < ss) & (ss < s_hi[seg])
    seg, target = seg[inside], ss[inside]
    lo, hi = np.zeros(seg.shape), h[seg].copy()
    cs = c[seg]
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        val = cs[:, 0] + mid * (cs[:, 1] + mid * (cs[:, 2] + mid * cs[:, 3]))
        below = val < target
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    crossings = b[seg] + 0.5 * (lo + hi)
    b = np.unique(np.concatenate([b, crossings]))
    b = b[np.concatenate([[True], np.diff(b) > 1e-12])]
    b[-1] = T + w
    h = np.diff(b)
    c = _filtered_coefficients(timing, w, b[:-1], h)
    mid_s = c[:, 0] + (h / 2) * (c[:, 1] + (h / 2) * (c[:, 2] + (h / 2) * c[:, 3]))
    path = profile.path
    piece = path.piece_index(mid_s)
    sigma = c.copy()
    sigma[:, 0] -= path.ss_waypoints[piece]
    coefficients = compose_quadratic(path.piece_coefficients()[piece], sigma)
    return Trajectory.from_polynomials(b - b[0], coefficients, joint_names)


def jerk_limited(
    path_or_waypoints: Path | npt.ArrayLike,
    limits: JointLimits,
    *,
    width_factors: tuple[float, ...] = DEFAULT_WIDTH_FACTORS,
    jerk_fraction: float = DEFAULT_JERK_FRACTION,
    repairs: int = DEFAULT_REPAIRS,
    points_per_segment: int = DEFAULT_POINTS_PER_SEGMENT,
    check_positions: bool = True,
) -> JerkLimitedResult:
    """Jerk-limited rest-to-rest trajectory along the path through the waypoints.

    Every velocity, acceleration and jerk stays within ``limits`` at every instant (verified exactly on the
    polynomial segments), acceleration is continuous and zero at both ends, and the waypoints are passed exactly.

    Repair: where the filtered trajectory exceeds a limit (by a ratio r), the TOPP-RA velocity and acceleration
    limits of the gridpoints that feed that stretch (the window ``[t - w, t]``) are scaled by 1/r**0.8
    (``TIGHTEN_EXPONENT``: full steps over-tighten) and TOPP-RA is solved again, ``repairs`` times; any excess left
    is removed by uniform time scaling.

    Args:
        path_or_waypoints: A :class:`~taplan.timing.path.Path` or waypoints [rad], shape (N, n).
        limits: Joint limits (velocity, acceleration, jerk; positions are checked).
        width_factors: Filter widths tried, as multiples of ``max_j(acceleration_j / jerk_j)`` [s].
        jerk_fraction: Share of the jerk limit left to the speed-only jerk term ``q''' sd^3``, in (0, 1].
        repairs: Local tighten-and-re-solve rounds.
        points_per_segment: TOPP-RA grid segments per waypoint interval.
        check_positions: Raise when the path leaves the position limits.

    Returns:
        The shortest candidate, with its duration ratio to TOPP-RA.

    Raises:
        InvalidInputError: malformed inputs. TimingError: no feasible timing.
    """
    if not isinstance(limits, JointLimits):
        raise InvalidInputError("limits", type(limits).__name__, "a taplan.JointLimits")
    if not width_factors or any(not (np.isfinite(f) and f > 0) for f in width_factors):
        raise InvalidInputError("width_factors", width_factors, "positive numbers")
    if not (0 < jerk_fraction <= 1):
        raise InvalidInputError("jerk_fraction", jerk_fraction, "a number in (0, 1]")
    if int(repairs) < 0:
        raise InvalidInputError("repairs", repairs, "an integer >= 0")
    path, _, _ = as_path(path_or_waypoints, limits.size)
    if check_positions:
        check_path_positions(path, limits)
    vel = np.asarray(limits.velocity, dtype=float)
    acc = np.asarray(limits.acceleration, dtype=float)
    jerk = np.asarray(limits.jerk, dtype=float)
    base = float(np.max(acc / jerk))
    topp_duration = time_optimal_profile(path, vel, acc, points_per_segment=points_per_segment).duration
    scale = np.ones(len(grid_for(path, points_per_segment)))
    best: JerkLimitedResult | None = None
    for _ in range(int(repairs) + 1):
        profile = time_optimal_profile(
            path,
            vel,
            acc,
            points_per_segment=points_per_segment,
            jerk=jerk,
            jerk_fraction=jerk_fraction,
            limit_scale=scale,
        )
        round_best = None
        for factor in width_factors:
            w = factor * base
            traj = filter_profile(profile, w, limits.names)
            rv = np.max(max_abs_derivative(traj, 1) / vel, axis=1)
            ra = np.max(max_abs_derivative(traj, 2) / acc, axis=1)
            rj = np.max(max_abs_derivative(traj, 3) / jerk, axis=1)
            c = max(1.0, float(rv.max()), float(np.sqrt(ra.max())), float(np.cbrt(rj.max()))) * (1.0 + LIMIT_MARGIN)
            if round_best is None or traj.duration * c < round_best[0]:
                round_best = (traj.duration * c, traj, w, c, np.maximum(np.maximum(rv, ra), rj))
        assert round_best is not None
        duration, traj, w, c, segment_ratio = round_best
        if best is None or duration < best.trajectory.duration:
            best = JerkLimitedResult(time_scaled(traj, c) if c > 1.0 else traj, topp_duration, w, c)
        if c <= 1.0:
            break
        scale = _tighten(scale, profile.times, traj.times, w, segment_ratio)
    assert best is not None
    return best


def _tighten(scale: np.ndarray, grid_times: np.ndarray, times: np.ndarray, w: float, ratio: np.ndarray) -> np.ndarray:
    """Scale down the limits of the gridpoints feeding each filtered segment that exceeds a limit by ``ratio``."""
    out = scale.copy()
    for k in np.flatnonzero(ratio > 1.0):
        lo = max(int(np.searchsorted(grid_times, times[k] - w)) - 1, 0)
        hi = min(int(np.searchsorted(grid_times, times[k + 1])) + 1, len(out))
        out[lo:hi] = np.minimum(out[lo:hi], scale[lo:hi] / ratio[k] ** TIGHTEN_EXPONENT)
    return out
