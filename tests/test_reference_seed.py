"""IndustrialSimulator(mode="seed") against a literal transcription of the seed's worker under genpy time.

``_LiteralSimulator`` below re-types the seed's ``_motion_worker``/``interpolate``/``accelerate``/``_move_to`` line by
line on top of ``_Duration``, a minimal re-implementation of genpy's ``Duration`` (float constructor truncating to
nanoseconds, canonical secs/nsecs, ``to_sec``, ``+``, ``-``, ordering, ``__truediv__`` without ``__rtruediv__``),
a fake ``rospy.sleep`` that advances a nanosecond clock, and a ``queue.Queue``. The vectorised model must match it
exactly: times to the nanosecond, positions and velocities bit for bit, the same dropped waypoints.
"""

from __future__ import annotations

import copy
import queue

import numpy as np
import pytest

from taplan.reference import IndustrialSimulator
from taplan.trajectory import Trajectory, Waypoint

POS_TOL = 1e-12  # [rad]
VEL_TOL = 1e-9  # [rad]/[s]
DRIFT_POS_TOL = 1e-7  # [rad]
DRIFT_VEL_TOL = 1e-6  # [rad]/[s]


# ------------------------------------------------------------------------------------ genpy-like Duration
def _canon(secs: int, nsecs: int) -> tuple[int, int]:
    while nsecs >= 1000000000:
        secs += 1
        nsecs -= 1000000000
    while nsecs < 0:
        secs -= 1
        nsecs += 1000000000
    return secs, nsecs


class _Duration:
    __slots__ = ("secs", "nsecs")

    def __init__(self, secs=0, nsecs=0):  # noqa: ANN001
        if not isinstance(secs, int):
            float_secs = secs
            secs = int(float_secs)
            nsecs = int((float_secs - secs) * 1000000000)
        self.secs, self.nsecs = _canon(secs, nsecs)

    @staticmethod
    def from_sec(x: float) -> _Duration:
        secs = int(x)
        return _Duration(secs, int((x - secs) * 1000000000))

    def to_sec(self) -> float:
        return float(self.secs) + float(self.nsecs) / 1e9

    def to_nsec(self) -> int:
        return self.secs * 1000000000 + self.nsecs

    def __add__(self, other):  # noqa: ANN001
        if not isinstance(other, _Duration):
            return NotImplemented
        return _Duration(self.secs + other.secs, self.nsecs + other.nsecs)

    def __sub__(self, other):  # noqa: ANN001
        if not isinstance(other, _Duration):
            return NotImplemented
        return _Duration(self.secs - other.secs, self.nsecs - other.nsecs)

    def __lt__(self, other):  # noqa: ANN001
        if not isinstance(other, _Duration):
            return NotImplemented
        return self.to_nsec() < other.to_nsec()

    def __truediv__(self, val):  # noqa: ANN001
        if type(val) in (int, float):
            return _Duration.from_sec(self.to_sec() / val)
        if isinstance(val, _Duration):
            return self.to_sec() / val.to_sec()
        return NotImplemented


class _Point:
    def __init__(self) -> None:
        self.positions: list[float] = []
        self.velocities: list[float] = []
        self.time_from_start = _Duration()


