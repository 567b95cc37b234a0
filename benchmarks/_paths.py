"""Seeded random joint paths shared by the timing benchmark and tests."""

from __future__ import annotations

import numpy as np

import taplan


def random_walk(limits: taplan.JointLimits, count: int, seed: int, step: float = 0.4) -> np.ndarray:
    """``count`` waypoints [rad], shape (count, n): a seeded random walk of steps up to ``step`` [rad] per joint,
    kept within the middle 75 % of each joint's range."""
    rng = np.random.default_rng(seed)
    mid, half = (limits.lower + limits.upper) / 2, (limits.upper - limits.lower) / 2
    q = [mid + rng.uniform(-0.5, 0.5, limits.size) * half]
    for _ in range(count - 1):
        q.append(np.clip(q[-1] + rng.uniform(-step, step, limits.size), mid - 0.75 * half, mid + 0.75 * half))
    return np.array(q)


def near_bound_walk(limits: taplan.JointLimits, count: int, seed: int, step: float = 0.3) -> np.ndarray:
    """``count`` waypoints [rad], shape (count, n), every one inside the position limits and many on them: a seeded
    random walk of steps up to ``step`` [rad] per joint clipped onto the bounds, mixed with the hard cases of long
    teleoperation recordings: joints set onto a bound or within 1 mrad of it, duplicates, tiny steps (1e-8 to
    1e-4 rad) and reversals (back to the previous waypoint)."""
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(limits.lower, dtype=float), np.asarray(limits.upper, dtype=float)
    q = [rng.uniform(lo, hi)]
    kinds = rng.choice(5, size=count - 1, p=[0.6, 0.1, 0.1, 0.1, 0.1])
    for kind in kinds:
        last = q[-1]
        if kind == 0:  # an ordinary step, clipped onto the bounds
            nxt = np.clip(last + rng.uniform(-step, step, limits.size), lo, hi)
        elif kind == 1:  # a few joints onto a bound or within a millimetre-radian of it
            nxt = last.copy()
            pick = rng.random(limits.size) < 0.4
            at_upper = rng.random(limits.size) < 0.5
            gap = np.where(rng.random(limits.size) < 0.5, 0.0, rng.uniform(0.0, 1e-3, limits.size))
            nxt[pick] = np.where(at_upper, hi - gap, lo + gap)[pick]
        elif kind == 2:  # a duplicate
            nxt = last.copy()
        elif kind == 3:  # a tiny step
            nxt = np.clip(last + rng.uniform(-1.0, 1.0, limits.size) * 10.0 ** rng.uniform(-8, -4), lo, hi)
        else:  # a reversal: straight back to the previous waypoint
            nxt = q[-2].copy() if len(q) > 1 else np.clip(last - rng.uniform(-step, step, limits.size), lo, hi)
        q.append(nxt)
    if np.max(np.abs(q[-1] - q[0])) == 0.0 and all(np.array_equal(p, q[0]) for p in q):
        q[-1] = np.clip(q[0] + step, lo, hi) if np.any(q[0] + step <= hi) else np.clip(q[0] - step, lo, hi)
    return np.array(q)


def teleoperation_recording(
    limits: taplan.JointLimits, rate: float, duration: float, seed: int, noise: float = 5e-4
) -> tuple[np.ndarray, np.ndarray]:
    """A synthetic teleoperation recording: ``(times [s], positions [rad] (k, n))`` sampled at about ``rate`` [Hz]
    with 5 % timing jitter. Each joint is a sum of three slow sines (0.03-0.25 Hz, 10-40 % of its half range)
    clipped onto the position bounds (an operator pressing against a limit), plus white noise of ``noise`` [rad]
    (which may put samples slightly outside the bounds, as an encoder's reading can)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1.0 / rate)
    t = np.sort(t + rng.normal(0.0, 0.05 / rate, t.shape))
    t -= t[0]
    mid, half = (limits.lower + limits.upper) / 2, (limits.upper - limits.lower) / 2
    q = np.zeros((len(t), limits.size))
    for j in range(limits.size):
        for _ in range(3):
            amplitude = rng.uniform(0.1, 0.4) * half[j]
            q[:, j] += amplitude * np.sin(2 * np.pi * rng.uniform(0.03, 0.25) * t + rng.uniform(0.0, 2 * np.pi))
    q = np.clip(mid + q, limits.lower, limits.upper)
    return t, q + rng.normal(0.0, noise, q.shape)
