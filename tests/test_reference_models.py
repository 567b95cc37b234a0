"""Intended-mode simulator, JointTrajectoryController and JointModeRobot on hand-computed cases."""

from __future__ import annotations

import numpy as np
import pytest

from taplan.errors import InvalidInputError
from taplan.limits import JointLimits
from taplan.reference import ARM_KP, IndustrialSimulator, JointModeRobot, JointTrajectoryController
from taplan.trajectory import Trajectory, Waypoint

POS_TOL = 1e-12  # [rad]
VEL_TOL = 1e-9  # [rad]/[s]


# ------------------------------------------------------------------------------------ intended simulator
def test_intended_linear_matches_slopes_and_is_continuous() -> None:
    wps = [Waypoint(0.0, np.array([0.0])), Waypoint(0.5, np.array([1.0])), Waypoint(1.0, np.array([0.0]))]
    r = IndustrialSimulator(mode="intended").replay(wps)
    assert r.dropped == ()
    first = (r.times > 0) & (r.times <= 0.5 + 1e-12)
    np.testing.assert_allclose(r.velocities[first, 0], 2.0, atol=VEL_TOL)
    np.testing.assert_allclose(r.positions[first, 0], 2.0 * r.times[first], atol=POS_TOL)
    second = r.times > 0.5 + 1e-12
    np.testing.assert_allclose(r.velocities[second, 0], -2.0, atol=VEL_TOL)
    assert np.max(np.abs(np.diff(r.positions[:, 0]))) <= 2.0 * 0.01 + POS_TOL  # continuous: one step per update
    np.testing.assert_array_equal(np.diff(r.times_ns[1:]), 10_000_000)


def test_intended_interpolates_first_segment_and_new_trajectory() -> None:
    v0 = np.array([0.0])
    wps = [Waypoint(1.0, np.array([1.0]), v0), Waypoint(0.5, np.array([0.0]), v0)]
    r = IndustrialSimulator(mode="intended").replay(wps, [0.0])
    assert r.dropped == () and r.jumps.size == 0
    assert np.max(np.abs(np.diff(r.positions[:, 0]))) < 0.05  # no jumps anywhere
    assert r.times_ns[-1] == 1_500_000_000
    seed = IndustrialSimulator(mode="seed").replay(wps, [0.0])
    # the seed drops the first point (the initial state has no velocities) and then the second, measured from
    # the initial point as well
    assert seed.dropped == (0, 1)


def test_intended_hermite_end_conditions() -> None:
    wps = [Waypoint(0.0, np.array([0.0]), np.array([1.0])), Waypoint(0.5, np.array([2.0]), np.array([-1.0]))]
    r = IndustrialSimulator(mode="intended").replay(wps)
    traj = Trajectory([0.0, 0.5], [[0.0], [2.0]], [[1.0], [-1.0]])
    np.testing.assert_allclose(r.positions[:, 0], traj(r.times)[:, 0], atol=1e-12)
    np.testing.assert_allclose(r.velocities[:, 0], traj(r.times, 1)[:, 0], atol=1e-9)
    assert r.velocities[-1, 0] == -1.0


def test_simulator_rejects_bad_inputs() -> None:
    with pytest.raises(InvalidInputError):
        IndustrialSimulator(update_rate=0.0)
    with pytest.raises(InvalidInputError):
        IndustrialSimulator(pub_rate=-1.0)
    with pytest.raises(InvalidInputError):
        IndustrialSimulator(mode="fast")  # type: ignore[arg-type]
    sim = IndustrialSimulator()
    with pytest.raises(InvalidInputError):
        sim.replay([Waypoint(0.0, np.array([0.0, np.nan]))])
    with pytest.raises(InvalidInputError):
        sim.replay([Waypoint(0.0, np.zeros(2)), Waypoint(0.1, np.zeros(3))])
    with pytest.raises(InvalidInputError):
        sim.replay([Waypoint(-0.1, np.zeros(2))])
    with pytest.raises(InvalidInputError):
        sim.replay([])
    with pytest.raises(InvalidInputError):
        Trajectory([0.0, 0.0], [[0.0], [1.0]])  # non-monotonic times never reach a controller


# ---------------------------------------------------------------------------------------------------- JTC
@pytest.mark.parametrize(
    ("velocities", "accelerations", "expected_mid"),
    [(False, False, 0.5), (True, False, 0.5), (True, True, 0.5)],
)
def test_jtc_interpolation_by_fields(velocities: bool, accelerations: bool, expected_mid: float) -> None:
    q = [[0.0], [1.0]]
    v = [[0.0], [0.0]] if velocities else None
    a = [[0.0], [0.0]] if accelerations else None
    r = JointTrajectoryController().replay(Trajectory([0.0, 1.0], q, v, a))
    ref = Trajectory([0.0, 1.0], q, v, a)
    np.testing.assert_allclose(r.positions[:101, 0], ref(r.times[:101])[:, 0], atol=1e-12)
    np.testing.assert_allclose(r.velocities[:100, 0], ref(r.times[:100], 1)[:, 0], atol=1e-9)
    assert r.positions[50, 0] == pytest.approx(expected_mid)
    if not velocities:
        np.testing.assert_allclose(r.velocities[1:100, 0], 1.0)  # linear: slope
    assert r.positions[-1, 0] == 1.0 and r.velocities[-1, 0] == 0.0  # held


