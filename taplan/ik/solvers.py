"""QP backends: a persistent, warm-started proxsuite dense QP (default) and the others through qpsolvers.

Every backend solves the :class:`~taplan.ik.problem.Problem` formulation: variables ``[v, s]`` (velocity
[rad/s] and one slack per soft row), box bounds on ``v`` as variable bounds, soft rows ``G v - s <= h``, ``s >= 0``.
A failure raises :class:`taplan.errors.SolverError` with a copy of the problem attached; nothing returns ``None``.

proxqp stays the default. The stepper skips the backend whenever the unconstrained minimiser is feasible (exact; see
:func:`taplan.ik.problem.solve_problem`), which in tracking is almost every step (the circle-tracking benchmark at
dt 0.01 s solves a QP on about 2 % of the steps), so the backend barely moves the median step time. When a QP is
solved, ``"daqp"`` (called directly, :class:`DAQPSolver`) was the cheapest here: about 8 µs for a 14-variable box
QP with 11 active bounds against 14 µs for a warm-started proxqp (same machine, same problem).
"""

from __future__ import annotations

import abc
from typing import Any

import numpy as np

from taplan._osqp import polish_setting
from taplan.errors import SolverError, UnknownNameError
from taplan.ik.problem import Problem

__all__ = ["QPSolver", "ProxQPSolver", "DAQPSolver", "QPSolversSolver", "get_solver", "available_solvers", "SOLVERS"]

SOLVERS = ("proxqp", "daqp", "quadprog", "osqp")
_BIG = 1e20  # proxqp's and our stand-in for an infinite bound


def available_solvers() -> list[str]:
    """Backends usable here (installed), in taplan's order of preference."""
    import qpsolvers

    installed = set(qpsolvers.available_solvers)
    out = []
    for name in SOLVERS:
        if name == "proxqp":
            try:
                import proxsuite  # noqa: F401
            except ImportError:
                continue
            out.append(name)
        elif name in installed:
            out.append(name)
    return out


def get_solver(name: str, **options: Any) -> QPSolver:
    """A new backend by name: ``"proxqp"`` (persistent dense QP), ``"daqp"``, ``"quadprog"`` or ``"osqp"``.

    Raises:
        UnknownNameError: an unknown or uninstalled backend (the message lists the installed ones).
    """
    valid = available_solvers()
    if name not in valid:
        raise UnknownNameError("QP solver", name, valid)
    if name == "proxqp":
        return ProxQPSolver(**options)
    if name == "daqp":
        return DAQPSolver(**options)
    return QPSolversSolver(name, **options)


class QPSolver(abc.ABC):
    """A QP backend. ``solve`` returns the velocity part of the solution (nv,) [rad/s] (a buffer it re-uses).

    Attributes:
        name: Backend name.
        iterations: Iterations of the last solve (0 if not reported or not called).
        exact_shortcut: Whether callers may skip ``solve`` when the problem's unconstrained minimiser is feasible
            (it is then the exact optimum; :func:`taplan.ik.problem.solve_problem`). False by default so that a
            custom backend sees every problem; True for the built-in backends.
    """

    name: str
    iterations: int = 0
    exact_shortcut: bool = False

    @abc.abstractmethod
    def solve(self, problem: Problem) -> np.ndarray:
        """Solve; raise ``SolverError`` (with ``problem.copy()``) on failure."""

    def reset(self) -> None:  # noqa: B027 - optional hook
        """Forget warm-start data."""


