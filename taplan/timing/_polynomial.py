"""Vectorised piecewise-polynomial helpers: composition with a quadratic, exact extrema, time scaling."""

from __future__ import annotations

from math import comb

import numpy as np

from taplan.trajectory import Trajectory

__all__ = [
    "compose_quadratic",
    "concatenated",
    "derivative_bound",
    "max_abs_derivative",
    "peak_ratio",
    "near_cubic_bounds",
    "position_range",
    "sliced",
    "sliced_pieces",
    "time_scaled",
]

_SAMPLES = 12  # samples per segment before locating the extrema by bisection
_BISECTIONS = 48
_SETTLED = 1e-9  # relative: a Bernstein bound this far below a limit settles the entry (exact search skipped)


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


def derivative_bound(traj: Trajectory, order: int) -> np.ndarray:
    """An upper bound of ``|d^order q / dt^order|`` on each segment of ``traj`` (N-1, n): the largest absolute
    Bernstein coefficient of the derivative on the segment (a polynomial lies in the convex hull of its Bernstein
    coefficients). Within a few percent of :func:`max_abs_derivative` on short segments (the hull tightens with the
    square of the segment's length), at a fraction of its cost (no sampling, no root search); joints that do not
    move on a segment get exactly 0."""
    c = traj.derivative_coefficients(order)  # (m, D+1, n)
    h = np.diff(traj.times)
    degree = c.shape[1] - 1
    if degree == 0:
        return np.abs(c[:, 0])
    scaled = c * (h[:, None] ** np.arange(degree + 1))[:, :, None]
    return np.abs(np.einsum("ki,min->mkn", _bernstein(degree), scaled)).max(axis=1)


def _bernstein(degree: int) -> np.ndarray:
    """Power to Bernstein coefficients on [0, 1]: ``b_k = sum_{i<=k} C(k, i) / C(degree, i) a_i``."""
    return np.array(
        [[comb(k, i) / comb(degree, i) if i <= k else 0.0 for i in range(degree + 1)] for k in range(degree + 1)]
    )


def max_abs_derivative(traj: Trajectory, order: int) -> np.ndarray:
    """Largest ``|d^order q / dt^order|`` on each segment of ``traj``, exact up to bisection accuracy.

    Samples each segment, then refines every sign change of the next derivative by bisection, so interior
    extrema between samples are found.

    Returns:
        Shape (N-1, n).
    """
    return _max_abs(traj.derivative_coefficients(order), np.diff(traj.times))


def peak_ratio(traj: Trajectory, order: int, limit: np.ndarray) -> np.ndarray:
    """Per segment and joint (N-1, n): ``max |d^order q / dt^order| / limit``, exact (:func:`max_abs_derivative`)
    wherever it exceeds 1, and at most 1 elsewhere. The Bernstein bound (:func:`derivative_bound`) settles every
    entry it keeps at or below 1; the sampling and root search run only on the others. A time scaling or a
    tightening computed from the entries above 1 is the same as from the exact peaks (TOPP-RA's output at the
    limits: a fraction of the entries to search)."""
    ratio = derivative_bound(traj, order) / limit
    segment, joint = np.nonzero(ratio > 1.0 - _SETTLED)  # a bound this close to 1 could hide rounding
    if segment.size:
        c = traj.derivative_coefficients(order)[segment, :, joint][:, :, None]  # (p, d+1, 1)
        exact = _max_abs(c, np.diff(traj.times)[segment])[:, 0]
        ratio[segment, joint] = exact / limit[joint]
    return ratio


def _max_abs(c: np.ndarray, h: np.ndarray) -> np.ndarray:
    """:func:`max_abs_derivative` of polynomial pieces ``c`` (m, d+1, n) on [0, h] (m,) -> (m, n)."""
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


def sliced(traj: Trajectory, start: float, end: float) -> Trajectory:
    """The part of ``traj`` between ``start`` and ``end`` [s], exact, re-timed to start at 0."""
    return Trajectory.from_polynomials(*sliced_pieces(traj, start, end), traj.joint_names)