def test_jtc_first_segment_from_current_state() -> None:
    wps = [Waypoint(1.0, np.array([1.0]))]
    r = JointTrajectoryController().replay(wps, initial_positions=[0.0])
    np.testing.assert_allclose(r.positions[:101, 0], r.times[:101], atol=1e-12)


def test_jtc_new_goal_replaces_old_from_current_state() -> None:
    first = Trajectory([0.0, 2.0], [[0.0], [2.0]])
    second = [Waypoint(1.0, np.array([0.0]))]
    r = JointTrajectoryController().replay([(0.0, first), (0.5, second)])
    k = 50  # first update of the new goal: duration 0 into the segment from the previous command
    assert r.positions[k, 0] == pytest.approx(r.positions[k - 1, 0])
    assert r.positions[k + 50, 0] == pytest.approx(0.49 * 0.5)  # halfway from 0.49 back to 0
    assert r.positions[-1, 0] == 0.0
    assert "pre-empted" in r.events[0]


def test_jtc_none_forwards_next_point() -> None:
    traj = Trajectory([0.0, 1.0, 2.0], [[0.0], [1.0], [3.0]])
    r = JointTrajectoryController(interpolation="none").replay(traj)
    assert r.positions[10, 0] == 1.0 and r.positions[150, 0] == 3.0


def test_jtc_accelerations_without_velocities_output_zero_like_humble() -> None:
    wps = [Waypoint(0.0, np.array([1.0]), None, np.array([0.0])), Waypoint(1.0, np.array([2.0]), None, np.array([0.0]))]
    r = JointTrajectoryController().replay(wps)
    assert r.positions[50, 0] == 0.0


# ------------------------------------------------------------------------------------------- joint mode
def arm_limits() -> JointLimits:
    names = tuple(f"l_joint{i}" for i in range(1, 8))
    return JointLimits.from_arrays(
        names, [-2] * 7, [2] * 7, [15, 15, 20, 20, 44, 33, 33], [120, 120, 60, 60, 17, 14, 14]
    )


def test_velocity_convention_follows_kp_law_and_caps() -> None:
    lim = arm_limits()
    robot = JointModeRobot(lim, convention="velocity")
    target = np.full(7, 0.1)
    r = robot.replay([0.0], target[None, :], np.zeros(7), duration=0.02)
    np.testing.assert_allclose(r.velocities[0], np.array(ARM_KP) * 0.1, atol=VEL_TOL)  # unsaturated
    far = robot.replay([0.0], np.full((1, 7), 1.9), np.zeros(7), duration=0.02)
    np.testing.assert_allclose(far.velocities[0], np.minimum(np.array(ARM_KP) * 1.9, 0.3 * lim.velocity), atol=VEL_TOL)


def test_position_convention_clips_targets_and_times_out() -> None:
    lim = arm_limits()
    robot = JointModeRobot(lim, convention="position")
    r = robot.replay([0.0], np.full((1, 7), 3.0), np.zeros(7), duration=1.0)
    np.testing.assert_allclose(r.positions[-1], 2.0)  # clipped to the upper limit
    stale = robot.replay([0.0, 0.1], np.array([np.zeros(7), np.full(7, 0.5)]), np.zeros(7), duration=1.0)
    assert np.all(stale.positions[-1] == 0.5)
    late = JointModeRobot(lim, convention="velocity", command_timeout=0.05).replay(
        [0.0], np.full((1, 7), 1.0), np.zeros(7), duration=0.5
    )
    assert np.all(late.velocities[-1] == 0.0) and np.all(late.positions[-1] < 1.0)


def test_joint_mode_streams_a_trajectory_at_command_rate(teleavatar) -> None:  # noqa: ANN001
    names = teleavatar.joint_names[:7]
    q0 = teleavatar.home[:7]
    traj = Trajectory([0.0, 2.0], [q0, q0 + 0.2], np.zeros((2, 7)), joint_names=names)
    r = JointModeRobot(convention="position").replay_trajectory(traj, 60.0, jitter=0.2)
    np.testing.assert_allclose(r.positions[-1], q0 + 0.2, atol=1e-9)
    rv = JointModeRobot(convention="velocity").replay_trajectory(traj, 60.0)
    np.testing.assert_allclose(rv.positions[-1], q0 + 0.2, atol=5e-3)


def test_joint_mode_rejects_bad_streams() -> None:
    robot = JointModeRobot(arm_limits())
    with pytest.raises(InvalidInputError):
        robot.replay([0.1, 0.0], np.zeros((2, 7)))
    with pytest.raises(InvalidInputError):
        robot.replay([0.0, 0.1], np.zeros((3, 7)))
    with pytest.raises(InvalidInputError):
        JointModeRobot(rate=0.0)


def test_joint_mode_accepts_the_api_name_of_the_feedback_convention():
    from taplan.reference import JointModeRobot

    assert JointModeRobot(convention="velocity_feedback").convention == "velocity"
