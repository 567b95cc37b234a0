"""taplan.timing.optimize: bounds hold exactly, minimum time beats its warm start, waypoints met, bad inputs."""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from benchmarks._paths import random_walk
from taplan.errors import InvalidInputError, TimingError, UnknownNameError
from taplan.timing import OptimizationResult, jerk_limited, limit_usage, optimize, retime, sampled_limit_usage

LIMIT_TOL = 1e-6  # relative: |qd|/v, |qdd|/a, |jerk|/j <= 1 + LIMIT_TOL
WAYPOINT_TOL = 1e-6  # [rad]
REST_TOL = 1e-6  # [rad]/[s] and [rad]/[s]^2 at both ends
BOX = 0.02  # [rad] waypoint tolerance box
DURATION_TOL = 1e-6  # [s]


@pytest.fixture(scope="module")
def arm_limits(teleavatar: taplan.Robot) -> taplan.JointLimits:
    return teleavatar.planning_limits.subset(teleavatar.group("left").joint_names)


@pytest.fixture(scope="module")
def waypoints(arm_limits: taplan.JointLimits) -> np.ndarray:
    return random_walk(arm_limits, 5, 0)


@pytest.fixture(scope="module")
def min_time(waypoints: np.ndarray, arm_limits: taplan.JointLimits) -> OptimizationResult:
    return optimize(waypoints, arm_limits, objective="time")


@pytest.fixture(scope="module")
def min_jerk(waypoints: np.ndarray, arm_limits: taplan.JointLimits) -> OptimizationResult:
    return optimize(waypoints, arm_limits, objective="jerk")  # at the jerk-limited duration


def check_bounds(res: OptimizationResult, limits: taplan.JointLimits) -> None:
    exact = limit_usage(res.trajectory, limits)
    sampled = sampled_limit_usage(res.trajectory, limits, rate=1000.0)
    assert exact.within(LIMIT_TOL, jerk=True)
    assert sampled.within(LIMIT_TOL, jerk=True)
    assert float(exact.position.max()) <= WAYPOINT_TOL


@pytest.mark.parametrize("which", ["min_time", "min_jerk"])
def test_bounds_hold_exactly(request: pytest.FixtureRequest, which: str, arm_limits: taplan.JointLimits) -> None:
    check_bounds(request.getfixturevalue(which), arm_limits)


@pytest.mark.parametrize("which", ["min_time", "min_jerk"])
def test_waypoints_met_and_rest_at_ends(request: pytest.FixtureRequest, which: str, waypoints: np.ndarray) -> None:
    res = request.getfixturevalue(which)
    np.testing.assert_allclose(res.trajectory(res.waypoint_times), waypoints, atol=WAYPOINT_TOL)
    assert res.waypoint_error <= WAYPOINT_TOL
    for t in res.trajectory.times[[0, -1]]:
        np.testing.assert_allclose(res.trajectory(t, 1), 0.0, atol=REST_TOL)
        np.testing.assert_allclose(res.trajectory(t, 2), 0.0, atol=REST_TOL)


def test_minimum_time_is_no_longer_than_its_warm_start(min_time: OptimizationResult) -> None:
    assert min_time.duration <= min_time.warm_start.duration + DURATION_TOL
    assert min_time.usage.max_jerk > 0.99  # time-optimal: the jerk bound is active somewhere


def test_minimum_time_is_no_longer_than_topp_warm_start(waypoints: np.ndarray, arm_limits) -> None:
    res = optimize(waypoints, arm_limits, objective="time", warm_start="topp")
    assert res.duration <= retime(waypoints, arm_limits).duration + DURATION_TOL
    check_bounds(res, arm_limits)


def test_minimum_jerk_keeps_the_requested_duration(waypoints: np.ndarray, arm_limits) -> None:
    duration = 1.3 * jerk_limited(waypoints, arm_limits).trajectory.duration
    res = optimize(waypoints, arm_limits, objective="jerk", duration=duration)
    assert res.duration == pytest.approx(duration, abs=DURATION_TOL)
    assert res.time_scale == 1.0
    check_bounds(res, arm_limits)


