"""The closed-form stopping range (safety.stop_excursion) against ruckig's braking profile, and its use."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import ruckig

from taplan.stream import JointStreamer, stopping_range
from taplan.stream._ruckig import profile_range
from taplan.stream.joint_streamer import _stop_fits, _stop_rows
from taplan.stream.safety import stop_excursion
from taplan.stream.sweep import StreamRecord, random_scenario, run_scenario, stream_violations

DT = 1.0 / 77.0  # [s]
EXCURSION_TOL = 1e-12  # [rad]: float slack between the closed form and ruckig's profile (observed ~1e-14)


def _random_states(rng: np.random.Generator, count: int):
    """Random limits and states that ruckig keeps inside the limits (|a| <= sqrt(2 j (vmax - |v|)) toward v)."""
    for _ in range(count):
        vmax, amax = rng.uniform(0.5, 15.0), rng.uniform(1.0, 40.0)
        jmax = amax * rng.uniform(1.0, 20.0)
        v = rng.uniform(-vmax, vmax) if rng.random() > 0.05 else 0.0
        a = rng.uniform(-amax, amax) if rng.random() > 0.1 else 0.0
        reachable = np.sqrt(2.0 * jmax * max(vmax - abs(v), 0.0))
        if np.sign(a) == np.sign(v) and abs(a) > reachable:
            a = np.sign(a) * reachable * rng.uniform(0.0, 1.0)
        yield float(v), float(a), vmax, amax, jmax


def _ruckig_brake_range(v: float, a: float, vmax: float, amax: float, jmax: float) -> tuple[float, float]:
    """Exact position range of ruckig's velocity-interface stop (what the streamer's brake runs)."""
    otg, inp, out = ruckig.Ruckig(1, 0.01), ruckig.InputParameter(1), ruckig.OutputParameter(1)
    inp.control_interface = ruckig.ControlInterface.Velocity
    inp.synchronization = ruckig.Synchronization.No
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [v], [a]
    inp.target_velocity, inp.target_acceleration = [0.0], [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [vmax], [amax], [jmax]
    otg.update(inp, out)
    return profile_range(out.trajectory.profiles[0][0])


def test_stop_excursion_covers_ruckig_braking(rng):
    """Never smaller than ruckig's actual braking excursion (and in fact equal to it)."""
    for v, a, vmax, amax, jmax in _random_states(rng, 2000):
        low, high = _ruckig_brake_range(v, a, vmax, amax, jmax)
        down, up = stop_excursion(v, a, amax, jmax)
        assert down <= low + EXCURSION_TOL and up >= high - EXCURSION_TOL
        assert down == pytest.approx(low, abs=1e-9) and up == pytest.approx(high, abs=1e-9)


def test_stop_excursion_at_the_mirror_edge(rng):
    """Regression: v = -a^2 / (2 j) (the velocity that an acceleration ramped down at the jerk limit cancels) once
    raised a math domain error from rounding, in a streamer's step."""
    for _ in range(5000):
        amax, jmax = rng.uniform(1.0, 40.0), rng.uniform(1.0, 400.0)
        a = rng.uniform(0.0, amax) * rng.choice([-1.0, 1.0])
        v = -a * abs(a) / (2.0 * jmax)
        down, up = stop_excursion(v, a, amax, jmax)
        low, high = _ruckig_brake_range(v, a, 1e3, amax, jmax)
        assert down <= low + EXCURSION_TOL and up >= high - EXCURSION_TOL


def test_stop_screen_is_conservative(rng):
    """_stop_fits' cheap screen bounds the exact excursion: s (|a| / j + 2 amax / j + s / amax), s = |v| + a^2/2j."""
    for v, a, _vmax, amax, jmax in _random_states(rng, 20000):
        speed = abs(v) + a * a / (2.0 * jmax)
        reach = speed * (abs(a) / jmax + 2.0 * amax / jmax + speed / amax)
        down, up = stop_excursion(v, a, amax, jmax)
        assert max(-down, up) <= reach * (1.0 + 1e-12) + 1e-15


def test_stop_fits_matches_the_exact_rule(rng):
    rows = _stop_rows([-1.0], [1.0], [20.0], [200.0])
    for _ in range(3000):
        v, a = rng.uniform(-4.0, 4.0), rng.uniform(-20.0, 20.0)
        reachable = np.sqrt(2.0 * 200.0 * (4.0 - abs(v)))
        if np.sign(a) == np.sign(v) and abs(a) > reachable:
            continue
        p = rng.uniform(-1.0, 1.0)
        down, up = stop_excursion(v, a, 20.0, 200.0)
        inside = p + down >= -1.0 + 1e-9 and p + up <= 1.0 - 1e-9
        assert _stop_fits([p], [v], [a], rows) == inside
    low, high = stopping_range([0.0, 1.0], [0.0, 0.0], [20.0, 20.0], [200.0, 200.0])
    assert low.tolist() == [0.0, 0.0] and high[0] == 0.0 and high[1] > 0.0
    assert not _stop_fits([float("nan")], [0.0], [0.0], rows)


def test_unsynchronised_moving_target_stops_inside_bounds(teleavatar, caplog):
    """Regression: without synchronisation an early joint coasts at its target velocity until the slowest joint
    arrives; the end state's stop (after a period of coasting) must fit, or the trajectory is replaced."""
    limits = teleavatar.planning_limits
    rng = np.random.default_rng(7)
    for _ in range(227):  # the 227th scenario of this seed once overshot the upper bound of r_joint3 by 4 mm
        scenario = random_scenario(limits, rng, duration=3.0)
    streamer = JointStreamer(limits, DT, synchronization="none")
    with caplog.at_level(logging.WARNING, logger="taplan.stream.joint_streamer"):
        record = run_scenario(streamer, scenario)
    counts = stream_violations(record, limits, DT, scenario.initial)
    assert counts == dict.fromkeys(counts, 0)
    assert not [r for r in caplog.records if "leaves the position bounds" in r.getMessage()]


@pytest.mark.parametrize("synchronization", ["time", "none", "auto"])
def test_retarget_every_period_near_bounds(teleavatar, synchronization):
    """A new target every period (the vouched-for first period only) aimed at and beyond the bounds, with target
    velocities, then silence: every command inside the limits and continuous."""
    limits = teleavatar.planning_limits
    rng = np.random.default_rng(5)
    streamer = JointStreamer(limits, DT, synchronization=synchronization, timeout=0.3)
    for _ in range(15):
        streamer.reset(rng.uniform(limits.lower + 0.1, limits.upper - 0.1))
        initial = streamer.state.position
        states = []
        goal = np.where(rng.random(limits.size) < 0.5, limits.lower, limits.upper)
        for k in range(400):
            if k < 60:
                q = goal + rng.normal(0.0, 0.05, limits.size)
                v = rng.uniform(-1.0, 1.0, limits.size) * limits.velocity if k % 2 else None
                streamer.set_target(q, v)
            states.append(streamer.step())
        record = StreamRecord.from_states(states)
        counts = stream_violations(record, limits, DT, initial)
        assert counts == dict.fromkeys(counts, 0)
        assert states[-1].at_rest