class _LiteralSimulator:
    """The seed's MotionControllerSimulator, single-threaded, with a nanosecond clock."""

    def __init__(self, initial, update_rate=100.0):  # noqa: ANN001
        self.update_rate = update_rate
        self.joint_positions = list(initial)
        self.joint_velocitys = [0] * len(initial)
        self.motion_buffer: queue.Queue = queue.Queue(0)
        self.clock = 0
        self.log: list[tuple[int, list[float], list[float]]] = []
        self.errors: list[str] = []

    def sleep(self, duration) -> None:  # noqa: ANN001  rospy.sleep under simulated time
        if not isinstance(duration, _Duration):
            duration = _Duration.from_sec(duration)
        self.clock += max(duration.to_nsec(), 0)

    def interpolate(self, last_pt, current_pt, alpha):  # noqa: ANN001
        intermediate_pt = _Point()
        for last_joint, current_joint in zip(last_pt.positions, current_pt.positions, strict=False):
            intermediate_pt.positions.append(last_joint + alpha * (current_joint - last_joint))
        intermediate_pt.time_from_start = last_pt.time_from_start + _Duration(
            alpha * (current_pt.time_from_start.to_sec() - last_pt.time_from_start.to_sec())
        )
        return intermediate_pt

    def accelerate(self, last_pt, current_pt, current_time, delta_time):  # noqa: ANN001
        intermediate_pt = _Point()
        for last_joint, current_joint, last_vel, current_vel in zip(
            last_pt.positions, current_pt.positions, last_pt.velocities, current_pt.velocities, strict=False
        ):
            delta_x = current_joint - last_joint
            dv = current_vel + last_vel
            a1 = 6 * delta_x / pow(delta_time, 2) - 2 * (dv + last_vel) / delta_time
            a2 = -12 * delta_x / pow(delta_time, 3) + 6 * dv / pow(delta_time, 2)
            current_pos = (
                last_joint + last_vel * current_time + a1 * pow(current_time, 2) / 2 + a2 * pow(current_time, 3) / 6
            )
            current_interp_vel = last_vel + a1 * current_time + a2 * pow(current_time, 2) / 2
            intermediate_pt.positions.append(current_pos)
            intermediate_pt.velocities.append(current_interp_vel)
        intermediate_pt.time_from_start = last_pt.time_from_start + _Duration(current_time)
        return intermediate_pt

    def _move_to(self, point, dur):  # noqa: ANN001
        self.sleep(dur)
        self.joint_positions = point.positions[:]
        self.joint_velocitys = point.velocities[:]
        self.log.append((self.clock, self.joint_positions[:], self.joint_velocitys[:]))

    def run(self) -> None:
        move_duration = _Duration()
        update_duration = _Duration(1.0 / self.update_rate)
        last_goal_point = _Point()
        last_goal_point.positions = self.joint_positions[:]
        while not self.motion_buffer.empty():
            try:
                current_goal_point = self.motion_buffer.get()
                if current_goal_point.time_from_start < last_goal_point.time_from_start:
                    move_duration = current_goal_point.time_from_start
                else:
                    move_duration = current_goal_point.time_from_start - last_goal_point.time_from_start
                    if self.update_rate > 0:
                        starting_goal_point = copy.deepcopy(last_goal_point)
                        full_duration = move_duration.to_sec()
                        while update_duration < move_duration:
                            if not starting_goal_point.velocities or not current_goal_point.velocities:
                                intermediate_goal_point = self.interpolate(
                                    last_goal_point,
                                    current_goal_point,
                                    update_duration.to_sec() / move_duration.to_sec(),
                                )
                                for last_joint, current_joint in zip(
                                    last_goal_point.positions, current_goal_point.positions, strict=False
                                ):
                                    intermediate_goal_point.velocities.append(
                                        (current_joint - last_joint) / move_duration
                                    )
                            else:
                                intermediate_goal_point = self.accelerate(
                                    starting_goal_point,
                                    current_goal_point,
                                    full_duration - move_duration.to_sec() + update_duration.to_sec(),
                                    full_duration,
                                )
                            self._move_to(intermediate_goal_point, update_duration.to_sec())
                            last_goal_point = copy.deepcopy(intermediate_goal_point)
                            move_duration = current_goal_point.time_from_start - intermediate_goal_point.time_from_start
                self._move_to(current_goal_point, move_duration)
                last_goal_point = copy.deepcopy(current_goal_point)
            except Exception as exc:  # noqa: BLE001  the seed's catch-all
                self.errors.append(f"{type(exc).__name__}: {exc}")


def literal(waypoints: list[Waypoint], initial, update_rate=100.0) -> _LiteralSimulator:  # noqa: ANN001
    sim = _LiteralSimulator(initial, update_rate)
    for w in waypoints:
        p = _Point()
        p.positions = [float(x) for x in w.positions]
        p.velocities = [] if w.velocities is None else [float(x) for x in w.velocities]
        p.time_from_start = _Duration(float(w.time_from_start))
        sim.motion_buffer.put(p)
    sim.run()
    return sim


def assert_same(model, lit: _LiteralSimulator) -> None:  # noqa: ANN001
    assert len(model) == len(lit.log)
    np.testing.assert_array_equal(model.times_ns, [e[0] for e in lit.log])
    for i, (_, q, v) in enumerate(lit.log):
        np.testing.assert_array_equal(model.positions[i], q)
        if v:
            np.testing.assert_array_equal(model.velocities[i], v)
        else:
            assert np.all(np.isnan(model.velocities[i]))


def random_plan(rng: np.random.Generator, count: int, n: int, velocities: bool, scale: float = 1.0) -> list[Waypoint]:
    t = np.concatenate([[0.0], np.cumsum(rng.uniform(0.004, 0.4, count - 1) * scale)])
    q = rng.uniform(-1, 1, (count, n))
    v = rng.uniform(-1, 1, (count, n)) if velocities else None
    return [Waypoint(float(t[i]), q[i], None if v is None else v[i]) for i in range(count)]


