"""A geometric path through joint waypoints: ``path(s, order)`` like toppra's interface.

The path is a C² cubic spline ``q(s)`` through the waypoints, with the path parameter ``s`` at the waypoints either
uniform (``0, 1, ..., N-1`` scaled to [0, 1], toppra's usual choice) or proportional to the cumulative joint-space
chord length. It derives from :class:`toppra.interpolator.AbstractGeometricPath`, so toppra accepts it directly.

**Staying inside a box** (``bounds=(lower, upper)``, what :func:`~taplan.timing.retime` and
:func:`~taplan.timing.jerk_limited` pass from the position limits). A spline through waypoints near a bound
overshoots between them. With bounds, each piece is written as a quintic Hermite polynomial with the spline's
first and second derivatives at its knots, which reproduces the cubic exactly, and those derivatives are then
clipped per joint and per knot so that the piece's six Bernstein coefficients lie inside the box:

    b0 = y0, b1 = y0 + d0 h/5, b2 = y0 + 2 d0 h/5 + e0 h²/20, b3 = y1 - 2 d1 h/5 + e1 h²/20, b4 = y1 - d1 h/5, b5 = y1

A polynomial lies in the convex hull of its Bernstein coefficients, so the path *cannot* leave the box; each
condition involves one knot only, so the clipping is closed-form (no iteration), and the path stays C² (the
knots keep one first and one second derivative on both sides). Where nothing needs clipping the path is the
plain cubic spline. A waypoint on a bound gets zero slope there (it is a local extremum of that joint).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.interpolate import CubicHermiteSpline, CubicSpline, PPoly
from toppra.interpolator import AbstractGeometricPath

from taplan._validation import as_matrix, as_vector
from taplan.errors import InvalidInputError

__all__ = ["Path", "validate_waypoints", "drop_duplicates", "DUPLICATE_TOL"]

DUPLICATE_TOL = 1e-9  # [rad]: consecutive waypoints closer than this (max-norm) are duplicates

_PARAMETRISATIONS = ("uniform", "chord")


def validate_waypoints(
    waypoints: npt.ArrayLike, name: str = "waypoints", size: int | None = None, *, repeats: bool = False
) -> np.ndarray:
    """Return ``waypoints`` as a finite (N, n) array with N >= 2 and no duplicate consecutive rows, or raise.

    Args:
        waypoints: Joint positions [rad], shape (N, n).
        name: Argument name used in error messages.
        size: Required n, or None.
        repeats: Allow consecutive equal rows (a pause on a path parametrised by time).
    """
    q = as_matrix(waypoints, name, (None, size))
    if q.shape[0] < 2:
        raise InvalidInputError(name, f"{q.shape[0]} waypoint(s)", "at least 2 waypoints")
    if q.shape[1] < 1:
        raise InvalidInputError(name, f"shape {q.shape}", "at least one joint")
    step = np.max(np.abs(np.diff(q, axis=0)), axis=1)
    if not repeats and np.any(step <= DUPLICATE_TOL):
        k = int(np.argmax(step <= DUPLICATE_TOL))
        raise InvalidInputError(
            name, f"waypoints {k} and {k + 1} are equal", f"consecutive waypoints that differ by > {DUPLICATE_TOL} rad"
        )
    return q


def drop_duplicates(waypoints: npt.ArrayLike, name: str = "waypoints", size: int | None = None) -> np.ndarray:
    """``waypoints`` as a finite (N, n) array without repeats: a waypoint within ``DUPLICATE_TOL`` (max-norm) of the
    last one kept is dropped, except the final waypoint, which replaces it (the path still ends exactly there).

    Raises:
        InvalidInputError: not a finite (N, n) array, or fewer than 2 distinct waypoints.
    """
    q = as_matrix(waypoints, name, (None, size))
    if q.shape[1] < 1:
        raise InvalidInputError(name, f"shape {q.shape}", "at least one joint")
    keep = [0]
    for k in range(1, len(q)):
        if np.max(np.abs(q[k] - q[keep[-1]])) > DUPLICATE_TOL:
            keep.append(k)
    if len(keep) < 2:
        got = f"{len(q)} waypoint(s)" + (", all equal" if len(q) > 1 else "")
        raise InvalidInputError(name, got, "at least 2 distinct waypoints")
    if keep[-1] != len(q) - 1:
        keep[-1] = len(q) - 1
    return q[keep]


class Path(AbstractGeometricPath):
    """Cubic-spline joint path ``q(s)`` through waypoints.

    Args:
        waypoints: Joint positions [rad], shape (N, n), N >= 2, no two consecutive equal.
        ss: Path parameter at the waypoints, strictly increasing, shape (N,); overrides ``parametrisation``. With
            ``ss``, consecutive equal waypoints are allowed (a pause when ``s`` is time).
        parametrisation: ``"uniform"`` (s in [0, 1], equal steps, toppra's usual choice) or ``"chord"`` (s = cumulative
            joint-space distance [rad], so ``|q'(s)|`` is about 1).
        start_tangent: ``q'(s_0)`` [rad]/[unit s], shape (n,), or None (not-a-knot end condition).
        end_tangent: ``q'(s_N)``, shape (n,), or None.
        bounds: ``(lower, upper)`` [rad], each shape (n,), or None: the path never leaves this box (see the module
            notes). Every waypoint must be inside it.
        derivatives: ``(q'(ss), q''(ss))``, each shape (N, n), of a C² cubic spline through the waypoints (e.g. a
            least-squares fit), used instead of interpolating; requires ``ss``.

    Raises:
        InvalidInputError: malformed waypoints, ``ss`` or tangents, or a waypoint outside ``bounds``.
    """

    def __init__(
        self,
        waypoints: npt.ArrayLike,
        ss: npt.ArrayLike | None = None,
        *,
        parametrisation: str = "uniform",
        start_tangent: npt.ArrayLike | None = None,
        end_tangent: npt.ArrayLike | None = None,
        bounds: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
        derivatives: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
    ) -> None:
        q = validate_waypoints(waypoints, repeats=ss is not None)
        n_points, dof = q.shape
        if ss is None:
            if parametrisation not in _PARAMETRISATIONS:
                raise InvalidInputError("parametrisation", parametrisation, f"one of {_PARAMETRISATIONS}")
            if parametrisation == "uniform":
                s = np.linspace(0.0, 1.0, n_points)
            else:
                s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0), axis=1))])
        else:
            s = as_vector(ss, "ss", n_points)
            if np.any(np.diff(s) <= 0.0):
                raise InvalidInputError("ss", s, "strictly increasing path parameters, one per waypoint")
        start = None if start_tangent is None else as_vector(start_tangent, "start_tangent", dof)
        end = None if end_tangent is None else as_vector(end_tangent, "end_tangent", dof)
        if start is None and end is None:
            bc: object = "not-a-knot" if n_points > 3 else "natural"
        else:
            bc = (
                (2, np.zeros(dof)) if start is None else (1, start),
                (2, np.zeros(dof)) if end is None else (1, end),
            )
        if derivatives is not None:
            if ss is None or not isinstance(derivatives, tuple | list) or len(derivatives) != 2:
                raise InvalidInputError("derivatives", type(derivatives).__name__, "(slopes, curvatures) with ss")
            given = (
                as_matrix(derivatives[0], "derivatives[0]", q.shape),
                as_matrix(derivatives[1], "derivatives[1]", q.shape),
            )
            spline: PPoly = CubicHermiteSpline(s, q, given[0])
        else:
            spline = CubicSpline(s, q, bc_type=bc)
        self.bounded = False
        if bounds is not None or derivatives is not None:
            lower, upper = _box(bounds, q) if bounds is not None else (np.full(dof, -np.inf), np.full(dof, np.inf))
            slope, curvature = (spline(s, 1), spline(s, 2)) if derivatives is None else given
            d, e = _inside_box_derivatives(s, q, slope, curvature, lower, upper)
            if not (np.array_equal(d, slope) and np.array_equal(e, curvature)):
                spline = PPoly(_quintic_hermite(s, q, d, e), s)
                self.bounded = True
        self._spline = spline
        self._derivatives = [self._spline.derivative(k) for k in (1, 2, 3)]
        self._ss = s
        self._q = q
        self._q.setflags(write=False)
        self._ss.setflags(write=False)

    def __call__(self, path_positions: npt.ArrayLike, order: int = 0) -> np.ndarray:
        """``q`` (order 0), ``q'`` (1), ``q''`` (2) or ``q'''`` (3) at ``path_positions``.

        Returns shape (n,) for a scalar, (m, n) for an array of m path positions.
        """
        if order == 0:
            return self._spline(path_positions)
        if order in (1, 2, 3):
            return self._derivatives[order - 1](path_positions)
        raise InvalidInputError("order", order, "0, 1, 2 or 3")

    def piece_coefficients(self) -> np.ndarray:
        """Polynomial pieces in ascending powers of ``s - ss[k]``, shape (N-1, d+1, n): d = 3 (cubic spline), or 5
        when ``bounds`` changed a knot's derivatives (quintic Hermite pieces)."""
        return np.transpose(self._spline.c[::-1], (1, 0, 2))

    def piece_index(self, s: npt.ArrayLike) -> np.ndarray:
        """Index of the cubic piece containing each path position (the last piece for ``s_end``)."""
        k = np.searchsorted(self._ss, np.asarray(s, dtype=float), side="right") - 1
        return np.clip(k, 0, len(self._ss) - 2)

    @property
    def dof(self) -> int:
        """Number of joints n."""
        return int(self._q.shape[1])

    @property
    def path_interval(self) -> np.ndarray:
        """``[s_start, s_end]``, shape (2,)."""
        return np.array([self._ss[0], self._ss[-1]])

    @property
    def waypoints(self) -> tuple[np.ndarray, np.ndarray]:
        """``(ss (N,), positions (N, n))``: the path parameters and joint positions [rad] of the waypoints."""
        return self._ss, self._q

    @property
    def ss_waypoints(self) -> np.ndarray:
        """Path parameter at the waypoints, shape (N,)."""
        return self._ss

    @property
    def positions(self) -> np.ndarray:
        """Waypoint positions [rad], shape (N, n)."""
        return self._q

    @property
    def degree(self) -> int:
        """Degree of the polynomial pieces (3 or 5)."""
        return int(self._spline.c.shape[0] - 1)

    def __repr__(self) -> str:
        return f"Path(waypoints={len(self._ss)}, dof={self.dof}, s=[{self._ss[0]:g}, {self._ss[-1]:g}])"


def _box(bounds: tuple[npt.ArrayLike, npt.ArrayLike], q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(bounds, tuple | list) or len(bounds) != 2:
        raise InvalidInputError("bounds", bounds, "(lower, upper), each of shape (n,)")
    lower = as_vector(bounds[0], "bounds[0]", q.shape[1])
    upper = as_vector(bounds[1], "bounds[1]", q.shape[1])
    outside = (q < lower) | (q > upper)
    if np.any(outside):
        k, j = np.argwhere(outside)[0]
        raise InvalidInputError(
            "waypoints", f"waypoint {k}, joint {j} = {q[k, j]:.9g} rad", f"inside [{lower[j]:.9g}, {upper[j]:.9g}]"
        )
    return lower, upper


def _inside_box_derivatives(
    s: np.ndarray, q: np.ndarray, slope: np.ndarray, curvature: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Knot derivatives (d, e), shape (N, n), clipped so that every quintic Hermite piece's Bernstein coefficients
    stay in [lower, upper] (module notes). Each interval holds 0, so clipping never empties it."""
    h = np.diff(s)[:, None]
    room_up, room_down = upper - q, q - lower  # >= 0
    d_hi = np.full(q.shape, np.inf)
    d_lo = np.full(q.shape, -np.inf)
    # as a piece's left knot: y + 2 d h/5 in the box; as its right knot: y - 2 d h/5 in the box
    d_hi[:-1] = np.minimum(d_hi[:-1], 2.5 * room_up[:-1] / h)
    d_lo[:-1] = np.maximum(d_lo[:-1], -2.5 * room_down[:-1] / h)
    d_hi[1:] = np.minimum(d_hi[1:], 2.5 * room_down[1:] / h)
    d_lo[1:] = np.maximum(d_lo[1:], -2.5 * room_up[1:] / h)
    d = np.clip(slope, d_lo, d_hi)
    e_hi = np.full(q.shape, np.inf)
    e_lo = np.full(q.shape, -np.inf)
    mid_right = q[:-1] + 0.4 * d[:-1] * h  # b2 without the curvature term
    mid_left = q[1:] - 0.4 * d[1:] * h  # b3 without the curvature term
    e_hi[:-1] = np.minimum(e_hi[:-1], 20.0 * (upper - mid_right) / h**2)
    e_lo[:-1] = np.maximum(e_lo[:-1], 20.0 * (lower - mid_right) / h**2)
    e_hi[1:] = np.minimum(e_hi[1:], 20.0 * (upper - mid_left) / h**2)
    e_lo[1:] = np.maximum(e_lo[1:], 20.0 * (lower - mid_left) / h**2)
    e = np.clip(curvature, e_lo, np.maximum(e_hi, e_lo))
    return d, e


def _quintic_hermite(s: np.ndarray, q: np.ndarray, d: np.ndarray, e: np.ndarray) -> np.ndarray:
    """PPoly coefficients (6, N-1, n), descending powers, of the quintics matching (q, d, e) at both knots."""
    h = np.diff(s)[:, None]
    y0, y1, d0, d1, e0, e1 = q[:-1], q[1:], d[:-1], d[1:], e[:-1], e[1:]
    # the three top coefficients solve the end conditions at x = h (closed form of the 3x3 Hermite system)
    r0 = y1 - (y0 + d0 * h + 0.5 * e0 * h**2)
    r1 = d1 - (d0 + e0 * h)
    r2 = e1 - e0
    c3 = (20 * r0 - 8 * r1 * h + r2 * h**2) / (2 * h**3)
    c4 = (-15 * r0 + 7 * r1 * h - r2 * h**2) / h**4
    c5 = (12 * r0 - 6 * r1 * h + r2 * h**2) / (2 * h**5)
    return np.stack([c5, c4, c3, 0.5 * e0, d0, y0])
