"""Exact moving-average (FIR) filtering of a piecewise-polynomial joint trajectory.

The filtered trajectory is ``q_f(t) = (1/w) ∫_{t-w}^{t} q(τ) dτ`` with ``q`` held at its first position before the
start and at its last after the end. Its derivatives are differences of the input's, divided by ``w``:

.. math::

    \\dot q_f = \\frac{q(t) - q(t-w)}{w}, \\quad \\ddot q_f = \\frac{\\dot q(t) - \\dot q(t-w)}{w}, \\quad
    \\dddot q_f = \\frac{\\ddot q(t) - \\ddot q(t-w)}{w}

so, for an input at rest at both ends: ``|q̇_f| <= max|q̇|`` and ``|q̈_f| <= max|q̈|`` (mean values), ``|q⃛_f| <=
2 max|q̈| / w``, every position is an average of the input's (inside any box that contains them), and the output
starts and ends at rest with zero acceleration, ``w`` later than the input.

The output is exact: on every interval between the input's breakpoints and the same shifted by ``w`` it is the
difference of two shifted antiderivative pieces, a polynomial one degree above the input's.
"""

from __future__ import annotations

from math import comb

import numpy as np

from taplan.trajectory import Trajectory

__all__ = ["moving_average", "taylor_shift"]

_BREAK_TOL = 1e-12  # [s] breakpoints closer than this are merged


def taylor_shift(coefficients: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """Coefficients of ``p(y + d)`` in ascending powers of ``y``, for ``p`` given in ascending powers.

    Args:
        coefficients: Shape (m, D+1, n).
        shift: ``d`` per polynomial, shape (m,).
    """
    degree = coefficients.shape[1] - 1
    k = np.arange(degree + 1)
    binomial = np.array([[comb(i, j) for i in k] for j in k], dtype=float)  # C(k, j), zero where k < j
    # weights[m, j, k] = C(k, j) d^(k - j): one batched matrix product instead of a loop over (j, k) (4x cheaper)
    weights = binomial[None] * shift[:, None, None] ** np.maximum(k[None, :] - k[:, None], 0)[None]
    return weights @ coefficients


def moving_average(trajectory: Trajectory, width: float) -> Trajectory:
    """The moving average of ``trajectory`` over ``width`` [s], exact, starting at the input's start time.

    Args:
        trajectory: A trajectory (its polynomial pieces are used as they are).
        width: Window ``w`` [s] > 0; the output lasts ``w`` longer than the input.
    """
    t = trajectory.times
    c = trajectory.coefficients  # (M, d+1, n), powers of (t - t_k)
    pieces, order, n = c.shape
    h = np.diff(t)
    # antiderivative pieces Q, with index 0 the held start and M+1 the held end
    Q = np.zeros((pieces + 2, order + 1, n))
    Q[1:-1, 1:] = c / np.arange(1, order + 1)[None, :, None]
    area = np.einsum("mk,mkn->mn", h[:, None] ** np.arange(1, order + 1)[None, :], Q[1:-1, 1:])
    cumulative = np.concatenate([np.zeros((1, n)), np.cumsum(area, axis=0)])
    Q[1:-1, 0] = cumulative[:-1]
    Q[0, 1] = c[0, 0]  # Q(t) = q(t0) (t - t0) before the start
    Q[-1, 0] = cumulative[-1]
    Q[-1, 1] = trajectory.positions[-1]
    origins = np.concatenate([[t[0]], t[:-1], [t[-1]]])

    breaks = np.unique(np.concatenate([t, t + width]))
    breaks = breaks[np.concatenate([[True], np.diff(breaks) > _BREAK_TOL])]
    breaks[-1] = t[-1] + width
    left = breaks[:-1]
    middle = left + np.diff(breaks) / 2  # never on a breakpoint: the piece is unambiguous

    def piece(x: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(t, x, side="right"), 0, pieces + 1)

    now, before = piece(middle), piece(middle - width)
    upper = taylor_shift(Q[now], left - origins[now])
    lower = taylor_shift(Q[before], left - width - origins[before])
    return Trajectory.from_polynomials(breaks, (upper - lower) / width, trajectory.joint_names)