# ------------------------------------------------------------------------------------------------ tests
@pytest.mark.parametrize("scale", [1.0, 7.3])
def test_hermite_plans_match_literal_seed(rng: np.random.Generator, scale: float) -> None:
    for _ in range(6):
        wps = random_plan(rng, 12, 3, velocities=True, scale=scale)
        init = rng.uniform(-1, 1, 3)
        model = IndustrialSimulator(mode="seed").replay(wps, init)
        lit = literal(wps, init)
        assert_same(model, lit)
        assert model.dropped == ()


def test_mixed_fields_and_new_trajectories_match_literal_seed(rng: np.random.Generator) -> None:
    for _ in range(6):
        a = random_plan(rng, 8, 2, velocities=True)
        b = random_plan(rng, 6, 2, velocities=False)
        c = random_plan(rng, 5, 2, velocities=True)
        wps = a + b + c
        # strip velocities from a few points at random
        wps = [Waypoint(w.time_from_start, w.positions, None if rng.random() < 0.2 else w.velocities) for w in wps]
        init = rng.uniform(-1, 1, 2)
        model = IndustrialSimulator(mode="seed").replay(wps, init)
        lit = literal(wps, init)
        assert_same(model, lit)
        assert len(model.dropped) == len(lit.errors)
        assert all(e.startswith("TypeError") for e in lit.errors)


@pytest.mark.parametrize("rate", [100.0, 77.0, 125.0, 30.0])
def test_odd_update_rates_match_literal_seed(rng: np.random.Generator, rate: float) -> None:
    wps = random_plan(rng, 15, 2, velocities=True, scale=3.1)
    model = IndustrialSimulator(update_rate=rate, mode="seed").replay(wps, np.zeros(2))
    assert_same(model, literal(wps, np.zeros(2), rate))


def test_linear_branch_drops_waypoints() -> None:
    wps = [Waypoint(0.0, np.array([0.0])), Waypoint(0.5, np.array([1.0])), Waypoint(1.0, np.array([2.0]))]
    r = IndustrialSimulator(mode="seed").replay(wps, [0.3])
    assert r.dropped == (1, 2)
    assert len(r) == 1  # only the jump to the first point
    assert r.times_ns[0] == 0 and r.positions[0, 0] == 0.0
    assert np.isnan(r.velocities[0, 0])  # velocities empty: the point carries none
    np.testing.assert_array_equal(r.samples.positions[:, 0], 0.0)  # joint_states never moves


def test_drop_measures_next_segment_from_last_reached_goal() -> None:
    # point 1 lacks velocities -> dropped; point 2 is then reached from point 0 over 0.3 s along the Hermite
    wps = [
        Waypoint(0.0, np.array([0.0]), np.array([0.0])),
        Waypoint(0.1, np.array([5.0])),
        Waypoint(0.3, np.array([1.0]), np.array([0.0])),
    ]
    r = IndustrialSimulator(mode="seed").replay(wps)
    assert r.dropped == (1,)
    # float current_time truncates a few steps 1 ns short, and each shortfall lengthens the segment by 1 ns
    assert 300_000_000 <= r.times_ns[-1] < 300_000_100
    assert np.all(r.positions[:, 0] <= 1.0 + POS_TOL)  # never heads to the dropped 5.0
    assert_same(r, literal(wps, [0.0]))


def test_first_waypoint_later_than_one_period_is_dropped_in_seed() -> None:
    wps = [Waypoint(0.5, np.array([1.0]), np.array([0.0])), Waypoint(1.0, np.array([2.0]), np.array([0.0]))]
    r = IndustrialSimulator(mode="seed").replay(wps, [0.0])
    # initial last_goal_point has no velocities -> linear branch; point 1 is then measured from the initial
    # point too (1.0 s, still linear) -> dropped as well
    assert r.dropped == (0, 1)
    assert len(r) == 0
    wps2 = [Waypoint(0.005, np.array([1.0]), np.array([0.0])), Waypoint(1.0, np.array([2.0]), np.array([0.0]))]
    r2 = IndustrialSimulator(mode="seed").replay(wps2, [0.0])
    assert r2.dropped == ()
    assert r2.times_ns[0] == 5_000_000 and r2.positions[0, 0] == 1.0  # jump after sleeping 5 ms


