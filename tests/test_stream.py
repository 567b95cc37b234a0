"""JointStreamer: continuity across retargets, smooth stop on timeout, rejected bad targets, limits in sweeps."""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from taplan.stream import JointStreamer, StreamStatus, braking_distance, max_safe_velocity
from taplan.stream.sweep import StreamRecord, random_scenario, run_scenario, stream_violations

DT = 1.0 / 77.0  # [s]
POS_TOL = 1e-7  # [rad]
VEL_TOL = 1e-9  # [rad]/[s]


@pytest.fixture(scope="module")
def limits(teleavatar: taplan.Robot) -> taplan.JointLimits:
    return teleavatar.planning_limits


@pytest.fixture
def streamer(limits, teleavatar) -> JointStreamer:
    return JointStreamer(limits, DT, initial=teleavatar.home, timeout=1.0)


def _violations(states, limits, initial):
    record = StreamRecord.from_states(states)
    return stream_violations(record, limits, DT, initial)


def test_reaches_target_and_reports_it(streamer, limits, teleavatar):
    goal = teleavatar.home + 0.2 * np.sign(limits.upper - teleavatar.home) * 0.5
    streamer.set_target(goal)
    states = [streamer.step() for _ in range(300)]
    assert states[-1].reached
    np.testing.assert_allclose(states[-1].position, goal, atol=POS_TOL)
    np.testing.assert_allclose(states[-1].velocity, 0.0, atol=VEL_TOL)
    assert all(v == 0 for v in _violations(states, limits, teleavatar.home).values())


def test_retargets_keep_state_continuous(streamer, limits, teleavatar, rng):
    states = []
    for _ in range(20):  # a new target every 7 periods, mid-motion
        streamer.set_target(rng.uniform(limits.lower, limits.upper))
        for _step in range(7):
            states.append(streamer.step())
    retargets = [i for i, s in enumerate(states) if s.new_calculation]
    assert len(retargets) >= 19
    counts = _violations(states, limits, teleavatar.home)
    assert counts == dict.fromkeys(counts, 0)
    # at each retarget the acceleration moves by at most jerk * dt: no jump
    for i in retargets[1:]:
        assert np.all(np.abs(states[i].acceleration - states[i - 1].acceleration) <= limits.jerk * DT * (1 + 1e-9))


def test_timeout_brakes_smoothly_to_rest(limits, teleavatar):
    streamer = JointStreamer(limits, DT, initial=teleavatar.home, timeout=0.3)
    far = np.where(teleavatar.home > 0.5 * (limits.lower + limits.upper), limits.lower, limits.upper)
    streamer.set_target(far)
    states = [streamer.step() for _ in range(200)]
    statuses = [s.status for s in states]
    assert StreamStatus.STOPPING in statuses
    first_stop = statuses.index(StreamStatus.STOPPING)
    assert first_stop * DT == pytest.approx(0.3, abs=2 * DT)
    assert statuses[-1] is StreamStatus.STOPPED
    np.testing.assert_allclose(states[-1].velocity, 0.0, atol=VEL_TOL)
    assert not np.allclose(states[-1].position, far)  # stopped short of the stale target
    counts = _violations(states, limits, teleavatar.home)
    assert counts == dict.fromkeys(counts, 0)
    streamer.set_target(teleavatar.home)  # a new target resumes
    assert streamer.step().status is StreamStatus.MOVING


@pytest.mark.parametrize(
    "bad",
    [np.full(14, np.nan), np.full(14, np.inf), np.zeros(13), np.zeros((2, 14)), "abc"],
    ids=["nan", "inf", "short", "2d", "text"],
)
def test_bad_target_rejected_motion_kept(streamer, limits, teleavatar, bad):
    goal = 0.5 * (limits.lower + limits.upper)
    streamer.set_target(goal)
    for _ in range(10):
        streamer.step()
    before = streamer.target
    with pytest.raises(taplan.StreamError):
        streamer.set_target(bad)
    np.testing.assert_array_equal(streamer.target[0], before[0])
    state = streamer.step()
    assert not state.new_calculation  # still on the same trajectory
    assert state.status is StreamStatus.MOVING