class _ProxQPWorkspace:
    """One proxsuite dense QP of fixed size and its input buffers."""

    def __init__(self, n: int, m: int, eps_abs: float, max_iter: int) -> None:
        from proxsuite import proxqp

        self.n, self.m = n, m
        self.eps_abs, self.max_iter = eps_abs, max_iter
        self.qp = self._new_qp()
        self.solved = proxqp.QPSolverOutput.PROXQP_SOLVED
        self.H = np.zeros((n + m, n + m))
        self.g = np.zeros(n + m)
        self.lo = np.zeros(n + m)
        self.hi = np.full(n + m, _BIG)
        self.C = np.zeros((m, n + m))
        self.lower_rows = np.full(m, -_BIG)
        self.out = np.zeros(n)
        if m:
            self.C[:, n:] = -np.eye(m)
        self.initialised = False

    def _new_qp(self) -> Any:
        from proxsuite import proxqp

        qp = proxqp.dense.QP(self.n + self.m, 0, self.m, True)
        s = qp.settings
        s.eps_abs = self.eps_abs
        s.eps_rel = 0.0
        s.max_iter = self.max_iter
        s.compute_timings = False
        s.initial_guess = proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
        return qp

    def solve(self, problem: Problem) -> np.ndarray:
        n, m = self.n, self.m
        lo, hi = self.lo, self.hi
        np.maximum(problem.lower, -_BIG, out=lo[:n])
        np.minimum(problem.upper, _BIG, out=hi[:n])
        qp = self.qp
        if m == 0:
            H, g, C, u, low = problem.H, problem.c, None, None, None
        else:
            H, g, C = self.H, self.g, self.C
            H[:n, :n] = problem.H
            H[n:, n:] = problem.slack_quadratic * np.eye(m)
            g[:n] = problem.c
            g[n:] = problem.slack_linear
            C[:, :n] = problem.G
            u, low = problem.h, self.lower_rows
        if self.initialised:
            qp.update(H=H, g=g, C=C, l=low, u=u, l_box=lo, u_box=hi)
        else:
            qp.init(H, g, None, None, C, low, u, lo, hi)
            self.initialised = True
        qp.solve()
        results = qp.results
        if results.info.status != self.solved:  # a stale warm start can mislead it: retry once from scratch
            self.qp = qp = self._new_qp()
            qp.init(H, g, None, None, C, low, u, lo, hi)
            qp.solve()
            results = qp.results
            if results.info.status != self.solved:
                self.initialised = False
                raise SolverError(f"proxqp failed: {results.info.status}", problem.copy())
        self.out[:] = results.x[:n]
        self.iterations = int(results.info.iter)
        return self.out


class ProxQPSolver(QPSolver):
    """proxsuite's dense ProxQP, one persistent QP object per problem size, warm-started from the last result.

    If proxqp fails twice on a problem (warm, then cold), that problem is solved by :class:`DAQPSolver` instead
    (counted in ``fallbacks``); a failure of both raises ``SolverError``.

    Args:
        eps_abs: Absolute tolerance on the KKT residuals (velocity units [rad/s]; the box is enforced exactly
            afterwards by projection).
        max_iter: Iteration limit.
    """

    name = "proxqp"
    exact_shortcut = True

    def __init__(self, eps_abs: float = 1e-9, max_iter: int = 1000) -> None:
        self.eps_abs = float(eps_abs)
        self.max_iter = int(max_iter)
        self._workspaces: dict[tuple[int, int], _ProxQPWorkspace] = {}
        self._fallback: QPSolver | None = None
        self.fallbacks = 0  # solves handed to DAQP after proxqp failed

    def solve(self, problem: Problem) -> np.ndarray:
        key = (problem.nv, problem.n_rows)
        ws = self._workspaces.get(key)
        if ws is None:
            ws = self._workspaces[key] = _ProxQPWorkspace(key[0], key[1], self.eps_abs, self.max_iter)
        try:
            out = ws.solve(problem)
        except SolverError as error:
            # The problem is feasible by construction (non-empty box, soft rows), so a failure here is numerical
            # (e.g. proxqp's infeasibility detection misfiring on a badly scaled step): fall back to DAQP once.
            if self._fallback is None:
                try:
                    self._fallback = DAQPSolver()
                except ImportError:
                    raise error from None
            out = self._fallback.solve(problem)
            self.fallbacks += 1
            self.iterations = self._fallback.iterations
            return out
        self.iterations = ws.iterations
        return out

    def reset(self) -> None:
        self._workspaces.clear()


