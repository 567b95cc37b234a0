"""taplan.timing.straight_line: ruckig's time-optimal jerk-limited straight segment, checked against the closed-form
1-DOF duration, the TOPP-RA optimum, exact limit usage and the segment itself."""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from taplan.errors import InvalidInputError
from taplan.limits import JointLimits
from taplan.timing import jerk_limited, limit_usage, retime, straight_line
from taplan.timing.straight import rest_to_rest_time, ruckig_input


def _one_joint(v: float, a: float, j: float) -> JointLimits:
    return JointLimits(("j",), np.array([-10.0]), np.array([10.0]), np.array([v]), np.array([a]), np.array([j]))


def test_one_joint_matches_the_closed_form_duration() -> None:
    # cruise reached: T = L/v + v/a + a/j when v >= a²/j and L >= v (v/a + a/j)
    v, a, j, length = 1.0, 2.0, 10.0, 2.0
    trajectory = straight_line([0.0], [length], _one_joint(v, a, j))
    assert trajectory.duration == pytest.approx(length / v + v / a + a / j, abs=1e-9)  # [s]
    # no cruise, acceleration reached: T = a/j + sqrt((a/j)² + 4L/a) for v large
    length = 0.5
    trajectory = straight_line([0.0], [length], _one_joint(100.0, a, j))
    assert trajectory.duration == pytest.approx(a / j + np.sqrt((a / j) ** 2 + 4 * length / a), abs=1e-9)  # [s]
    np.testing.assert_allclose(trajectory(trajectory.duration), [length], atol=1e-12)


def test_dual_arm_segment_stays_on_the_line_within_the_limits() -> None:
    robot = taplan.Robot.teleavatar()
    limits = robot.planning_limits
    rng = np.random.default_rng(7)
    for _ in range(5):
        a = limits.lower + rng.uniform(0.1, 0.9, robot.nq) * (limits.upper - limits.lower)
        b = limits.lower + rng.uniform(0.1, 0.9, robot.nq) * (limits.upper - limits.lower)
        trajectory = straight_line(a, b, limits)
        assert limit_usage(trajectory, limits).within(1e-9, jerk=True)  # exact peaks, relative
        q = trajectory(np.linspace(0.0, trajectory.duration, 400))
        s = (q - a) @ (b - a) / ((b - a) @ (b - a))
        assert np.abs(q - (a + s[:, None] * (b - a))).max() < 1e-9  # on the segment [rad]
        assert np.all(np.diff(s) >= -1e-12)  # monotone: never backs up
        np.testing.assert_allclose(trajectory(0.0), a, atol=1e-12)
        np.testing.assert_allclose(trajectory(trajectory.duration), b, atol=1e-9)
        np.testing.assert_allclose(trajectory(trajectory.duration, 1), 0.0, atol=1e-9)
        optimum = retime(np.linspace(a, b, 5), limits).duration  # TOPP-RA, no jerk limit
        ramp = float(np.max(limits.acceleration / limits.jerk))
        assert optimum - 1e-3 <= trajectory.duration <= optimum + 1.5 * ramp  # [s]: about one jerk ramp more
        assert trajectory.duration < jerk_limited(np.linspace(a, b, 5), limits).trajectory.duration


def test_bad_input_is_named() -> None:
    limits = _one_joint(1.0, 2.0, 10.0)
    with pytest.raises(InvalidInputError, match="goal"):
        straight_line([0.0], [0.0], limits)
    with pytest.raises(InvalidInputError, match="goal"):
        straight_line([0.0], [11.0], limits)
    with pytest.raises(InvalidInputError, match="start"):
        straight_line([np.nan], [1.0], limits)
    with pytest.raises(InvalidInputError, match="limits"):
        straight_line([0.0], [1.0], {"velocity": 1.0})


def test_state_to_state_meets_the_goal_state_within_the_limits(teleavatar) -> None:
    from taplan.timing import limit_usage
    from taplan.timing.straight import state_to_state

    limits = teleavatar.planning_limits.subset(teleavatar.group("left").joint_names)
    rng = np.random.default_rng(21)
    q0 = teleavatar.home[:7]
    goal = (q0 + rng.uniform(-0.3, 0.3, 7), 0.3 * limits.velocity * rng.uniform(-1, 1, 7), np.zeros(7))
    start = (q0, np.zeros(7), 0.5 * limits.acceleration * rng.uniform(-1, 1, 7))
    motion = state_to_state(start, goal, limits)
    for k in range(3):  # exact cubic pieces: the states at both ends to 1e-9
        np.testing.assert_allclose(motion(0.0, k), start[k], atol=1e-9)
        np.testing.assert_allclose(motion(motion.duration, k), goal[k], atol=1e-7)
    assert limit_usage(motion, limits).within(1e-9, jerk=True)


