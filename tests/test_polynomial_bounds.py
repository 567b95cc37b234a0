"""taplan.timing._polynomial: the Bernstein bound of a derivative contains its exact peaks and is close to them on
short pieces; peak_ratio is exact wherever a limit is exceeded; the vectorised Taylor shift equals the direct one."""

from __future__ import annotations

from math import comb

import numpy as np
import pytest

import taplan
from benchmarks._paths import random_walk
from taplan.timing import retime
from taplan.timing._fir import moving_average, taylor_shift
from taplan.timing._polynomial import derivative_bound, max_abs_derivative, peak_ratio

BOUND_TOL = 1e-12  # relative: the bound may sit this far below the sampled-and-bisected peak (rounding)


@pytest.fixture(scope="module")
def trajectories(teleavatar: taplan.Robot) -> list[taplan.Trajectory]:
    """TOPP-RA outputs (degree 6) and their moving averages (degree 7), pieces of a few ms as in the planner."""
    limits = teleavatar.planning_limits.subset(teleavatar.group("left").joint_names)
    out = []
    for seed in range(3):
        topp = retime(random_walk(limits, 12, seed), limits, points_per_segment=4)
        out += [topp, moving_average(topp, 0.2)]
    return out


@pytest.mark.parametrize("order", [1, 2, 3])
def test_derivative_bound_contains_the_peaks_and_stays_close(trajectories, order: int) -> None:
    for trajectory in trajectories:
        exact = max_abs_derivative(trajectory, order)
        bound = derivative_bound(trajectory, order)
        assert bound.shape == exact.shape
        assert np.all(bound >= exact * (1 - BOUND_TOL) - 1e-12)
        # on pieces of a few ms the hull is within a few percent of the peak of each joint
        assert np.all(bound.max(axis=0) <= 1.05 * exact.max(axis=0) + 1e-9)
        t = np.linspace(0.0, trajectory.duration, 4001)  # and above densely sampled values
        sampled = np.abs(trajectory(t, order))
        piece = np.clip(np.searchsorted(trajectory.times, t, side="right") - 1, 0, len(trajectory.times) - 2)
        assert np.all(sampled <= bound[piece] * (1 + BOUND_TOL) + 1e-12)


def test_derivative_bound_of_a_still_joint_is_zero() -> None:
    times = np.array([0.0, 0.5, 1.0])
    c = np.zeros((2, 4, 2))
    c[:, 0, 1] = 0.3  # joint 1 holds its position
    c[0, 1:, 0] = [0.2, 0.1, -0.05]
    c[1, 0, 0] = 0.2 * 0.5 + 0.1 * 0.25 - 0.05 * 0.125
    c[1, 1, 0] = 0.2 + 0.2 * 0.5 - 0.15 * 0.25
    trajectory = taplan.Trajectory.from_polynomials(times, c)
    assert np.all(derivative_bound(trajectory, 1)[:, 1] == 0.0)


@pytest.mark.parametrize("order", [1, 2, 3])
def test_peak_ratio_is_exact_above_the_limit_and_at_most_one_below(trajectories, order: int) -> None:
    for trajectory in trajectories:
        exact = max_abs_derivative(trajectory, order)
        limit = 0.9 * exact.max(axis=0)  # some pieces above, most below
        ratio = peak_ratio(trajectory, order, limit)
        above = exact / limit > 1.0
        assert above.any() and (~above).any()
        np.testing.assert_array_equal(ratio[above], (exact / limit)[above])
        assert np.all(ratio[~above] <= 1.0)
        assert np.all(ratio[~above] >= (exact / limit)[~above] * (1 - BOUND_TOL))


def test_taylor_shift_equals_the_binomial_expansion() -> None:
    rng = np.random.default_rng(1)
    c = rng.normal(size=(40, 8, 3))
    d = rng.uniform(-0.3, 0.3, 40)
    direct = np.zeros_like(c)
    for j in range(8):
        for k in range(j, 8):
            direct[:, j] += comb(k, j) * d[:, None] ** (k - j) * c[:, k]
    np.testing.assert_allclose(taylor_shift(c, d), direct, rtol=1e-13, atol=1e-14)
