"""Any path whose waypoints are inside the position limits is timed, inside every limit, through its waypoints.

The limits are checked twice: exactly on the polynomial pieces (``limit_usage``) and independently by finite
differences of the positions sampled at 10 kHz (a k-th difference over dt**k is a positive-kernel average of the
k-th derivative, so it can never exceed the true peak: any excess beyond rounding is a real violation).
"""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from benchmarks._paths import near_bound_walk
from taplan.errors import InvalidInputError, TimingError
from taplan.timing import Path, jerk_limited, limit_usage, retime

LIMIT_TOL = 1e-6  # relative: exact peaks / limit
POS_TOL = 1e-9  # [rad] position excursion outside the bounds (rounding only)
WAYPOINT_TOL = 1e-9  # [rad] distance from a waypoint the trajectory promises to pass exactly
FD_RATE = 10_000.0  # [Hz] independent finite-difference check
FD_ROUNDING = (1e-9, 1e-6, 1e-2)  # [rad/s], [rad/s²], [rad/s³]: float64 rounding of 1st/2nd/3rd differences at 10 kHz


@pytest.fixture(scope="module")
def arm(teleavatar: taplan.Robot) -> taplan.JointLimits:
    return teleavatar.planning_limits.subset(teleavatar.group("right").joint_names)


def finite_difference_excess(traj: taplan.Trajectory, limits: taplan.JointLimits, jerk: bool) -> float:
    """Largest |k-th difference| / dt**k over its limit (k = 1, 2, and 3 when ``jerk``), and position excursion:
    a value > 0 is a violation."""
    dt = 1.0 / FD_RATE
    t = np.arange(0.0, traj.duration + dt, dt)
    q = traj(np.minimum(t, traj.duration))
    q = np.vstack([np.repeat(q[:1], 3, axis=0), q, np.repeat(q[-1:], 3, axis=0)])  # at rest before and after
    worst = float(np.max(np.maximum(q - limits.upper, limits.lower - q))) - POS_TOL
    bounds = (limits.velocity, limits.acceleration, limits.jerk)
    for k in range(1, 4 if jerk else 3):
        derivative = np.diff(q, n=k, axis=0) / dt**k
        excess = np.abs(derivative) - bounds[k - 1] * (1 + LIMIT_TOL) - FD_ROUNDING[k - 1]
        worst = max(worst, float(excess.max()))
    return worst


def passes_waypoints(traj: taplan.Trajectory, waypoints: np.ndarray) -> float:
    """Largest distance [rad] (max-norm) from a waypoint to the trajectory's breakpoints, where retime puts them."""
    return float(max(np.min(np.max(np.abs(traj.positions - w), axis=1)) for w in waypoints))


SWEEP = [(size, seed) for size, seeds in ((2, 6), (3, 4), (5, 3), (12, 3), (40, 2), (80, 1)) for seed in range(seeds)]


@pytest.mark.parametrize(("size", "seed"), SWEEP)
def test_near_bound_sweep_retime_and_joint_filter(arm: taplan.JointLimits, size: int, seed: int) -> None:
    q = near_bound_walk(arm, size, 7919 * size + seed)
    fast = retime(q, arm)
    usage = limit_usage(fast, arm)
    assert usage.within(LIMIT_TOL) and usage.position.max() <= POS_TOL
    assert finite_difference_excess(fast, arm, jerk=False) <= 0.0
    assert passes_waypoints(fast, q) <= WAYPOINT_TOL
    smooth = jerk_limited(q, arm)
    usage = limit_usage(smooth.trajectory, arm)
    assert usage.within(LIMIT_TOL, jerk=True) and usage.position.max() <= POS_TOL
    assert finite_difference_excess(smooth.trajectory, arm, jerk=True) <= 0.0
    np.testing.assert_allclose(smooth.trajectory(0.0), q[0], atol=WAYPOINT_TOL)
    np.testing.assert_allclose(smooth.trajectory(smooth.trajectory.duration), q[-1], atol=WAYPOINT_TOL)


@pytest.mark.parametrize(("size", "seed"), [(2, 0), (4, 1), (9, 2)])
def test_near_bound_sweep_path_filter(arm: taplan.JointLimits, size: int, seed: int) -> None:
    q = near_bound_walk(arm, size, 104729 + 31 * size + seed)
    result = jerk_limited(q, arm, method="path")
    usage = limit_usage(result.trajectory, arm)
    assert usage.within(LIMIT_TOL, jerk=True) and usage.position.max() <= POS_TOL
    assert finite_difference_excess(result.trajectory, arm, jerk=True) <= 0.0
    assert result.deviation == 0.0


