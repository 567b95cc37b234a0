"""Vectorised piecewise-polynomial helpers: composition with a quadratic, exact extrema, time scaling."""

from __future__ import annotations

import numpy as np

from taplan.trajectory import Trajectory

__all__ = ["compose_quadratic", "max_abs_derivative", "time_scaled"]

_SAMPLES = 12  # samples per segment before locating the extrema by bisection
_BISECTIONS = 48


def _polymul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Product of batched polynomials p (m, a) and q (m, b) in ascending powers -> (m, a+b-1)."""
    out = np.zeros((p.shape[0], p.shape[1] + q.shape[1] - 1))
    for i in range(p.shape[1]):
        out[:, i : i + q.shape[1]] += p[:, i : i + 1] * q
    return out


def compose_quadratic(cubic: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Coefficients of ``q(sigma(tau))`` for polynomial pieces ``q`` (cubic, quintic, ...) and a polynomial ``sigma``.

    Args:
        cubic: Shape (m, d+1, n): ``q(x) = sum_k cubic[:, k] x**k``.
        sigma: Shape (m, p+1): ``x = sum_i sigma[:, i] tau**i``.

    Returns:
        Shape (m, d p+1, n): ascending powers of ``tau`` (7 for a cubic ``q`` and a quadratic ``sigma``).
    """
    m, order, n = cubic.shape
    powers = [np.ones((m, 1))]
    for _ in range(order - 1):
        powers.append(_polymul(powers[-1], sigma))
    out = np.zeros((m, powers[-1].shape[1], n))
    for k, pk in enumerate(powers):
        out[:, : pk.shape[1], :] += pk[:, :, None] * cubic[:, k : k + 1, :]
    return out


def _horner(c: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Evaluate c (m, d+1, n) at tau (m, k) -> (m, k, n)."""
    out = np.broadcast_to(c[:, -1:, :], (c.shape[0], tau.shape[1], c.shape[2])).copy()
    for i in range(c.shape[1] - 2, -1, -1):
        out = c[:, i : i + 1, :] + tau[:, :, None] * out
    return out


def _derivative(c: np.ndarray) -> np.ndarray:
    if c.shape[1] == 1:
        return np.zeros_like(c)
    return c[:, 1:] * np.arange(1, c.shape[1])[None, :, None]


def max_abs_derivative(traj: Trajectory, order: int) -> np.ndarray:
    """Largest ``|d^order q / dt^order|`` on each segment of ``traj``, exact up to bisection accuracy.

    Samples each segment, then refines every sign change of the next derivative by bisection, so interior
    extrema between samples are found.

    Returns:
        Shape (N-1, n).
    """
    c = traj.derivative_coefficients(order)
    h = np.diff(traj.times)
    tau = h[:, None] * np.linspace(0.0, 1.0, _SAMPLES + 1)[None, :]
    values = np.abs(_horner(c, tau))  # (m, k, n)
    best = values.max(axis=1)
    if c.shape[1] <= 1:
        return best
    dc = _derivative(c)
    slope = _horner(dc, tau)
    change = (slope[:, :-1] * slope[:, 1:]) < 0  # (m, k-1, n)
    seg, k, joint = np.nonzero(change)
    if seg.size:
        lo = tau[seg, k].copy()
        hi = tau[seg, k + 1].copy()
        f_lo = slope[seg, k, joint]
        dcj = dc[seg, :, joint]  # (p, d)
        for _ in range(_BISECTIONS):
            mid = 0.5 * (lo + hi)
            f_mid = _eval_rows(dcj, mid)
            left = np.sign(f_mid) == np.sign(f_lo)
            lo = np.where(left, mid, lo)
            f_lo = np.where(left, f_mid, f_lo)
            hi = np.where(left, hi, mid)
        peak = np.abs(_eval_rows(c[seg, :, joint], 0.5 * (lo + hi)))
        np.maximum.at(best, (seg, joint), peak)
    return best


def _eval_rows(c: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Evaluate rows c (p, d+1) at x (p,)."""
    out = c[:, -1].copy()
    for i in range(c.shape[1] - 2, -1, -1):
        out = c[:, i] + x * out
    return out


def time_scaled(traj: Trajectory, factor: float) -> Trajectory:
    """The same motion ``factor`` times slower (>1) or faster (<1): velocities / factor, accelerations / factor²."""
    return traj.stretched(factor)
