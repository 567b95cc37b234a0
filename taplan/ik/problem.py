"""Assemble the differential-IK QP in one readable place (``build_ik``) and solve it (``solve_ik``).

Decision variable: the joint velocity ``v`` [rad/s] (nv,), applied for ``dt``: ``Δq = v dt``. Tasks contribute
rows ``A Δq ≈ b``; dividing the objective by ``dt²`` gives a problem in ``v`` whose numbers do not shrink with
``dt``:

.. math::

    \\min_v \\tfrac12 v^T H v + c^T v, \\quad H = A^T A + \\lambda I, \\quad c = -A^T b / dt

subject to the velocity box ``lower <= v <= upper`` (all box limits, intersected in priority order without ever
becoming empty, see :mod:`taplan.ik.limits.limit`) and soft rows ``G v - s <= h``, ``s >= 0``, each slack ``s``
penalised by ``slack_linear s + slack_quadratic s² / 2`` (an exact penalty: zero whenever the rows are feasible
together with the box and their multipliers stay below ``slack_linear``).

The box is hard: after the solver returns, ``v`` is projected onto it (a no-op up to the solver's tolerance), so
solver tolerances can never breach the acceleration bound ``a dt`` however small ``dt`` is.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from scipy.linalg.lapack import dposv as _dposv

from taplan.errors import InvalidInputError, SolverError
from taplan.ik._kinematics import Kinematics
from taplan.ik.limits.limit import BoxLimit, RowLimit, StepContext, intersect_relaxed
from taplan.ik.tasks.task import Task

if TYPE_CHECKING:
    from taplan.ik.solvers import QPSolver

__all__ = ["Problem", "ProblemBuilder", "build_ik", "solve_ik", "SLACK_LINEAR", "SLACK_QUADRATIC"]

SLACK_LINEAR = 1e4  # penalty per [m/s] of violation of a soft row
SLACK_QUADRATIC = 1e2  # quadratic penalty per [m/s]²


@dataclass
class Problem:
    """One differential-IK QP in velocity [rad/s] (see the module docstring for the formulation).

    The arrays are the builder's buffers: a stepper overwrites them at its next step (copy to keep).

    Attributes:
        H: Hessian (nv, nv).
        c: Linear term (nv,).
        lower: Velocity lower bounds [rad/s] (nv,).
        upper: Velocity upper bounds [rad/s] (nv,).
        G: Soft inequality rows (m, nv), ``G v <= h`` up to slack.
        h: Right-hand sides (m,) [m/s].
        dt: Step duration [s].
        v_prev: Previous commanded velocity [rad/s] (nv,).
        v_free: Minimiser without constraints [rad/s] (nv,).
        layers: ``(name, lower, upper)`` of each box limit in the order applied (for ``relaxations``).
        slack_linear: Linear slack penalty.
        slack_quadratic: Quadratic slack penalty.
    """

    H: np.ndarray
    c: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    G: np.ndarray
    h: np.ndarray
    dt: float
    v_prev: np.ndarray
    v_free: np.ndarray
    layers: list[tuple[str, np.ndarray, np.ndarray]] = field(default_factory=list)
    slack_linear: float = SLACK_LINEAR
    slack_quadratic: float = SLACK_QUADRATIC

    @property
    def nv(self) -> int:
        """Number of velocity variables."""
        return int(self.c.shape[0])

    @property
    def n_rows(self) -> int:
        """Number of soft inequality rows."""
        return int(self.h.shape[0])

    def relaxations(self) -> dict[str, np.ndarray]:
        """Per box limit, which joints had that bound relaxed (bool (nv,)), replaying the intersection."""
        lo = np.full(self.nv, -np.inf)
        hi = np.full(self.nv, np.inf)
        scratch = np.empty(self.nv)
        out = {}
        for name, new_lo, new_hi in self.layers:
            out[name] = (new_lo > hi) | (new_hi < lo)
            intersect_relaxed(lo, hi, new_lo, new_hi, scratch)
        return out

    def objective(self, v: npt.ArrayLike) -> float:
        """Objective value ``½ vᵀHv + cᵀv`` (without slack) at ``v`` [rad/s]."""
        v = np.asarray(v, dtype=float)
        return float(0.5 * v @ self.H @ v + self.c @ v)

    def copy(self) -> Problem:
        """A deep copy (safe to keep across steps)."""
        return Problem(
            self.H.copy(),
            self.c.copy(),
            self.lower.copy(),
            self.upper.copy(),
            self.G.copy(),
            self.h.copy(),
            self.dt,
            self.v_prev.copy(),
            self.v_free.copy(),
            [(n, lo.copy(), hi.copy()) for n, lo, hi in self.layers],
            self.slack_linear,
            self.slack_quadratic,
        )


class ProblemBuilder:
    """Builds :class:`Problem` s for fixed tasks and limits into pre-allocated buffers (the stepper's hot path).

    Args:
        kin: Kinematics (updated by ``build``).
        tasks: Objective terms.
        limits: Box limits (applied by ``priority``) and row limits.
        damping: Levenberg-Marquardt damping ``λ`` added to the Hessian's diagonal, >= 0.
    """

    def __init__(
        self,
        kin: Kinematics,
        tasks: Sequence[Task],
        limits: Sequence[BoxLimit | RowLimit] = (),
        damping: float = 1e-12,
    ) -> None:
        if not (np.isfinite(damping) and damping >= 0.0):
            raise InvalidInputError("damping", damping, "a number >= 0")
        self.kin = kin
        self.tasks = list(tasks)
        self.box_limits = sorted((lim for lim in limits if isinstance(lim, BoxLimit)), key=lambda lim: lim.priority)
        self.row_limits = [lim for lim in limits if isinstance(lim, RowLimit)]
        unknown = [lim for lim in limits if not isinstance(lim, BoxLimit | RowLimit)]
        if unknown:
            raise InvalidInputError("limits", unknown, "BoxLimit or RowLimit instances")
        n = kin.nv
        self.damping = float(damping)
        rows = sum(t.rows for t in self.tasks)
        self._A = np.zeros((rows, n))
        self._b = np.zeros(rows)
        self._views = []
        start = 0
        for t in self.tasks:
            self._views.append((t, self._A[start : start + t.rows], self._b[start : start + t.rows]))
            start += t.rows
        self._H = np.zeros((n, n))
        self._c = np.zeros(n)
        self._diag = np.arange(n) * (n + 1)
        self._lower = np.empty(n)
        self._upper = np.empty(n)
        self._scratch = np.empty(n)
        self._v_prev = np.zeros(n)
        self._v_free = np.zeros(n)
        max_rows = sum(lim.max_rows for lim in self.row_limits)
        self._G = np.zeros((max_rows, n))
        self._h = np.zeros(max_rows)
        self._needs_free = any(lim.needs_free_velocity for lim in self.box_limits)
        self._ctx = StepContext(kin, 0.01, self._v_prev, self._v_free)
        self.problem = Problem(
            self._H, self._c, self._lower, self._upper, self._G[:0], self._h[:0], 0.01, self._v_prev, self._v_free
        )

    def build(self, q: np.ndarray, dt: float, v_prev: np.ndarray | None = None) -> Problem:
        """Update kinematics at ``q`` [rad] and fill the problem for a step of ``dt`` [s] (inputs not validated)."""
        kin = self.kin
        kin.update(q)
        for task, A, b in self._views:
            task.fill(kin, A, b)
        H, c = self._H, self._c
        np.matmul(self._A.T, self._A, out=H)
        if self.damping:
            H.flat[self._diag] += self.damping
        np.matmul(self._A.T, self._b, out=c)
        c *= -1.0 / dt
        if v_prev is None:
            self._v_prev[:] = 0.0
        else:
            self._v_prev[:] = v_prev
        ctx = self._ctx
        ctx.dt = dt
        if self._needs_free:
            _free_velocity(H, c, self._v_free)
        lower, upper = self._lower, self._upper
        lower.fill(-np.inf)
        upper.fill(np.inf)
        layers = self.problem.layers
        layers.clear()
        scale = 1.0
        for lim in self.box_limits:
            lo, hi = lim.bounds(ctx)
            intersect_relaxed(lower, upper, lo, hi, self._scratch)
            layers.append((lim.name, lo, hi))
            scale *= lim.objective_scale
        if scale != 1.0:
            c *= scale
        k = 0
        for lim in self.row_limits:
            k += lim.rows(ctx, self._G[k:], self._h[k:])
        problem = self.problem
        problem.dt = dt
        if problem.h.shape[0] != k:
            problem.G = self._G[:k]
            problem.h = self._h[:k]
        return problem


def _free_velocity(H: np.ndarray, c: np.ndarray, out: np.ndarray) -> None:
    """Unconstrained minimiser ``-H⁻¹ c`` (least squares if H is singular)."""
    _, x, info = _dposv(H, c, lower=0, overwrite_a=0, overwrite_b=0)
    if info == 0:
        np.negative(x, out=out)
    else:  # not positive definite: least squares
        out[:] = np.linalg.lstsq(H, c, rcond=None)[0]
        np.negative(out, out=out)
    if not np.all(np.isfinite(out)):
        out[:] = 0.0


def build_ik(
    kin: Kinematics,
    q: npt.ArrayLike,
    tasks: Sequence[Task],
    limits: Sequence[BoxLimit | RowLimit] = (),
    dt: float = 0.01,
    v_prev: npt.ArrayLike | None = None,
    damping: float = 1e-12,
) -> Problem:
    """Build one IK problem (a fresh copy; for loops use :class:`ProblemBuilder` or ``DifferentialIK``).

    Args:
        kin: Kinematics of the robot (e.g. ``Kinematics(robot.model)``).
        q: Configuration [rad], shape (nv,).
        tasks: Objective terms.
        limits: Box and row limits.
        dt: Step duration [s], > 0.
        v_prev: Previous commanded velocity [rad/s] (nv,), default zero (for the acceleration limit).
        damping: Levenberg-Marquardt damping added to the Hessian diagonal.

    Returns:
        The problem (its arrays are not shared with anything else).
    """
    from taplan._validation import as_positive, as_vector

    dt = as_positive(dt, "dt")
    q = as_vector(q, "q", kin.nv)
    v_prev = None if v_prev is None else as_vector(v_prev, "v_prev", kin.nv)
    return ProblemBuilder(kin, tasks, limits, damping).build(q, dt, v_prev).copy()


def solve_ik(problem: Problem, solver: str | QPSolver = "proxqp") -> np.ndarray:
    """Solve ``problem`` and return the velocity [rad/s] (nv,), projected onto the velocity box.

    Args:
        problem: From :func:`build_ik` or a builder.
        solver: A backend name (``taplan.ik.available_solvers()``) or a :class:`~taplan.ik.solvers.QPSolver`.

    Raises:
        SolverError: the backend failed or returned a non-finite solution (``error.problem`` is a copy of the
            problem).
        UnknownNameError: unknown backend name.
    """
    from taplan.ik.solvers import get_solver

    backend = get_solver(solver) if isinstance(solver, str) else solver
    v = backend.solve(problem)
    return project(problem, v)


def project(problem: Problem, v: np.ndarray) -> np.ndarray:
    """Project ``v`` onto the problem's box in place and check it is finite; returns ``v``."""
    np.maximum(v, problem.lower, out=v)
    np.minimum(v, problem.upper, out=v)
    if not np.isfinite(v).all():
        raise SolverError("the QP solution is not finite", problem.copy())
    return v