def sliced_pieces(traj: Trajectory, start: float, end: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`sliced` as ``(times from 0, coefficients)``, without building a :class:`Trajectory`."""
    times = traj.times
    inner = times[(times > start + 1e-12) & (times < end - 1e-12)]
    breaks = np.concatenate([[start], inner, [end]])
    k = np.clip(np.searchsorted(times, breaks[:-1], side="right") - 1, 0, len(times) - 2)
    c = traj.coefficients[k]
    shift = breaks[:-1] - times[k]
    degree = c.shape[1] - 1
    # re-expand each piece about its new start: out_j = sum_i C(i, j) shift^(i-j) c_i
    binomial = np.array([[comb(i, j) for i in range(degree + 1)] for j in range(degree + 1)], dtype=float)
    exponent = np.maximum(np.arange(degree + 1)[None, :] - np.arange(degree + 1)[:, None], 0)
    weights = binomial[None] * shift[:, None, None] ** exponent[None]  # (m, j, i); zero where i < j
    out = np.einsum("mji,min->mjn", weights, c)
    return breaks - start, out


def concatenated(
    parts: list[Trajectory | tuple[np.ndarray, np.ndarray]], joint_names: tuple[str, ...] | None = None
) -> Trajectory:
    """The trajectories one after the other (each starting where the previous one ends), exact. ``parts`` are
    trajectories or ``(times, coefficients)`` pairs; ``joint_names`` default to the first trajectory's."""
    pairs = [(p.times, p.coefficients) if isinstance(p, Trajectory) else p for p in parts]
    if joint_names is None:
        joint_names = next(p.joint_names for p in parts if isinstance(p, Trajectory))
    width = max(c.shape[1] for _, c in pairs)
    times, pieces, offset = [0.0], [], 0.0
    for t, c in pairs:
        times += list(offset + t[1:] - t[0])
        pieces.append(np.pad(c, ((0, 0), (0, width - c.shape[1]), (0, 0))))
        offset += float(t[-1] - t[0])
    return Trajectory.from_polynomials(np.array(times), np.concatenate(pieces), joint_names)


def position_range(traj: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """Exact lowest and highest position of each joint over all pieces, shape (n,) each (closed form for cubics,
    polynomial roots above)."""
    c = traj.coefficients
    if c.shape[1] > 4 and np.any(c[:, 4:]):
        return _position_range_roots(traj)
    h = np.diff(traj.times)[:, None]
    c0, c1, c2, c3 = (c[:, i] for i in range(4))
    # extrema where c1 + 2 c2 x + 3 c3 x² = 0, inside [0, h]
    candidates = [np.zeros_like(c0), np.broadcast_to(h, c0.shape)]
    disc = np.maximum(4 * c2**2 - 12 * c3 * c1, 0.0)
    safe = np.where(np.abs(c3) > 1e-300, 6 * c3, np.inf)
    linear = np.where(np.abs(c2) > 1e-300, -c1 / np.where(np.abs(c2) > 1e-300, 2 * c2, 1.0), 0.0)
    for sign in (-1.0, 1.0):
        root = np.where(np.isfinite(safe), (-2 * c2 + sign * np.sqrt(disc)) / safe, linear)
        candidates.append(np.clip(root, 0.0, h))
    x = np.stack(candidates)  # (4, m, n)
    values = c0 + x * (c1 + x * (c2 + x * c3))
    return values.min(axis=(0, 1)), values.max(axis=(0, 1))


def near_cubic_bounds(times: np.ndarray, coefficients: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rigorous bounds for pieces that are cubics plus a small higher-degree rest (ruckig's motions with their
    1e-12 end correction): the cubic part's extrema in closed form, plus the largest the rest can add on the piece
    (``sum_i |c_i| i!/(i-k)! h^(i-k)``). Cheaper than :func:`position_range` and :func:`max_abs_derivative` on
    quintics, and never below the true values.

    Returns:
        ``(low (n,), high (n,), peaks (3, n))``: position range [rad] and the largest ``|q̇|``, ``|q̈|``, ``|jerk|``.
    """
    c = coefficients
    h = np.diff(times)[:, None]  # (m, 1)
    c0, c1, c2, c3 = (c[:, i] for i in range(4))
    rest = np.abs(c[:, 4:])  # (m, r, n)
    powers = np.arange(4, c.shape[1])

    def slack(order: int) -> np.ndarray:  # bound of the rest's order-th derivative on [0, h], (m, n)
        if rest.shape[1] == 0:
            return np.zeros_like(c0)
        falling = np.array([np.prod(np.arange(p - order + 1, p + 1)) for p in powers], dtype=float)
        return np.einsum("mrn,r,mr->mn", rest, falling, h ** (powers - order))

    # position: cubic extrema where c1 + 2 c2 x + 3 c3 x² = 0 inside [0, h]
    candidates = [np.zeros_like(c0), np.broadcast_to(h, c0.shape)]
    disc = np.maximum(4 * c2**2 - 12 * c3 * c1, 0.0)
    quadratic = np.abs(c3) > 1e-300
    linear = np.abs(c2) > 1e-300
    for sign in (-1.0, 1.0):
        root = np.where(quadratic, (-2 * c2 + sign * np.sqrt(disc)) / np.where(quadratic, 6 * c3, 1.0), 0.0)
        root = np.where(quadratic, root, np.where(linear, -c1 / np.where(linear, 2 * c2, 1.0), 0.0))
        candidates.append(np.clip(root, 0.0, h))
    x = np.stack(candidates)
    values = c0 + x * (c1 + x * (c2 + x * c3))
    position_slack = slack(0)
    low = (values.min(axis=0) - position_slack).min(axis=0)
    high = (values.max(axis=0) + position_slack).max(axis=0)
    # velocity c1 + 2 c2 x + 3 c3 x²: ends and vertex; acceleration 2 c2 + 6 c3 x: ends; jerk 6 c3
    vertex = np.clip(np.where(quadratic, -c2 / np.where(quadratic, 3 * c3, 1.0), 0.0), 0.0, h)
    velocity = np.stack([c1 + y * (2 * c2 + 3 * c3 * y) for y in (candidates[0], candidates[1], vertex)])
    acceleration = np.stack([2 * c2, 2 * c2 + 6 * c3 * h])
    peaks = np.stack(
        [
            (np.abs(velocity).max(axis=0) + slack(1)).max(axis=0),
            (np.abs(acceleration).max(axis=0) + slack(2)).max(axis=0),
            (np.abs(6 * c3) + slack(3)).max(axis=0),
        ]
    )
    return low, high, peaks


def _position_range_roots(traj: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """Per joint the extremes over the pieces: the ends and the real roots of the derivative inside each piece, from
    the eigenvalues of the derivatives' companion matrices, batched by degree (one eigvals call per degree instead
    of one ``Polynomial.roots`` per piece and joint)."""
    c = traj.coefficients  # (m, d + 1, n), ascending powers
    m, order, n = c.shape
    h = np.repeat(np.diff(traj.times), n)  # per polynomial (piece-major, then joint)
    polys = c.transpose(0, 2, 1).reshape(m * n, order)
    deriv = polys[:, 1:] * np.arange(1, order)  # (K, d) ascending
    nonzero = deriv != 0.0
    degree = np.where(nonzero.any(axis=1), deriv.shape[1] - 1 - np.argmax(nonzero[:, ::-1], axis=1), 0)
    points = [np.zeros((m * n, 1)), h[:, None]]
    for D in np.unique(degree[degree >= 1]).tolist():
        rows = np.flatnonzero(degree == D)
        a = deriv[rows, : D + 1]
        companion = np.zeros((len(rows), D, D))
        companion[:, np.arange(1, D), np.arange(D - 1)] = 1.0
        companion[:, :, -1] = -a[:, :D] / a[:, D : D + 1]
        roots = np.linalg.eigvals(companion)
        inside = (np.abs(roots.imag) < 1e-12) & (roots.real > 0) & (roots.real < h[rows, None])
        x = np.zeros((m * n, D))  # a root outside the piece stands in as its start (already a candidate)
        x[rows] = np.where(inside, roots.real, 0.0)
        points.append(x)
    x = np.concatenate(points, axis=1)  # (K, candidates)
    values = np.zeros_like(x)
    for i in range(order - 1, -1, -1):
        values = polys[:, i : i + 1] + x * values
    values = values.reshape(m, n, -1)
    return values.min(axis=(0, 2)), values.max(axis=(0, 2))