def test_minimum_jerk_is_smoother_than_its_warm_start(min_jerk: OptimizationResult, arm_limits) -> None:
    def jerk_cost(traj: taplan.Trajectory) -> float:  # ∫ Σ (jerk / limit)² dt, sampled at 2 kHz
        t = traj.sample_times(2000.0)
        return float(np.sum((traj(t, 3) / arm_limits.jerk) ** 2) / 2000.0)

    assert min_jerk.duration == pytest.approx(min_jerk.warm_start.duration, abs=DURATION_TOL)
    assert jerk_cost(min_jerk.trajectory) < jerk_cost(min_jerk.warm_start)
    assert jerk_cost(min_jerk.trajectory) == pytest.approx(min_jerk.cost, rel=1e-2)


def test_tolerance_box_shortens_the_motion(waypoints: np.ndarray, arm_limits, min_time: OptimizationResult) -> None:
    res = optimize(waypoints, arm_limits, objective="time", tolerance=BOX)
    err = np.abs(res.trajectory(res.waypoint_times) - waypoints)
    assert err.max() <= BOX + WAYPOINT_TOL
    np.testing.assert_allclose(err[[0, -1]], 0.0, atol=WAYPOINT_TOL)  # ends are exact
    assert res.duration <= min_time.duration + DURATION_TOL
    check_bounds(res, arm_limits)


def test_single_joint_rest_to_rest_matches_the_jerk_limited_optimum() -> None:
    limits = taplan.JointLimits.from_arrays(["j"], [-5.0], [5.0], [2.0], [4.0], [16.0])
    res = optimize([[0.0], [1.0]], limits, objective="time", intervals=12)
    optimum = _jerk_limited_rest_to_rest(1.0, 2.0, 4.0, 16.0)  # 1.2808 s
    assert res.duration >= optimum * (1 - 1e-6)  # nothing beats the analytic optimum
    assert res.duration <= optimum * 1.02  # equal interval durations: within 2 % of it


def _jerk_limited_rest_to_rest(d: float, v: float, a: float, j: float) -> float:
    """Time-optimal rest-to-rest duration [s] of the 7-phase jerk-limited profile (distance d, limits v, a, j)."""

    def ramp(vp: float) -> float:  # time from rest to speed vp and its distance vp * ramp / 2
        return a / j + vp / a if vp * j >= a * a else 2.0 * np.sqrt(vp / j)

    if v * ramp(v) <= d:
        return 2.0 * ramp(v) + (d - v * ramp(v)) / v
    lo, hi = 0.0, v
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mid * ramp(mid) <= d else (lo, mid)
    return 2.0 * ramp(lo)


def test_too_short_duration_raises(waypoints: np.ndarray, arm_limits, min_time: OptimizationResult) -> None:
    with pytest.raises(TimingError, match="ipopt failed"):
        optimize(waypoints, arm_limits, objective="jerk", duration=0.5 * min_time.duration, max_iterations=200)


@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"objective": "energy"}, UnknownNameError),
        ({"warm_start": "linear"}, UnknownNameError),
        ({"intervals": 0}, InvalidInputError),
        ({"tolerance": -0.1}, InvalidInputError),
        ({"tolerance": [0.1, 0.2]}, InvalidInputError),
        ({"duration": -1.0, "objective": "jerk"}, InvalidInputError),
        ({"max_iterations": 0}, InvalidInputError),
    ],
)
def test_bad_options_raise(waypoints: np.ndarray, arm_limits, kwargs: dict, error: type[Exception]) -> None:
    with pytest.raises(error):
        optimize(waypoints, arm_limits, **kwargs)


def test_bad_waypoints_raise(waypoints: np.ndarray, arm_limits: taplan.JointLimits) -> None:
    with pytest.raises(InvalidInputError):
        optimize(waypoints[:1], arm_limits)  # one waypoint
    bad = waypoints.copy()
    bad[2, 3] = np.nan
    with pytest.raises(InvalidInputError):
        optimize(bad, arm_limits)
    with pytest.raises(InvalidInputError):
        optimize(np.vstack([waypoints[:2], waypoints[1:2]]), arm_limits)  # duplicate
    outside = waypoints.copy()
    outside[1, 0] = arm_limits.upper[0] + 0.1
    with pytest.raises(InvalidInputError, match="within the limits"):
        optimize(outside, arm_limits)
    with pytest.raises(InvalidInputError):
        optimize(waypoints[:, :6], arm_limits)
