"""Recorded demonstrations -> limit-respecting, jerk-limited trajectories within a stated deviation."""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from benchmarks._paths import teleoperation_recording
from taplan import api
from taplan.cli import main
from taplan.errors import InvalidInputError, TimingError
from taplan.timing import limit_usage, load_recording, time_demonstration
from tests.test_timing_any_path import finite_difference_excess

LIMIT_TOL = 1e-6  # relative: exact peaks / limit
MAX_DEVIATION = 0.01  # [rad] asked for
HAND_DEVIATION = 0.005  # [m] the default bound on the hands
ENDS = 0.3  # [s] starting from and stopping at rest may slow the first and last this much of the recording


@pytest.fixture(scope="module")
def arm(teleavatar: taplan.Robot) -> taplan.JointLimits:
    return teleavatar.planning_limits.subset(teleavatar.group("right").joint_names)


@pytest.mark.parametrize("rate", [30.0, 100.0])
def test_recording_keeps_its_timing_within_the_limits_and_deviation(arm, teleavatar, rate) -> None:
    t, q = teleoperation_recording(arm, rate, 12.0, seed=int(rate))
    result = time_demonstration(t, q, arm, max_deviation=MAX_DEVIATION, robot=teleavatar)
    traj = result.trajectory
    usage = limit_usage(traj, arm)
    assert usage.within(LIMIT_TOL, jerk=True) and usage.position.max() <= 1e-9
    assert finite_difference_excess(traj, arm, jerk=True) <= 0.0
    # independent deviation: the trajectory at the times it passes each recorded sample's place on the path
    s_of_t = result.timing.path_position(np.linspace(0.0, traj.duration, 20001))
    passing = np.interp(t, s_of_t, np.linspace(0.0, traj.duration, 20001))
    recorded = np.clip(q, arm.lower, arm.upper)
    assert np.max(np.abs(traj(passing) - recorded)) <= MAX_DEVIATION + 1e-4  # interpolated passing times
    assert result.max_deviation <= MAX_DEVIATION
    assert set(result.frame_deviation) == {"right_ee"} and result.frame_deviation["right_ee"] <= HAND_DEVIATION
    # as recorded except for starting and stopping at rest
    assert result.recording_duration < traj.duration < result.recording_duration + 2 * ENDS
    assert all(s.end <= ENDS or s.start >= result.recording_duration - ENDS for s in result.slowdowns)
    assert len(result.waypoints) < len(t) / 5  # a fit through few samples, not every noisy one


def test_noise_does_not_become_jerk_or_waypoints(arm) -> None:
    t, clean = teleoperation_recording(arm, 100.0, 10.0, seed=3, noise=0.0)
    noisy = clean + np.random.default_rng(4).normal(0.0, 1e-3, clean.shape)  # 1 mrad white noise
    a = time_demonstration(t, clean, arm)
    b = time_demonstration(t, noisy, arm)
    assert len(b.waypoints) <= 1.5 * len(a.waypoints) + 2
    assert b.trajectory.duration <= 1.01 * a.trajectory.duration
    assert limit_usage(b.trajectory, arm).within(LIMIT_TOL, jerk=True)


def test_too_fast_stretch_is_slowed_down_and_reported(arm) -> None:
    t, q = teleoperation_recording(arm, 50.0, 10.0, seed=5)
    x = np.clip((t - 4.0) / 2.0, 0.0, 1.0)
    fast = t - 1.2 * x**2 * (
        3.0 - 2.0 * x
    )  # a smooth time warp: 4-6 s replayed up to 10 x faster, ending 1.2 s earlier
    result = time_demonstration(fast, q, arm)
    assert limit_usage(result.trajectory, arm).within(LIMIT_TOL, jerk=True)
    inside = [s for s in result.slowdowns if s.start < 4.8 and s.end > 4.0]
    assert inside and min(s.min_speed for s in inside) < 0.5 and sum(s.added for s in inside) > 0.3
    assert result.max_deviation <= 0.01
    quickest = time_demonstration(fast, q, arm, keep_timing=False)
    assert quickest.trajectory.duration < result.trajectory.duration and quickest.slowdowns == ()


def test_bad_recordings_say_why(arm) -> None:
    t, q = teleoperation_recording(arm, 30.0, 2.0, seed=6)
    with pytest.raises(InvalidInputError, match="times"):
        time_demonstration(t[::-1], q, arm)
    with pytest.raises(InvalidInputError, match="max_deviation"):
        time_demonstration(t, q, arm, max_deviation=0.0)
    noisy = q + np.random.default_rng(7).normal(0.0, 0.02, q.shape)  # 20 mrad of noise
    with pytest.raises(TimingError, match="noisier"):
        time_demonstration(t, noisy, arm, max_deviation=0.005)


def test_plan_times_a_bag_in_one_command(tmp_path, teleavatar, capsys) -> None:
    from taplan.ros.bag import BagWriter

    names = list(teleavatar.group("left").joint_names) + list(teleavatar.group("right").joint_names)
    limits = teleavatar.planning_limits.subset(names)
    t, q = teleoperation_recording(limits, 50.0, 6.0, seed=8)
    bag = tmp_path / "demo.mcap"
    with BagWriter(bag) as writer:
        for k, (tk, qk) in enumerate(zip(t, q, strict=True)):
            for side, part in (("left", qk[:7]), ("right", qk[7:])):
                fields = {"name": list(api.ARM_JOINT_NAMES[side]), "position": list(part), "stamp": 1000.0 + tk}
                writer.record(api.Topics.joint_states(side), api.JOINT_STATE, fields, int((1000.0 + tk) * 1e9) + k)
    from taplan.ros.bag import read_recording

    times, positions, read_names = read_recording(bag)
    assert read_names == tuple(names) and positions.shape == q.shape
    np.testing.assert_allclose(positions, q, atol=1e-12)
    out = tmp_path / "plan.json"
    assert main(["plan", str(bag), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "PASS" in printed and "deviation from the recording" in printed and "right_ee" in printed
    trajectory = taplan.Trajectory.load(out)
    assert trajectory.joint_names == tuple(names)
    assert limit_usage(trajectory, limits).within(LIMIT_TOL, jerk=True)
    # the plan file passes taplan check on its own, and through the JTC controller model
    assert main(["check", str(out), "--limits", "planning", "--no-png"]) == 0
    assert main(["check", str(out), "--limits", "planning", "--controller", "jtc", "--no-png"]) == 0
    assert capsys.readouterr().out.count(": PASS") == 2


def test_recording_csv_round_trip(tmp_path, arm) -> None:
    t, q = teleoperation_recording(arm, 30.0, 1.0, seed=9)
    path = tmp_path / "rec.csv"
    np.savetxt(path, np.column_stack([t + 5.0, q]), delimiter=",", header="time," + ",".join(arm.names), comments="")
    times, positions, names = load_recording(str(path))
    assert names == arm.names
    np.testing.assert_allclose(times, t, atol=1e-12)
    np.testing.assert_allclose(positions, q, atol=1e-15)
    with pytest.raises(InvalidInputError, match="first column"):
        load_recording(str(_no_time(tmp_path)))


def _no_time(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("a,b\n1,2\n")
    return path