def test_out_of_bounds_clamped_or_raised(limits, teleavatar):
    clamp = JointStreamer(limits, DT, initial=teleavatar.home)
    beyond = limits.upper + 0.5
    assert clamp.set_target(beyond) is True
    np.testing.assert_array_equal(clamp.target[0], limits.upper)
    states = [clamp.step() for _ in range(400)]
    assert states[-1].target_adjusted
    assert np.all(np.array([s.position for s in states]) <= limits.upper)
    strict = JointStreamer(limits, DT, initial=teleavatar.home, on_out_of_bounds="raise")
    with pytest.raises(taplan.StreamError, match="outside"):
        strict.set_target(beyond)
    with pytest.raises(taplan.StreamError, match="exceeds"):
        strict.set_target(teleavatar.home, velocities=2 * limits.velocity)


def test_target_velocity_capped_by_braking_room(limits, teleavatar):
    streamer = JointStreamer(limits, DT, initial=teleavatar.home)
    near = limits.upper - 0.01
    streamer.set_target(near, velocities=limits.velocity)  # toward the bound at full speed: impossible to stop
    q, v = streamer.target
    room = limits.upper - q
    assert np.all(braking_distance(v, limits.acceleration, limits.jerk) + np.abs(v) * DT <= room + 1e-12)
    states = [streamer.step() for _ in range(300)]
    assert np.all(np.array([s.position for s in states]) <= limits.upper)
    assert states[-1].status is StreamStatus.STOPPED  # reached the moving target, then braked


def test_braking_distance_inverse(rng):
    a, j = rng.uniform(1, 40, 50), rng.uniform(10, 400, 50)
    v = rng.uniform(0, 10, 50)
    d = braking_distance(v, a, j)
    np.testing.assert_allclose(max_safe_velocity(d, a, j), v, rtol=1e-9)


def test_reset_validates_measured_state(limits, teleavatar):
    streamer = JointStreamer(limits, DT)
    with pytest.raises(taplan.StreamError):
        streamer.step()
    outside = teleavatar.home.copy()
    outside[0] = limits.upper[0] + 0.01
    with pytest.raises(taplan.InvalidInputError, match="l_joint1"):
        streamer.reset(outside)
    state = streamer.reset(outside, clamp=True)
    assert state.position[0] == limits.upper[0]
    with pytest.raises(taplan.InvalidInputError, match="velocity"):
        streamer.reset(teleavatar.home, velocity=2 * limits.velocity)
    moving = streamer.reset(teleavatar.home, velocity=0.1 * limits.velocity * np.sign(teleavatar.home))
    assert moving.status is StreamStatus.STOPPING
    states = [streamer.step() for _ in range(100)]
    assert states[-1].status is StreamStatus.STOPPED


def test_fast_and_checked_admission_agree(limits, teleavatar, rng):
    """Float arrays take set_target's fast path, lists the general one: same admitted targets and flags."""
    fast = JointStreamer(limits, DT, initial=teleavatar.home)
    checked = JointStreamer(limits, DT, initial=teleavatar.home)
    span = limits.upper - limits.lower
    for _ in range(300):
        q = rng.uniform(limits.lower - 0.02 * span, limits.upper + 0.02 * span)
        if rng.random() < 0.5:  # close to a bound, where the braking room binds
            q = np.where(rng.random(q.size) < 0.5, limits.lower, limits.upper) + rng.normal(0.0, 0.05, q.size)
        v = None if rng.random() < 0.3 else rng.uniform(-1.0, 1.0, q.size) * limits.velocity * rng.uniform(0, 1.1)
        assert fast.set_target(q, v) == checked.set_target(q.tolist(), None if v is None else v.tolist())
        for a, b in zip(fast.target, checked.target, strict=True):
            np.testing.assert_array_equal(a, b)
        q_admitted, v_admitted = fast.target
        room = np.where(v_admitted >= 0, limits.upper - q_admitted, q_admitted - limits.lower)
        stop = braking_distance(v_admitted, limits.acceleration, limits.jerk) + np.abs(v_admitted) * DT
        assert np.all(stop <= room + 1e-12)


