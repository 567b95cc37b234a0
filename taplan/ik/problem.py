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

When ``H`` is positive definite and its unconstrained minimiser already satisfies the box and the rows, it is the
QP's optimum and no solver is called (:func:`solve_problem`; exact, not an approximation). In tracking this is
most steps.

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
from taplan.ik.limits.limit import BoxLimit, RowLimit, StepContext, intersect_stacked
from taplan.ik.tasks.task import Task

if TYPE_CHECKING:
    from taplan.ik.solvers import QPSolver

__all__ = ["Problem", "ProblemBuilder", "build_ik", "solve_ik", "solve_problem", "SLACK_LINEAR", "SLACK_QUADRATIC"]

SLACK_LINEAR = 1e4  # penalty per [m/s] of violation of a soft row
SLACK_QUADRATIC = 1e2  # quadratic penalty per [m/s]²


_SIGN = np.array([[1.0], [-1.0]])


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
        v_free: Minimiser of the objective before the box limits' scaling (``objective_scale``) [rad/s] (nv,).
        layers: ``(name, stacked)`` of each box limit in the order applied, ``stacked`` (2, nv) being
            ``[upper, -lower]`` (for ``relaxations``).
        slack_linear: Linear slack penalty.
        slack_quadratic: Quadratic slack penalty.
        minimiser: Exact unconstrained minimiser ``-H⁻¹ c`` of this objective [rad/s] (nv,) (valid if
            ``minimiser_exact``).
        minimiser_exact: Whether ``H`` was positive definite, so that ``minimiser`` is the unique minimiser.
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
    layers: list[tuple[str, np.ndarray]] = field(default_factory=list)
    slack_linear: float = SLACK_LINEAR
    slack_quadratic: float = SLACK_QUADRATIC
    minimiser: np.ndarray | None = None
    minimiser_exact: bool = False
    _inside: np.ndarray | None = field(default=None, repr=False, compare=False)  # scratch of minimiser_is_feasible

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
        box = np.full((2, self.nv), np.inf)
        scratch = np.empty_like(box)
        out = {}
        for name, new in self.layers:
            out[name] = (new[0] < -box[1]) | (new[1] < -box[0])  # new upper < lower or new lower > upper
            intersect_stacked(box, new, scratch)
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
            [(n, s.copy()) for n, s in self.layers],
            self.slack_linear,
            self.slack_quadratic,
            None if self.minimiser is None else self.minimiser.copy(),
            self.minimiser_exact,
        )

    def minimiser_is_feasible(self) -> bool:
        """Whether the exact unconstrained minimiser satisfies the box and every row (it is then the QP optimum)."""
        x = self.minimiser
        if not self.minimiser_exact or x is None:
            return False
        inside = self._inside
        if inside is None or inside.shape[1] != x.shape[0]:
            inside = self._inside = np.empty((2, x.shape[0]), dtype=bool)
        np.less_equal(x, self.upper, out=inside[0])  # NaN fails both tests
        np.greater_equal(x, self.lower, out=inside[1])
        if np.count_nonzero(inside) != inside.size:
            return False
        return self.n_rows == 0 or bool((self.G @ x <= self.h).all())


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
        self.kin = kin
        self.tasks = list(tasks)
        self.box_limits = sorted((lim for lim in limits if isinstance(lim, BoxLimit)), key=lambda lim: lim.priority)
        self.row_limits = [lim for lim in limits if isinstance(lim, RowLimit)]
        unknown = [lim for lim in limits if not isinstance(lim, BoxLimit | RowLimit)]
        if unknown:
            raise InvalidInputError("limits", unknown, "BoxLimit or RowLimit instances")
        n = kin.nv
        rows = sum(t.rows for t in self.tasks)
        self._A = np.zeros((rows, n))
        self._AT = self._A.T
        self._b = np.zeros(rows)
        self._b_ff = np.zeros(rows)
        self._views = []
        self._ff_views = []  # tasks that can follow a moving target (see ``Task.feedforward``)
        start = 0
        for t in self.tasks:
            rows_t = slice(start, start + t.rows)
            self._views.append((t.fill, self._A[rows_t], self._b[rows_t]))
            if hasattr(t, "feedforward"):
                self._ff_views.append((t.feedforward, self._b_ff[rows_t], self._b[rows_t]))
            start += t.rows
        self._H = np.zeros((n, n))
        self._c = np.zeros(n)
        self._box = np.full((2, n), np.inf)
        self._scratch = np.empty((2, n))
        self._upper = self._box[0]
        self._lower = np.full(n, -np.inf)
        self._v_prev = np.zeros(n)
        self._v_free = np.zeros(n)
        self._minimiser = np.zeros(n)
        self._v_ff = np.zeros(n)
        self._c_ff = np.zeros(n)
        self._rhs = np.zeros((n, 2), order="F")
        max_rows = sum(lim.max_rows for lim in self.row_limits)
        self._G = np.zeros((max_rows, n))
        self._h = np.zeros(max_rows)
        self._ctx = StepContext(kin, 0.01, self._v_prev, self._v_free, self._v_ff)
        self.damping = damping
        self.problem = Problem(
            self._H,
            self._c,
            self._lower,
            self._upper,
            self._G[:0],
            self._h[:0],
            0.01,
            self._v_prev,
            self._v_free,
            minimiser=self._minimiser,
        )

    @property
    def damping(self) -> float:
        """Levenberg-Marquardt damping ``λ`` on the Hessian's diagonal."""
        return self._damping

    @damping.setter
    def damping(self, value: float) -> None:
        self._damping = check_damping(value)
        self._damping_matrix = self._damping * np.eye(self.kin.nv)

    def build(self, q: np.ndarray, dt: float, v_prev: np.ndarray | None = None) -> Problem:
        """Update kinematics at ``q`` [rad] and fill the problem for a step of ``dt`` [s] (inputs not validated)."""
        kin = self.kin
        kin.update(q)
        for fill, A, b in self._views:
            fill(kin, A, b)
        moving = False
        for feedforward, b_ff, b in self._ff_views:
            code = feedforward(dt, b_ff)
            if code:
                moving = True
                if code == 2:  # explicit target velocity: the step aims at where the target will be
                    b += b_ff * dt
        H, c = self._H, self._c
        np.matmul(self._AT, self._A, out=H)
        if self._damping:
            H += self._damping_matrix
        np.matmul(self._AT, self._b, out=c)
        c *= -1.0 / dt
        if v_prev is None:
            self._v_prev.fill(0.0)
        else:
            self._v_prev[:] = v_prev
        ctx = self._ctx
        ctx.dt = dt
        problem = self.problem
        ctx.moving = moving
        if moving:  # the target-following velocity v_ff = -H⁻¹ c_ff with c_ff = -Aᵀ b_ff, same factorisation
            c_ff = self._c_ff
            np.matmul(self._AT, self._b_ff, out=c_ff)
            np.negative(c_ff, out=c_ff)
            problem.minimiser_exact = _free_velocities(H, c, c_ff, self._rhs, self._v_free, self._v_ff)
        else:
            problem.minimiser_exact = _free_velocity(H, c, self._v_free)
        box = self._box
        layers = problem.layers
        layers.clear()
        scale = 1.0
        first = True
        for lim in self.box_limits:
            new = lim.stacked(ctx)
            if first:
                np.copyto(box, new)
                first = False
            else:
                intersect_stacked(box, new, self._scratch)
            layers.append((lim.name, new))
            scale *= lim.objective_scale
        np.negative(box[1], out=self._lower)
        if scale != 1.0 and moving:  # scale the part relative to the target's motion: v_ff + κ (v_free - v_ff)
            c -= self._c_ff
            c *= scale
            c += self._c_ff
            np.subtract(self._v_free, self._v_ff, out=self._minimiser)
            self._minimiser *= scale
            self._minimiser += self._v_ff
        elif scale != 1.0:
            c *= scale
            np.multiply(self._v_free, scale, out=self._minimiser)
        else:
            self._minimiser[:] = self._v_free
        k = 0
        for lim in self.row_limits:
            k += lim.rows(ctx, self._G[k:], self._h[k:])
        problem.dt = dt
        if problem.h.shape[0] != k:
            problem.G = self._G[:k]
            problem.h = self._h[:k]
        return problem


