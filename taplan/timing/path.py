"""A geometric path through joint waypoints: ``path(s, order)`` like toppra's interface.

The path is a C² cubic spline ``q(s)`` through the waypoints, with the path parameter ``s`` at the waypoints either
uniform (``0, 1, ..., N-1`` scaled to [0, 1], toppra's usual choice) or proportional to the cumulative joint-space
chord length. It derives from :class:`toppra.interpolator.AbstractGeometricPath`, so toppra accepts it directly.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.interpolate import CubicSpline
from toppra.interpolator import AbstractGeometricPath

from taplan._validation import as_matrix, as_vector
from taplan.errors import InvalidInputError

__all__ = ["Path", "validate_waypoints", "DUPLICATE_TOL"]

DUPLICATE_TOL = 1e-9  # [rad]: consecutive waypoints closer than this (max-norm) are duplicates

_PARAMETRISATIONS = ("uniform", "chord")


def validate_waypoints(waypoints: npt.ArrayLike, name: str = "waypoints", size: int | None = None) -> np.ndarray:
    """Return ``waypoints`` as a finite (N, n) array with N >= 2 and no duplicate consecutive rows, or raise.

    Args:
        waypoints: Joint positions [rad], shape (N, n).
        name: Argument name used in error messages.
        size: Required n, or None.
    """
    q = as_matrix(waypoints, name, (None, size))
    if q.shape[0] < 2:
        raise InvalidInputError(name, f"{q.shape[0]} waypoint(s)", "at least 2 waypoints")
    if q.shape[1] < 1:
        raise InvalidInputError(name, f"shape {q.shape}", "at least one joint")
    step = np.max(np.abs(np.diff(q, axis=0)), axis=1)
    if np.any(step <= DUPLICATE_TOL):
        k = int(np.argmax(step <= DUPLICATE_TOL))
        raise InvalidInputError(
            name, f"waypoints {k} and {k + 1} are equal", f"consecutive waypoints that differ by > {DUPLICATE_TOL} rad"
        )
    return q


class Path(AbstractGeometricPath):
    """Cubic-spline joint path ``q(s)`` through waypoints.

    Args:
        waypoints: Joint positions [rad], shape (N, n), N >= 2, no two consecutive equal.
        ss: Path parameter at the waypoints, strictly increasing, shape (N,); overrides ``parametrisation``.
        parametrisation: ``"uniform"`` (s in [0, 1], equal steps, toppra's usual choice) or ``"chord"`` (s = cumulative
            joint-space distance [rad], so ``|q'(s)|`` is about 1).
        start_tangent: ``q'(s_0)`` [rad]/[unit s], shape (n,), or None (not-a-knot end condition).
        end_tangent: ``q'(s_N)``, shape (n,), or None.
    """

    def __init__(
        self,
        waypoints: npt.ArrayLike,
        ss: npt.ArrayLike | None = None,
        *,
        parametrisation: str = "uniform",
        start_tangent: npt.ArrayLike | None = None,
        end_tangent: npt.ArrayLike | None = None,
    ) -> None:
        q = validate_waypoints(waypoints)
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
        self._spline = CubicSpline(s, q, bc_type=bc)
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
        """Cubic pieces in ascending powers of ``s - ss[k]``, shape (N-1, 4, n)."""
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

    def __repr__(self) -> str:
        return f"Path(waypoints={len(self._ss)}, dof={self.dof}, s=[{self._ss[0]:g}, {self._ss[-1]:g}])"