@pytest.mark.parametrize("synchronization", ["time", "phase", "none", "auto"])
def test_seeded_sweep_no_violations(limits, synchronization):
    rng = np.random.default_rng(7)
    streamer = JointStreamer(limits, DT, synchronization=synchronization, timeout=0.5)
    totals: dict[str, int] = {}
    rejected = 0
    for _ in range(40):
        scenario = random_scenario(limits, rng, duration=2.0, timeout=0.5)
        record = run_scenario(streamer, scenario)
        rejected += record.rejected
        for key, value in stream_violations(record, limits, DT, scenario.initial).items():
            totals[key] = totals.get(key, 0) + value
    assert totals == dict.fromkeys(totals, 0)
    assert rejected > 0  # malformed targets were exercised


def test_auto_synchronization_is_time_unless_retargeting_every_period(limits, teleavatar, rng):
    """ "auto": identical to "time" for targets that are followed for more than one period; with a target every
    period, unsynchronised first periods, and at the first period without a target a time-synchronised re-plan
    from the emitted state (what a "time" streamer would compute from that state)."""
    span = limits.upper - limits.lower
    auto = JointStreamer(limits, DT, synchronization="auto", timeout=None, initial=teleavatar.home)
    timed = JointStreamer(limits, DT, synchronization="time", timeout=None, initial=teleavatar.home)
    q = teleavatar.home.copy()
    for k in range(120):  # policy-rate targets (every 3 periods), some with velocities: bit-identical streams
        if k % 3 == 0:
            q = np.clip(q + rng.normal(0.0, 0.02, q.size) * span, limits.lower, limits.upper)
            v = 0.05 * limits.velocity * rng.uniform(-1.0, 1.0, q.size) if k % 2 else None
            auto.set_target(q, v)
            timed.set_target(q, v)
        a, b = auto.step(), timed.step()
        for x, y in zip(a[1:5], b[1:5], strict=True):
            np.testing.assert_array_equal(x, y)
        assert a.new_calculation == b.new_calculation
    states = []
    for _ in range(40):  # a target every period, then a pause
        q = np.clip(q + rng.normal(0.0, 0.005, q.size) * span, limits.lower, limits.upper)
        auto.set_target(q)
        states.append(auto.step())
    before, replanned = states[-1], auto.step()
    assert replanned.new_calculation  # the re-plan, time-synchronised
    reference = JointStreamer(limits, DT, synchronization="time", timeout=None)
    reference.reset(before.position, before.velocity, before.acceleration)
    reference.set_target(q)
    expected = reference.step()
    for x, y in zip(replanned[1:5], expected[1:5], strict=True):
        np.testing.assert_allclose(x, y, atol=1e-9)
    following = [auto.step() for _ in range(200)]
    assert following[-1].reached
    record = StreamRecord.from_states([a, *states, replanned, *following])  # from the last policy-phase state
    counts = stream_violations(record, limits, DT)
    assert counts == dict.fromkeys(counts, 0)


@pytest.mark.slow
def test_large_seeded_sweep(teleavatar):
    for limits, dt in ((teleavatar.planning_limits, 1 / 50), (teleavatar.limits, 1 / 77)):
        rng = np.random.default_rng(11)
        streamer = JointStreamer(limits, dt)
        for _ in range(300):
            scenario = random_scenario(limits, rng)
            record = run_scenario(streamer, scenario)
            counts = stream_violations(record, limits, dt, scenario.initial)
            assert counts == dict.fromkeys(counts, 0)
