"""Seeded random target streams and a checker of emitted command streams (used by tests, benchmarks, notebooks).

A *scenario* mimics how targets reach a streamer in real use: VR at 30-90 [Hz] with jitter, a policy every
0.1-0.6 [s], a human clicking every 0.5-3 [s]; some targets with velocities, some outside the bounds, some
malformed (NaN), and dropouts longer than the watchdog timeout. :func:`run_scenario` drives a
:class:`~taplan.stream.JointStreamer` through it and :func:`stream_violations` checks every emitted command against
the limits and checks continuity: between two commands the state can only change as a jerk-bounded motion allows,

.. math::

    |a_k - a_{k-1}| \\le j\\,\\Delta t,\\quad
    |v_k - v_{k-1} - a_{k-1}\\Delta t| \\le j\\,\\Delta t^2/2,\\quad
    |p_k - p_{k-1} - v_{k-1}\\Delta t - a_{k-1}\\Delta t^2/2| \\le j\\,\\Delta t^3/6,

which a jump at a retarget would break.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from taplan.errors import StreamError
from taplan.limits import JointLimits
from taplan.stream.joint_streamer import JointStreamer
from taplan.stream.state import StreamState

__all__ = ["TargetEvent", "Scenario", "random_scenario", "run_scenario", "stream_violations", "StreamRecord"]

LIMIT_TOL = 1e-9  # relative slack on velocity/acceleration/jerk checks (ruckig is exact to ~1e-12)
CONTINUITY_TOL = 1e-7  # absolute slack on the continuity inequalities: the position clip to the bounds (<= 1e-7 [rad])


@dataclass(frozen=True)
class TargetEvent:
    """A target arriving at ``time`` [s]; ``positions`` may be malformed on purpose (``valid`` False)."""

    time: float
    positions: np.ndarray
    velocities: np.ndarray | None = None
    valid: bool = True


@dataclass(frozen=True)
class Scenario:
    """A seeded target stream: initial position [rad] (n,), events sorted by time, duration [s]."""

    initial: np.ndarray
    events: tuple[TargetEvent, ...]
    duration: float
    kind: str


@dataclass
class StreamRecord:
    """What :func:`run_scenario` saw: arrays (steps, n) of the emitted states, and per-step flags."""

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    jerks: np.ndarray
    statuses: list[str]
    retargets: np.ndarray  # bool (steps,): a new trajectory was computed at this step
    rejected: int = 0  # malformed targets that raised StreamError
    adjusted: int = 0  # targets admitted after clamping
    faults: list[str] = field(default_factory=list)

    @classmethod
    def from_states(cls, states: Sequence[StreamState]) -> StreamRecord:
        """A record of the states a streamer emitted, in order."""
        return cls(
            np.array([s.time for s in states]),
            np.array([s.position for s in states]),
            np.array([s.velocity for s in states]),
            np.array([s.acceleration for s in states]),
            np.array([s.jerk for s in states]),
            [s.status.value for s in states],
            np.array([s.new_calculation for s in states]),
        )


def random_scenario(
    limits: JointLimits,
    rng: np.random.Generator,
    *,
    duration: float = 3.0,
    timeout: float = 1.0,
    kind: str | None = None,
) -> Scenario:
    """A random target stream for ``limits``.

    Args:
        limits: Joint limits (targets are drawn around their bounds).
        rng: Seeded generator.
        duration: Length of the scenario [s].
        timeout: The streamer's watchdog timeout [s] (dropouts are made longer than it).
        kind: ``"vr"``, ``"policy"``, ``"human"`` or None (random).
    """
    kind = kind or str(rng.choice(["vr", "policy", "human"]))
    lo, hi = limits.lower, limits.upper
    span = hi - lo
    initial = rng.uniform(lo + 0.05 * span, hi - 0.05 * span)
    period = {"vr": 1.0 / rng.uniform(30.0, 90.0), "policy": rng.uniform(0.1, 0.6), "human": rng.uniform(0.5, 3.0)}[
        kind
    ]
    events: list[TargetEvent] = []
    t = rng.uniform(0.0, period)
    q = initial.copy()
    while t < duration:
        if kind == "vr":  # a smooth hand motion sampled with jitter
            q = np.clip(q + rng.normal(0.0, 0.02, q.size) * span, lo - 0.02, hi + 0.02)
        else:
            q = rng.uniform(lo - 0.05 * span, hi + 0.05 * span)  # some land outside the bounds
            if rng.random() < 0.3:  # bounds are where streams go wrong: aim at them
                q = np.where(rng.random(q.size) < 0.5, lo, hi) + rng.normal(0.0, 1e-3, q.size)
        velocities = None
        if rng.random() < 0.3:
            velocities = rng.uniform(-1.0, 1.0, q.size) * limits.velocity * rng.uniform(0.0, 1.2)
        events.append(TargetEvent(t, q.copy(), velocities))
        if rng.random() < 0.05:  # malformed target
            bad = q.copy()
            if rng.random() < 0.5:
                bad[rng.integers(q.size)] = rng.choice([np.nan, np.inf, -np.inf])
            else:
                bad = bad[:-1]
            events.append(TargetEvent(t + 1e-4, bad, None, valid=False))
        gap = period * rng.uniform(0.5, 1.5)  # jitter
        if rng.random() < 0.1:  # dropout
            gap += timeout * rng.uniform(1.0, 2.0)
        t += gap
    return Scenario(initial, tuple(events), duration, kind)


def run_scenario(streamer: JointStreamer, scenario: Scenario) -> StreamRecord:
    """Reset ``streamer`` at the scenario's initial position and step it through the scenario.

    At each step the latest event that arrived since the previous step is given to ``set_target`` (all of them, in
    order, so malformed ones are counted as rejected).
    """
    streamer.reset(scenario.initial)
    dt = streamer.dt
    steps = int(np.ceil(scenario.duration / dt))
    n = streamer.n
    positions = np.empty((steps, n))
    velocities = np.empty((steps, n))
    accelerations = np.empty((steps, n))
    jerks = np.empty((steps, n))
    times = np.empty(steps)
    retargets = np.zeros(steps, dtype=bool)
    statuses: list[str] = []
    record = StreamRecord(times, positions, velocities, accelerations, jerks, statuses, retargets)
    events = scenario.events
    k = 0
    for i in range(steps):
        now = i * dt
        while k < len(events) and events[k].time <= now:
            event = events[k]
            k += 1
            try:
                if streamer.set_target(event.positions, event.velocities):
                    record.adjusted += 1
            except StreamError:
                if event.valid:
                    raise
                record.rejected += 1
        state: StreamState = streamer.step()
        times[i] = state.time
        positions[i] = state.position
        velocities[i] = state.velocity
        accelerations[i] = state.acceleration
        jerks[i] = state.jerk
        retargets[i] = state.new_calculation
        statuses.append(state.status.value)
        if state.fault:
            record.faults.append(state.fault)
    return record


def stream_violations(
    record: StreamRecord, limits: JointLimits, dt: float, initial: np.ndarray | None = None
) -> dict[str, int]:
    """Count limit and continuity violations in an emitted command stream.

    Args:
        record: Emitted states.
        limits: The limits the stream must respect.
        dt: Control period [s].
        initial: The state before the first command (position [rad], at rest), to check the first step too.

    Returns:
        Counts per kind (``position``, ``velocity``, ``acceleration``, ``jerk``, ``continuity``, ``nonfinite``);
        all zero for a good stream.
    """
    p, v, a, j = record.positions, record.velocities, record.accelerations, record.jerks
    if initial is not None:
        zero = np.zeros((1, p.shape[1]))
        p = np.vstack([initial[None, :], p])
        v, a = np.vstack([zero, v]), np.vstack([zero, a])
    vmax, amax, jmax = limits.velocity, limits.acceleration, limits.jerk
    counts = {
        "nonfinite": int(np.sum(~np.isfinite(p)) + np.sum(~np.isfinite(v)) + np.sum(~np.isfinite(a))),
        "position": int(np.sum((p < limits.lower) | (p > limits.upper))),
        "velocity": int(np.sum(np.abs(v) > vmax * (1 + LIMIT_TOL))),
        "acceleration": int(np.sum(np.abs(a) > amax * (1 + LIMIT_TOL))),
        "jerk": int(np.sum(np.abs(j) > jmax * (1 + LIMIT_TOL))),
    }
    dp, dv, da = np.diff(p, axis=0), np.diff(v, axis=0), np.diff(a, axis=0)
    counts["jerk"] += int(np.sum(np.abs(da) > jmax * dt * (1 + LIMIT_TOL) + CONTINUITY_TOL))
    counts["velocity"] += int(np.sum(np.abs(dp) > vmax * dt * (1 + LIMIT_TOL) + CONTINUITY_TOL))
    counts["acceleration"] += int(np.sum(np.abs(dv) > amax * dt * (1 + LIMIT_TOL) + CONTINUITY_TOL))
    v0, a0 = v[:-1], a[:-1]
    jump_v = np.abs(dv - a0 * dt) > jmax * dt**2 / 2 * (1 + LIMIT_TOL) + CONTINUITY_TOL
    jump_p = np.abs(dp - v0 * dt - a0 * dt**2 / 2) > jmax * dt**3 / 6 * (1 + LIMIT_TOL) + CONTINUITY_TOL
    counts["continuity"] = int(np.sum(jump_v) + np.sum(jump_p))
    return counts