def test_new_trajectory_sleeps_then_jumps() -> None:
    v0 = np.array([0.0])
    wps = [Waypoint(0.0, np.array([0.0]), v0), Waypoint(0.2, np.array([1.0]), v0), Waypoint(0.15, np.array([3.0]), v0)]
    r = IndustrialSimulator(mode="seed").replay(wps)
    assert r.times_ns[-1] == 200_000_000 + 150_000_000
    assert r.times_ns[-2] == 200_000_000
    assert r.positions[-1, 0] == 3.0 and r.positions[-2, 0] == 1.0
    assert "new trajectory" in " ".join(r.events)


def test_grid_restarts_and_extra_step() -> None:
    v0 = np.array([0.0])
    # 0.105 s segment: steps at 10..100 ms, then a 5 ms final update
    r = IndustrialSimulator(mode="seed").replay(
        [Waypoint(0.0, np.array([0.0]), v0), Waypoint(0.105, np.array([1.0]), v0)]
    )
    periods = np.diff(r.times_ns)
    assert np.all(np.abs(periods[:-1] - 10_000_000) <= 1)  # [ns]: float current_time may cost 1 ns per step
    assert abs(periods[-1] - 5_000_000) < 100
    # a remainder 1 ns above the period adds a step that leaves a 1 ns final sleep
    wps = [Waypoint(0.0, np.array([0.0]), v0), Waypoint(0.100000001, np.array([1.0]), v0)]
    r2 = IndustrialSimulator(mode="seed").replay(wps)
    assert np.diff(r2.times_ns)[-1] == 1
    assert_same(r2, literal(wps, [0.0]))


def test_float_times_truncate_to_nanoseconds() -> None:
    v0 = np.array([0.0])
    wps = [Waypoint(0.0, np.array([0.0]), v0), Waypoint(2.3, np.array([1.0]), v0)]
    # a 0.1 Hz loop: the 2.3 s segment is shorter than one period, so it is a single sleep of Duration(2.3)
    r = IndustrialSimulator(update_rate=0.1, mode="seed").replay(wps)
    assert r.times_ns[-1] == 2_299_999_999  # 2 s + int(0.2999999999999998 * 1e9) ns
    assert r.times_ns[-1] == literal(wps, [0.0], 0.1).log[-1][0]


def test_state_is_end_of_step_and_hermite_end_conditions() -> None:
    wps = [Waypoint(0.0, np.array([0.0]), np.array([0.0])), Waypoint(1.0, np.array([1.0]), np.array([0.0]))]
    r = IndustrialSimulator(mode="seed").replay(wps)
    # jump to point 0 at t = 0, 100 steps, then the final move: truncated step times leave the remainder 10 ns above
    # one period after step 99, so the loop adds a 100th step and the goal itself arrives 10 ns later
    assert len(r) == 102
    assert np.diff(r.times_ns)[-1] == 10
    t = np.arange(1, 101) * 0.01  # [s] step k evaluates the Hermite at ~k * 10 ms
    expected = 3 * t**2 - 2 * t**3  # cubic Hermite 0 -> 1 with zero end velocities over 1 s
    # the remainder's lost nanoseconds shift the evaluation time by up to ~1e-8 s late in the segment
    np.testing.assert_allclose(r.positions[1:101, 0], expected, atol=DRIFT_POS_TOL)
    np.testing.assert_allclose(r.velocities[1:101, 0], 6 * t - 6 * t**2, atol=DRIFT_VEL_TOL)
    assert r.positions[-1, 0] == 1.0 and r.velocities[-1, 0] == 0.0
    assert r.times_ns[1] == 10_000_000  # the first step's state is the point at the end of the step


def test_joint_states_samples_hold_latest_state() -> None:
    wps = [Waypoint(0.0, np.array([0.0]), np.array([0.0])), Waypoint(1.0, np.array([1.0]), np.array([0.0]))]
    r = IndustrialSimulator(mode="seed", pub_rate=10.0).replay(wps)
    s = r.samples
    np.testing.assert_array_equal(s.times_ns[:3], [100_000_000, 200_000_000, 300_000_000])
    q, _ = r.state(s.times)
    np.testing.assert_array_equal(s.positions, q)
    assert s.times_ns[-1] == 1_100_000_000  # default hold: one more publish period


def test_trajectory_input_is_accepted() -> None:
    traj = Trajectory([0, 0.5, 1.0], [[0.0], [0.5], [1.0]], [[0.0], [1.0], [0.0]])
    r = IndustrialSimulator().replay(traj)
    assert r.dropped == () and abs(r.times_ns[-1] - 1_000_000_000) < 100