def check_damping(value: float) -> float:
    """Validate a Levenberg-Marquardt damping (a finite number >= 0)."""
    if not (np.isfinite(value) and value >= 0.0):
        raise InvalidInputError("damping", value, "a number >= 0")
    return float(value)


def _free_velocity(H: np.ndarray, c: np.ndarray, out: np.ndarray) -> bool:
    """Unconstrained minimiser ``-H⁻¹ c`` into ``out`` (least squares if H is singular); True if H is definite."""
    _, x, info = _dposv(H.T, c)  # H is symmetric: its transpose is the Fortran-ordered view LAPACK wants (no copy)
    if info == 0:
        np.negative(x, out=out)
        return True
    out[:] = np.linalg.lstsq(H, c, rcond=None)[0]  # not positive definite: least squares
    np.negative(out, out=out)
    if not np.all(np.isfinite(out)):
        out[:] = 0.0
    return False


def _free_velocities(
    H: np.ndarray, c: np.ndarray, c_ff: np.ndarray, rhs: np.ndarray, out: np.ndarray, out_ff: np.ndarray
) -> bool:
    """:func:`_free_velocity` for two linear terms at once (``c`` into ``out``, ``c_ff`` into ``out_ff``)."""
    rhs[:, 0] = c
    rhs[:, 1] = c_ff
    _, x, info = _dposv(H.T, rhs)
    if info == 0:
        np.negative(x[:, 0], out=out)
        np.negative(x[:, 1], out=out_ff)
        return True
    _free_velocity(H, c_ff, out_ff)
    return _free_velocity(H, c, out)


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
    return solve_problem(problem, backend).copy()


def solve_problem(problem: Problem, backend: QPSolver) -> np.ndarray:
    """Solve with ``backend``, skipping it when the unconstrained minimiser is already feasible.

    When ``H`` is positive definite and its unconstrained minimiser satisfies the box and every row, that
    minimiser *is* the QP's optimum (zero slack, the objective's global minimum), so backends that allow it
    (``backend.exact_shortcut``) are not called. Returns the velocity [rad/s] (nv,) projected onto the box (a
    buffer of the problem or backend: copy to keep).
    """
    if backend.exact_shortcut and problem.minimiser_is_feasible():
        backend.iterations = 0
        return problem.minimiser
    return project(problem, backend.solve(problem))


def project(problem: Problem, v: np.ndarray) -> np.ndarray:
    """Project ``v`` onto the problem's box in place and check it is finite; returns ``v``."""
    np.maximum(v, problem.lower, out=v)
    np.minimum(v, problem.upper, out=v)
    if not np.isfinite(v).all():
        raise SolverError("the QP solution is not finite", problem.copy())
    return v