@pytest.mark.parametrize(
    ("count", "seed", "start", "stop"),
    [(5000, 7_000_003 + 59, 1585, 1598), (15, 7_000_003 + 127, 0, 15)],
    ids=["clipped-slope-knot", "barely-moving-stretch"],
)
def test_paths_toppras_lp_found_uncontrollable_are_timed(arm, count: int, seed: int, start: int, stop: int) -> None:
    # found by bench_timing's sweep: a knot where a joint's slope was clipped to ~1e-7 next to tiny steps, and a
    # stretch where the path barely moves (velocity rows of size 1e-5); toppra's seidel LP returned NaN on both
    # ("not controllable") until the constraint rows were normalised
    q = near_bound_walk(arm, count, seed)[start:stop]
    fast = retime(q, arm)
    usage = limit_usage(fast, arm)
    assert usage.within(LIMIT_TOL) and usage.position.max() <= POS_TOL
    assert finite_difference_excess(fast, arm, jerk=False) <= 0.0
    assert passes_waypoints(fast, q) <= WAYPOINT_TOL
    for method in ("joint", "path"):
        smooth = jerk_limited(q, arm, method=method).trajectory
        usage = limit_usage(smooth, arm)
        assert usage.within(LIMIT_TOL, jerk=True) and usage.position.max() <= POS_TOL
        assert finite_difference_excess(smooth, arm, jerk=True) <= 0.0


def test_bounded_path_stays_in_the_box_where_the_spline_overshoots() -> None:
    # a joint that climbs onto its bound and turns back: the cubic spline overshoots the top between waypoints
    q = np.array([[0.0], [0.45], [0.6], [0.6 - 1e-4], [0.2], [0.59]])
    lower, upper = np.array([-0.6]), np.array([0.6])
    plain, bounded = Path(q), Path(q, bounds=(lower, upper))
    s = np.linspace(*plain.path_interval, 20001)
    assert plain(s).max() > upper[0] + 1e-3  # the failure, reproduced
    assert bounded(s).max() <= upper[0] and bounded(s).min() >= lower[0]
    assert bounded.degree == 5 and plain.degree == 3
    np.testing.assert_allclose(bounded(bounded.ss_waypoints), q, atol=1e-15)
    knots = bounded.ss_waypoints[1:-1]
    for order in (0, 1, 2):  # C²: the same value and first two derivatives from both sides of every knot
        np.testing.assert_allclose(bounded(knots - 1e-9, order), bounded(knots + 1e-9, order), atol=1e-6)
    assert bounded(0.6 * 0 + bounded.ss_waypoints[2], 1)[0] == 0.0  # on the bound: zero slope


def test_bounded_path_is_the_spline_when_nothing_overshoots() -> None:
    q = np.array([[0.0, 0.1], [0.2, 0.0], [0.1, 0.3], [0.3, 0.2]])
    plain, bounded = Path(q), Path(q, bounds=(np.full(2, -3.0), np.full(2, 3.0)))
    s = np.linspace(*plain.path_interval, 101)
    np.testing.assert_array_equal(plain(s), bounded(s))


def test_duplicates_and_tiny_paths_are_timed(arm: taplan.JointLimits) -> None:
    a, b, c = near_bound_walk(arm, 3, 5)[[0, 1, 2]]
    traj = retime(np.array([a, a, b, b, b, c, c]), arm)
    assert traj.duration == pytest.approx(retime(np.array([a, b, c]), arm).duration, rel=1e-9)
    np.testing.assert_allclose(traj(traj.duration), c, atol=WAYPOINT_TOL)
    tiny = np.array([a, a + 1e-7 * np.sign(0.5 - (a - arm.lower) / (arm.upper - arm.lower))])  # 0.1 µrad, inwards
    smooth = jerk_limited(tiny, arm)
    assert limit_usage(smooth.trajectory, arm).within(LIMIT_TOL, jerk=True)
    np.testing.assert_allclose(smooth.trajectory(smooth.trajectory.duration), tiny[-1], atol=1e-15)


def test_really_infeasible_inputs_say_why(arm: taplan.JointLimits) -> None:
    q = near_bound_walk(arm, 4, 11)
    q[2, 6] = arm.upper[6] + 0.01
    for timing in (retime, jerk_limited):
        with pytest.raises(
            TimingError,
            match=r"waypoint 2 is outside the position limits: r_joint7 = 0\.59 rad \(limits \[-0\.58, 0\.58\]\)",
        ):
            timing(q, arm)
    with pytest.raises(InvalidInputError, match="all equal"):
        retime(np.repeat(q[:1], 3, axis=0), arm)
    outside = Path(np.array([[0.0], [0.45], [0.6], [0.2]]))  # a Path made without bounds overshoots: refused
    with pytest.raises(TimingError, match="leaves the position limits"):
        retime(outside, taplan.JointLimits.from_arrays(["j"], [-0.6], [0.6], [1.0], [1.0]))