class DAQPSolver(QPSolver):
    """DAQP (dual active set) called directly, with buffers re-used between calls.

    For this problem (14 variables, a box and a few soft rows) the dual active-set method needs no tolerance on the
    box (active bounds hold exactly) and is the cheapest of the backends. Warm start: the previous solution's
    active set (``primal_start``) when ``warm_start`` is True.

    Args:
        warm_start: Start from the previous solution's active set.
        **settings: DAQP settings (``primal_tol``, ``dual_tol``, ``iter_limit``, ...).
    """

    name = "daqp"
    exact_shortcut = True
    _INF = 1e30  # DAQP's infinity

    def __init__(self, warm_start: bool = False, **settings: Any) -> None:
        import daqp

        self._solve = daqp.solve
        self.warm_start = bool(warm_start)
        self.settings = dict(settings)
        self._buffers: dict[tuple[int, int], tuple[np.ndarray, ...]] = {}
        self._last: dict[tuple[int, int], np.ndarray] = {}

    def _workspace(self, n: int, m: int) -> tuple[np.ndarray, ...]:
        from ctypes import c_int

        ws = self._buffers.get((n, m))
        if ws is None:
            H = np.zeros((n + m, n + m))
            f = np.zeros(n + m)
            A = np.zeros((m, n + m))
            if m:
                A[:, n:] = -np.eye(m)
            upper = np.full(n + 2 * m, self._INF)
            lower = np.full(n + 2 * m, -self._INF)
            lower[n : n + m] = 0.0  # slacks >= 0
            sense = np.zeros(n + 2 * m, dtype=c_int)
            ws = self._buffers[(n, m)] = (H, f, A, upper, lower, sense)
        return ws

    def solve(self, problem: Problem) -> np.ndarray:
        n, m = problem.nv, problem.n_rows
        H, f, A, upper, lower, sense = self._workspace(n, m)
        np.minimum(problem.upper, self._INF, out=upper[:n])
        np.maximum(problem.lower, -self._INF, out=lower[:n])
        if m == 0:
            H, f = problem.H, problem.c
        else:
            H[:n, :n] = problem.H
            H.flat[(n + m + 1) * n :: n + m + 1] = problem.slack_quadratic
            f[:n] = problem.c
            f[n:] = problem.slack_linear
            A[:, :n] = problem.G
            upper[n + m :] = problem.h
        start = self._last.get((n, m)) if self.warm_start else None
        try:
            if start is None:
                x, _, flag, info = self._solve(H, f, A, upper, lower, sense, **self.settings)
            else:
                x, _, flag, info = self._solve(H, f, A, upper, lower, sense, primal_start=start, **self.settings)
        except Exception as exc:  # the extension raises its own types
            raise SolverError(f"daqp failed: {exc}", problem.copy()) from exc
        if flag < 1:
            raise SolverError(f"daqp failed: exit flag {flag}", problem.copy())
        if self.warm_start:
            self._last[(n, m)] = x
        self.iterations = int(info.get("iterations", 0))
        return x[:n]

    def reset(self) -> None:
        self._last.clear()


class QPSolversSolver(QPSolver):
    """Any qpsolvers backend (``daqp``, ``quadprog``, ``osqp``, ...); no state between calls.

    Args:
        name: qpsolvers backend name.
        **options: Passed to the backend (e.g. ``eps_abs`` for osqp).
    """

    exact_shortcut = True

    def __init__(self, name: str, **options: Any) -> None:
        self.name = name
        osqp = {"eps_abs": 1e-9, "eps_rel": 0.0, "max_iter": 20000, polish_setting(): True}
        defaults: dict[str, Any] = {"osqp": osqp}.get(name, {})
        self.options = {**defaults, **options}

    def solve(self, problem: Problem) -> np.ndarray:
        import qpsolvers

        n, m = problem.nv, problem.n_rows
        lower = np.maximum(problem.lower, -1e9)
        upper = np.minimum(problem.upper, 1e9)
        # a joint whose box is one point (a relaxed intersection) is an equality: as two opposite bounds it makes
        # quadprog's active set degenerate ("no solution")
        fixed = np.flatnonzero(upper <= lower)
        A = b = None
        if fixed.size:
            A = np.zeros((fixed.size, n + m))
            A[np.arange(fixed.size), fixed] = 1.0
            b = lower[fixed].copy()
            lower[fixed], upper[fixed] = -1e9, 1e9
        if m == 0:
            P, q, G, h, lb, ub = problem.H, problem.c, None, None, lower, upper
        else:
            P = np.zeros((n + m, n + m))
            P[:n, :n] = problem.H
            P[n:, n:] = problem.slack_quadratic * np.eye(m)
            q = np.concatenate([problem.c, np.full(m, problem.slack_linear)])
            G = np.hstack([problem.G, -np.eye(m)])
            h = problem.h.copy()
            lb = np.concatenate([lower, np.zeros(m)])
            ub = np.concatenate([upper, np.full(m, 1e9)])
        try:
            x = qpsolvers.solve_qp(P, q, G, h, A, b, lb=lb, ub=ub, solver=self.name, **self.options)
        except Exception as exc:  # backends raise their own types
            raise SolverError(f"{self.name} failed: {exc}", problem.copy()) from exc
        if x is None:
            raise SolverError(f"{self.name} found no solution", problem.copy())
        return np.asarray(x[:n], dtype=float)
