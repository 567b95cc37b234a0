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