def test_near_cubic_bounds_contain_the_sampled_range_and_peaks() -> None:
    # ruckig's windows in jerk_limited are checked with these bounds: never below the truth, tight for cubics
    from taplan.timing._polynomial import max_abs_derivative, near_cubic_bounds

    rng = np.random.default_rng(3)
    times = np.array([0.0, 0.3, 0.7, 1.0])
    coefficients = np.zeros((3, 6, 2))
    coefficients[:, :4] = rng.normal(size=(3, 4, 2))
    coefficients[:, 4:] = 1e-9 * rng.normal(size=(3, 2, 2))  # like ruckig's end correction
    for k in (1, 2):  # continuous position and velocity across the pieces
        h = times[k] - times[k - 1]
        coefficients[k, 0] = sum(coefficients[k - 1, i] * h**i for i in range(6))
        coefficients[k, 1] = sum(i * coefficients[k - 1, i] * h ** (i - 1) for i in range(1, 6))
    traj = taplan.Trajectory.from_polynomials(times, coefficients)
    low, high, peaks = near_cubic_bounds(times, coefficients)
    q = traj(np.linspace(0.0, 1.0, 200_001))
    assert np.all(low <= q.min(axis=0)) and np.all(high >= q.max(axis=0))
    np.testing.assert_allclose(low, q.min(axis=0), atol=1e-8)
    np.testing.assert_allclose(high, q.max(axis=0), atol=1e-8)
    for order in (1, 2, 3):
        exact = max_abs_derivative(traj, order).max(axis=0)
        assert np.all(peaks[order - 1] >= exact)
        np.testing.assert_allclose(peaks[order - 1], exact, rtol=1e-7)


def test_rest_to_rest_time_equals_ruckigs_one_joint_duration() -> None:
    """The closed-form time-optimal rest-to-rest duration (the fallback timings' floor in plan_motion) equals
    ruckig's one-joint duration in every regime: cruise or not, acceleration limit reached or not."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        v, a, j = rng.uniform(0.1, 3.0), rng.uniform(0.2, 10.0), rng.uniform(0.5, 80.0)
        length = 10 ** rng.uniform(-4, 0.9)
        expected = straight_line([0.0], [length], _one_joint(v, a, j)).duration
        assert rest_to_rest_time(length, v, a, j) == pytest.approx(expected, abs=1e-9)  # [s]
    several = rest_to_rest_time([0.0, 0.3, 2.0], [1.0, 1.0, 1.0], 2.0, 10.0)  # broadcast over joints
    assert several.shape == (3,) and several[0] == 0.0 and several[1] < several[2]
    with pytest.raises(InvalidInputError, match="distance"):
        rest_to_rest_time(-0.1, 1.0, 1.0, 1.0)


def test_state_to_state_pieces_follow_ruckigs_motion_on_both_arms(teleavatar) -> None:
    """The pieces integrate ruckig's constant jerk per phase (a running sum over the pieces): positions, velocities
    and accelerations equal ruckig's own motion at any time, for 14 joints from moving states."""
    import ruckig

    from taplan.timing.straight import state_to_state

    limits = teleavatar.planning_limits
    n = limits.size
    rng = np.random.default_rng(5)
    for _ in range(5):
        start = (
            teleavatar.home + rng.uniform(-0.3, 0.3, n),
            0.3 * limits.velocity * rng.uniform(-1, 1, n),
            np.zeros(n),
        )
        goal = (teleavatar.home + rng.uniform(-0.5, 0.5, n), 0.2 * limits.velocity * rng.uniform(-1, 1, n), np.zeros(n))
        motion = state_to_state(start, goal, limits)
        reference = ruckig.Trajectory(n)
        ruckig.Ruckig(n).calculate(ruckig_input(start, goal, limits), reference)
        assert motion.duration == pytest.approx(reference.duration, abs=1e-12)
        for t in np.linspace(0.0, motion.duration, 97):
            expected = reference.at_time(float(t))
            for k in range(3):  # [rad], [rad/s], [rad/s²]: ruckig's own states drift by up to a few 1e-9
                np.testing.assert_allclose(motion(t, k), expected[k], atol=1e-8)
