"""taplan.timing._fir: the exact moving average against quadrature, its bounds, and its ends."""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from benchmarks._paths import random_walk
from taplan.timing import limit_usage, retime
from taplan.timing._fir import moving_average, taylor_shift

POS_TOL = 1e-9  # [rad]
LIMIT_TOL = 1e-9  # relative


@pytest.fixture(scope="module")
def topp(teleavatar: taplan.Robot) -> tuple[taplan.Trajectory, taplan.JointLimits]:
    limits = teleavatar.planning_limits.subset(teleavatar.group("right").joint_names)
    return retime(random_walk(limits, 7, 21), limits), limits


def test_taylor_shift_matches_direct_evaluation() -> None:
    rng = np.random.default_rng(0)
    c = rng.normal(size=(5, 8, 3))
    d = rng.uniform(-2, 2, 5)
    y = rng.uniform(-1, 1, 5)
    shifted = taylor_shift(c, d)
    direct = np.einsum("mk,mkn->mn", (y + d)[:, None] ** np.arange(8), c)
    via_shift = np.einsum("mk,mkn->mn", y[:, None] ** np.arange(8), shifted)
    np.testing.assert_allclose(via_shift, direct, rtol=1e-12, atol=1e-10)


@pytest.mark.parametrize("width", [0.05, 0.2, 0.7])
def test_moving_average_matches_quadrature(topp, width: float) -> None:
    traj, _ = topp
    filtered = moving_average(traj, width)
    assert filtered.duration == pytest.approx(traj.duration + width, abs=1e-12)
    t = np.linspace(0.0, filtered.duration, 37)
    nodes, weights = np.polynomial.legendre.leggauss(40)
    expected = []
    for ti in t:  # Gauss-Legendre on each input piece inside [t - w, t], the held ends outside
        lo, hi = ti - width, ti
        cuts = np.unique(np.clip(np.concatenate([[lo, hi], traj.times]), lo, hi))
        total = np.zeros(traj.n_joints)
        for a, b in zip(cuts[:-1], cuts[1:], strict=True):
            x = (a + b) / 2 + (b - a) / 2 * nodes
            total += (b - a) / 2 * weights @ traj(np.clip(x, 0.0, traj.duration))
        expected.append(total / width)
    np.testing.assert_allclose(filtered(t), np.array(expected), atol=POS_TOL)


def test_moving_average_keeps_the_inputs_bounds_and_rests(topp) -> None:
    traj, limits = topp
    width = float(np.max(2 * limits.acceleration / limits.jerk))
    filtered = moving_average(traj, width)
    usage_in = limit_usage(traj, limits)
    usage_out = limit_usage(filtered, limits)
    assert usage_out.max_velocity <= usage_in.max_velocity * (1 + LIMIT_TOL)
    assert usage_out.max_acceleration <= usage_in.max_acceleration * (1 + LIMIT_TOL)
    assert usage_out.within(1e-6, jerk=True)
    for t in (0.0, filtered.duration):
        np.testing.assert_allclose(filtered(t, 1), 0.0, atol=1e-9)
        np.testing.assert_allclose(filtered(t, 2), 0.0, atol=1e-7)
    np.testing.assert_allclose(filtered(0.0), traj(0.0), atol=POS_TOL)
    np.testing.assert_allclose(filtered(filtered.duration), traj(traj.duration), atol=POS_TOL)
