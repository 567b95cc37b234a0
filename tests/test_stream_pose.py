"""PoseStreamer: reaches poses through the IK within the joint limits, flags unreachable poses, rejects bad ones."""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from taplan.stream import PoseStreamer, StreamStatus
from taplan.stream.sweep import StreamRecord, stream_violations

DT = 1.0 / 77.0  # [s]
POS_TOL = 2e-3  # [m]: convergence of the IK reference
POS_HOLD_TOL = 1e-12  # [rad]: a held command (ruckig re-evaluates it to the last bit)


@pytest.fixture(scope="module")
def streamer(teleavatar):
    return PoseStreamer(teleavatar, DT, collision=False)  # default IK options otherwise (posture_cost 1e-4)


def _record(states):
    return StreamRecord.from_states(states)


def test_dual_arm_poses_reached_within_limits(streamer, teleavatar):
    q0 = teleavatar.home
    streamer.reset(q0)
    targets = {}
    for frame, offset in (("left_ee", [0.04, 0.02, -0.03]), ("right_ee", [0.03, -0.02, 0.04])):
        T = teleavatar.frame_pose(q0, frame).copy()
        T[:3, 3] += offset
        targets[frame] = T
    states = []
    for k in range(230):  # 3 s, targets re-sent at ~15 Hz
        if k % 5 == 0:
            streamer.set_target(targets)
        states.append(streamer.step())
    last = states[-1]
    assert max(last.position_error.values()) < POS_TOL
    for frame, T in targets.items():
        np.testing.assert_allclose(teleavatar.frame_pose(last.position, frame)[:3, 3], T[:3, 3], atol=POS_TOL)
    counts = stream_violations(_record(states), streamer.limits, DT, q0)
    assert counts == dict.fromkeys(counts, 0)


def test_unreachable_pose_approached_and_flagged(streamer, teleavatar):
    q0 = teleavatar.home
    streamer.reset(q0)
    far = teleavatar.frame_pose(q0, "left_ee").copy()
    far[:3, 3] += [1.0, 0.0, 0.0]  # beyond reach (0.55 m arm)
    states = []
    for k in range(200):
        if k % 5 == 0:
            streamer.set_target({"left_ee": far})
        states.append(streamer.step())
    assert "left_ee" in states[-1].unreachable
    assert not states[-1].pose_reached
    assert states[-1].position_error["left_ee"] < states[0].position_error["left_ee"] - 0.05  # got closer
    counts = stream_violations(_record(states), streamer.limits, DT, q0)
    assert counts == dict.fromkeys(counts, 0)


def test_bad_pose_rejected_and_timeout_stops(teleavatar):
    streamer = PoseStreamer(teleavatar, DT, frames=("left_ee",), collision=False, timeout=0.3, initial=teleavatar.home)
    T = teleavatar.frame_pose(teleavatar.home, "left_ee").copy()
    T[:3, 3] += [0.0, 0.0, 0.08]
    streamer.set_target({"left_ee": T})
    moved_nan, moved_inf = T.copy(), T.copy()  # same rotation as the accepted target, bad translation
    moved_nan[0, 3], moved_inf[2, 3] = np.nan, np.inf
    for bad in (
        {"left_ee": np.full((4, 4), np.nan)},
        {"left_ee": moved_nan},
        {"left_ee": moved_inf},
        {"right_ee": T},
        {"left_ee": np.eye(3)},
        {},
    ):
        with pytest.raises(taplan.StreamError):
            streamer.set_target(bad)
    states = [streamer.step() for _ in range(150)]
    assert StreamStatus.STOPPING in [s.status for s in states]
    assert states[-1].status is StreamStatus.STOPPED
    np.testing.assert_allclose(states[-1].velocity, 0.0, atol=1e-9)


def test_reachable_poses_reached_with_default_options(teleavatar):
    """Poses of random configurations near home: reached within tolerance, never left flagged unreachable."""
    rng = np.random.default_rng(5)
    limits = teleavatar.planning_limits
    streamer = PoseStreamer(teleavatar, DT, timeout=None)  # defaults: collision on, posture_cost 1e-4
    for _ in range(3):
        q_goal = np.clip(teleavatar.home + rng.normal(0.0, 0.2, teleavatar.nq), limits.lower + 0.1, limits.upper - 0.1)
        streamer.reset(teleavatar.home)
        streamer.set_target({f: teleavatar.frame_pose(q_goal, f) for f in streamer.frames})
        states = []
        for _step in range(400):
            states.append(streamer.step())
            if states[-1].reached:
                break
        last = states[-1]
        assert last.reached and not last.unreachable
        assert max(last.position_error.values()) <= streamer.tolerance[0]
        for frame in streamer.frames:  # the commanded configuration itself is on the pose
            T = teleavatar.frame_pose(last.position, frame)
            np.testing.assert_allclose(T[:3, 3], teleavatar.frame_pose(q_goal, frame)[:3, 3], atol=POS_TOL)
        counts = stream_violations(_record(states), streamer.limits, DT, teleavatar.home)
        assert counts == dict.fromkeys(counts, 0)


def test_reached_pose_is_held_until_the_target_changes(teleavatar):
    streamer = PoseStreamer(teleavatar, DT, frames=("right_ee",), collision=False, timeout=None)
    streamer.reset(teleavatar.home)
    T = teleavatar.frame_pose(teleavatar.home, "right_ee").copy()
    T[:3, 3] += [0.02, 0.0, 0.02]
    streamer.set_target({"right_ee": T})
    for _ in range(300):
        if streamer.step().reached:
            break
    held = streamer.step()
    assert held.reached and held.status is StreamStatus.REACHED
    for _ in range(10):  # re-sending the same pose keeps the hold: no new trajectory, same command
        streamer.set_target({"right_ee": T.copy()})
        state = streamer.step()
        assert state.reached and not state.new_calculation
        np.testing.assert_allclose(state.position, held.position, atol=POS_HOLD_TOL)
    T2 = T.copy()
    T2[:3, 3] += [0.0, -0.02, 0.0]
    streamer.set_target({"right_ee": T2})  # a moved target resumes tracking
    assert streamer.step().status is StreamStatus.MOVING
