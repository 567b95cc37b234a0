"""Path optimisation by sequential convex programming (TrajOpt-style, Schulman et al. 2014) in joint space.

The path is ``K`` waypoints with fixed ends. Each iteration linearises every pair's signed distance at the
waypoints *and* at the midpoints of the segments (``d + J Δq ≥ target``, the midpoint rows sharing ``J / 2``
between the two waypoints) and solves one QP through qpsolvers:

    minimise  Σ_k |x_{k+1} − x_k|² + μ Σ_i t_i
    s.t.      d_i + J_i Δx + t_i ≥ target,  t_i ≥ 0,  |Δx|_∞ ≤ δ,  lower ≤ x ≤ upper

(the ℓ1 penalty of TrajOpt with slacks ``t``). A step is kept when the exact merit (the same objective with the true
distances) improves by at least a tenth of what the QP predicted; the trust region ``δ`` grows after a kept step and
shrinks after a rejected one; ``μ`` grows while constraints stay violated. The result is returned only when every
segment is certified by conservative advancement (:func:`~taplan.planning.verify.check_segments`, all segments in
one batch), otherwise None.

Used from the straight line (and perturbed seeds) before sampling, and as the smoother of a sampled path.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import qpsolvers
import scipy.sparse as sp

from taplan._osqp import polish_setting
from taplan.errors import InvalidInputError
from taplan.planning.verify import KnownDistances, check_segments
from taplan.scene.world import CollisionWorld

__all__ = ["optimize_path", "OptimizedPath", "resample"]

ACTIVATION = 0.04  # [m] pairs closer than target + this enter the linearisation
SEGMENT_STEP = 0.15  # [rad] waypoint spacing (max-norm) of the optimised path
LIMIT_INSET = 0.01  # [rad] waypoints stay this far inside the position limits (room for the timing spline)
DENSE_SOLVERS = ("daqp", "quadprog", "proxqp")  # given dense matrices; others get scipy.sparse
# ``solver="auto"``: daqp (dense active set) up to this many QP variables, osqp (sparse ADMM) above. The smoother's
# two-arm QPs (850-1,180 variables, one slack per distance row) took daqp 0.24-1.06 s each on a quiet machine and
# its dense setup runs outside daqp's time limit; osqp took a third to a sixth of that on the same paths, with
# the same durations (window problems of bench_planning, refitted real body). The two-arm optimiser's QPs
# (280-520 variables) crossed over near 300: 63 QPs of cubby/overhang/clutter/table problems, daqp 10-26 ms against
# osqp 8-19 ms above 330 variables (first cubby QP: daqp 195 ms), daqp 2-3x faster below 160; the paths equal
# to 1e-5 rad (osqp polishes its active set). With slacks only on the violated rows (:func:`_soft_rows`) the QPs
# have fewer, mostly hard rows, and the crossover moved: 64 QPs of 8 slow problems of the 39-suite, daqp against
# osqp (the same solutions to 1e-13), 300-350 variables 135 against 391 ms in all (daqp faster on all 6), 407
# variables 59 against 33 ms. The first QPs of deep two-arm collisions before the sampler (issue 22, i22g notes:
# qpbench.py on captured QPs, CPU at load 3): 386 variables daqp 23 against osqp 66 ms, 433: 54 against 228, 443:
# both fail, daqp after 56 ms, osqp after 217 (20,000 iterations), 454: 126 against 122, the same solutions to
# 1e-13; 487: daqp fails after 374 ms, osqp solves in 173. With 450 instead of 380: the same plans on problems(200, 0),
# (200, 1) and the hard (80, 1) (every stage and duration to 1e-6 s), cabinet #176 of (200, 1) 279 -> 103 ms of
# optimiser CPU, hard cabinet #66 232 -> 139, shelf #54 of (200, 0) 169 -> 135
LARGE_QP = 450
OSQP_SETTINGS = {"eps_abs": 1e-6, "eps_rel": 1e-6, polish_setting(): True, "max_iter": 20000, "raise_error": False}
REFINEMENTS = 4  # segment splits after a failed certification
# ``give_up_stalled``: after STALL_WINDOW + 1 QPs, an optimisation whose constraint violation (Σ of the distances
# short of the target [m]) is above STALL_FLOOR and more than STALL_RATIO of what it was STALL_WINDOW QPs before
# stops. On the 39 + 80 benchmark problems those that never get clear cut it by 10-25 % in three QPs (window, table:
# 0.38 -> 0.38, 1.19 / 2.18, 2.89 / 3.91) and keep doing so for 30 QPs; those that do get clear cut it 3-100x in
# three QPs (cubby 1.68 -> 0.003). The per-QP violations inside plan_motion (the rule off, 15 QPs, seeds 0 and 1 of
# both suites: 238 problems, issue 22's i22s notes) chose 2 QPs, 0.6 and 0.2 m instead of 3, 0.5 and 0.05: the
# same optimisations given up, 1 QP earlier on 7 of them (window #18 after 3 QPs instead of 5: ~40 ms; hard #24
# 414 -> 275 ms), and one the old rule gave up (an attached object whose violation stays at 0.07 for 4 QPs, clear
# after 8) left to finish; the floor keeps a nearly clear one (0.19 for two rejected QPs, clear after 5) going
STALL_WINDOW, STALL_RATIO, STALL_FLOOR = 2, 0.6, 0.2
# ``give_up_stalled`` also stops an optimisation whose kept path is still above STALL_FLOOR after STALL_BUDGET [s] of
# the calling thread's CPU (its own work, whatever the load) when its last QP left more than BUDGET_RATIO of the
# violation. Deep two-arm collisions (window family) have first QPs of 400-490 variables that take daqp/osqp
# 50-220 ms each: the stall rule's 3 QPs cost 430 ms CPU on window #174 of problems(200, 0) (6.86 -> 3.62 -> 3.62
# -> 2.88 m); window #148 got below the floor only after 406 ms and 4 QPs (9.17 -> 4.72 -> 3.45 -> 2.09 -> 1.16),
# into a 2.92 s plan where the sampler's is 2.16 s. The optimisations kept on seeds 0 and 1 got below the floor
# within 97 ms (clutter #108), but cabinet #176 of problems(200, 1): its first QP (433 variables) took 307 ms and
# cut 5.37 to 0.65 (to 12 %), clear after the next (CPU at load 2-3; issue 22, i22g notes)
STALL_BUDGET = 0.12
BUDGET_RATIO = 0.25
# ``give_up_stalled`` also stops after the first QP when the kept path's violation is still above FIRST_FLOOR [m] and
# more than FIRST_RATIO of the straight line's: on 480 benchmark problems (problems(200, 0), (200, 1) and the hard
# families (80, 1), the rules off for 15 QPs; issue 22, i22g's traces) the optimisations with such a first QP
# (window, poles, shelf, cubby, cabinet: 0.50-1.00 of the start, 1.2-4.7 m left) either never got clear or got clear
# after 190-450 ms into a plan the rules above already gave to the sampler; those that were kept cut the first
# violation to at most 0.41 (cubby #38: 5.79 -> 1.68 m, clear after 78 ms) or below the floor
FIRST_FLOOR, FIRST_RATIO = 1.0, 0.45
# ``give_up_stalled`` does not start with a first QP of more than FIRST_QP_LIMIT variables (one slack per violated
# row: a collision deep enough to violate 200-470 rows), which only osqp takes (LARGE_QP): on those 480 problems
# three optimisations had one (window #148 and #174 of problems(200, 0), cubby #142 of problems(200, 1): 454-520
# variables, osqp 120-200 ms for the first QP); none got clear but #148, after 450 ms, into a plan 35 % longer than
# the sampler's
FIRST_QP_LIMIT = LARGE_QP  # [QP variables]
POINTS = 0.5  # its segments are certified at margin / 2 (every planner edge): evaluated points need no more


@dataclass(frozen=True)
class OptimizedPath:
    """A certified path: ``path`` (K, nq), its ``iterations``, the smallest clearance seen at the evaluations [m]."""

    path: np.ndarray
    iterations: int
    clearance: float


def resample(path: np.ndarray, count: int) -> np.ndarray:
    """``count`` configurations evenly spaced in arc length (Euclidean) along the polyline ``path`` (K, n)."""
    path = np.asarray(path, dtype=float)
    lengths = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(lengths)])
    if s[-1] <= 0:
        return np.repeat(path[:1], count, axis=0)
    wanted = np.linspace(0.0, s[-1], count)
    return np.column_stack([np.interp(wanted, s, path[:, j]) for j in range(path.shape[1])])


class _Problem:
    """The QP's fixed parts for K waypoints of n active joints: the cost ``Σ_k |x_{k+1} − x_k|²`` over the interior
    waypoints x (ends fixed) is ``½ xᵀ P x + qᵀ x + const`` with ``P = 2 (BᵀB ⊗ I_n)``, ``B`` the (K−1, K−2)
    difference matrix (``B[k, k] = 1``, ``B[k, k − 1] = −1``). Built with numpy (scipy.sparse's kron and products
    were 5 ms per problem); the sparse ``P`` only for the sparse solver."""

    def __init__(self, start: np.ndarray, goal: np.ndarray, K: int) -> None:
        n = start.size
        self.K, self.n = K, n
        self.N = (K - 2) * n
        self.start, self.goal = start, goal
        B = np.eye(K - 1, K - 2) - np.eye(K - 1, K - 2, -1)
        self.BtB = B.T @ B
        c = np.zeros((K - 1, n))  # the differences' constant part: -start first, +goal last
        c[0] -= start
        c[K - 2] += goal
        self.q = 2.0 * (B.T @ c).ravel()
        self._P_dense: np.ndarray | None = None
        self._P_sparse: sp.csc_matrix | None = None

    @property
    def P_dense(self) -> np.ndarray:
        """``P`` as a dense array (the dense solvers' form), made once."""
        if self._P_dense is None:
            self._P_dense = 2.0 * np.kron(self.BtB, np.eye(self.n))
        return self._P_dense

    @property
    def P(self) -> sp.csc_matrix:
        """``P`` as a sparse matrix (the sparse solvers' form), made once."""
        if self._P_sparse is None:
            self._P_sparse = (2.0 * sp.kron(sp.csr_matrix(self.BtB), sp.identity(self.n))).tocsc()
        return self._P_sparse

    def cost(self, x: np.ndarray) -> float:
        path = np.vstack([self.start, x.reshape(self.K - 2, self.n), self.goal])
        return float(np.square(np.diff(path, axis=0)).sum())


def _evaluate(
    world: CollisionWorld, full: np.ndarray, path: np.ndarray, active: np.ndarray, cutoff: float
) -> tuple[list[tuple[np.ndarray, np.ndarray]], KnownDistances | None]:
    """Per evaluation point (waypoints 1..K-2, then the K-1 midpoints): (distances, Jacobian rows over active) of
    the pairs within ``cutoff`` that the active joints move; and, from the engine, every pair's exact distance at
    each segment's start, middle and end (the certificate's first level, :func:`check_segments`' ``known``)."""
    K = len(path)
    # the ends too (the certificate starts there); the middles as the certificate computes its fractions
    points = np.concatenate([path, path[:-1] + 0.5 * (path[1:] - path[:-1])])
    configurations = np.repeat(full[None, :], len(points), axis=0)
    configurations[:, active] = points
    batch = world.jacobian_batch(configurations, cutoff=cutoff)
    if batch is not None:  # the engine's arrays: the same pairs and rows as distances_many, without its objects
        assert batch.jacobian is not None
        movable = batch.travel[:, active].any(axis=1)  # pairs the moving joints cannot change stay as they are
        near = (batch.distance <= cutoff) & np.isfinite(batch.distance) & movable
        order = list(range(1, K - 1)) + list(range(K, 2 * K - 1))
        rows = [(batch.distance[n, near[n]], batch.jacobian[n, near[n]][:, active]) for n in order]
        k = np.arange(K - 1)
        along = np.stack([batch.distance[k], batch.distance[K + k], batch.distance[k + 1]], axis=1)  # (K-1, 3, P)
        return rows, KnownDistances(np.array([0.0, 0.5, 1.0]), batch.pairs, along, batch.travel)
    rows = []
    for d in world.distances_many(configurations[np.r_[1 : K - 1, K : 2 * K - 1]], cutoff=cutoff):
        assert d.jacobian is not None and d.travel is not None
        movable = d.travel[:, active].any(axis=1)
        rows.append((d.distance[movable], d.jacobian[movable][:, active]))
    return rows, None


def _lowest(evaluations: list[tuple[np.ndarray, np.ndarray]]) -> float:
    return min((float(d.min()) for d, _ in evaluations if d.size), default=np.inf)


def _violation(evaluations: list[tuple[np.ndarray, np.ndarray]], target: float) -> float:
    return float(sum(np.maximum(0.0, target - d).sum() for d, _ in evaluations))


def optimize_path(
    world: CollisionWorld,
    path: np.ndarray,
    active: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    margin: float,
    *,
    max_iterations: int = 30,
    deadline: float = np.inf,
    solver: str = "auto",
    give_up_stalled: bool = False,
) -> OptimizedPath | None:
    """Optimise ``path`` (K, nq) in the ``active`` joints to a short path that keeps ``margin`` [m] (certified at
    ``margin / 2`` between waypoints, like every planner edge); None when no certified path was found.

    Args:
        world: The collision world.
        path: Seed path (K, nq), its ends fixed; resampled to waypoints about ``SEGMENT_STEP`` apart.
        active: Indices of the joints that move.
        lower: Lower position limits [rad] (nq,).
        upper: Upper position limits [rad] (nq,).
        margin: Clearance [m].
        max_iterations: QP solves at most.
        deadline: ``time.perf_counter()`` value after which the optimisation gives up.
        solver: qpsolvers backend, or ``"auto"``: daqp, a dense active-set solver, the fastest on few-hundred-variable
            QPs (6.5 ms against proxqp's 12 ms sparse and 24 ms dense, same solution to 1e-6), and osqp's sparse
            ADMM above ``LARGE_QP`` variables.
        give_up_stalled: Stop early when the path stays in collision and its violation stops falling
            (``STALL_WINDOW``) or is still above ``STALL_FLOOR`` after ``STALL_BUDGET`` of this thread's CPU: for a
            caller with another planner to go to (the sampler).
    """
    if solver != "auto" and solver not in qpsolvers.available_solvers:
        valid = f"'auto' or an installed qpsolvers backend {qpsolvers.available_solvers}"
        raise InvalidInputError("solver", solver, valid)
    path = np.asarray(path, dtype=float)
    started = time.thread_time()  # the stall budget counts this thread's CPU: the optimiser's own work
    full = path[0].copy()
    seed = path[:, active]
    length = float(np.abs(np.diff(seed, axis=0)).max(axis=1).sum())
    x_path = resample(seed, int(np.clip(np.ceil(length / SEGMENT_STEP) + 1, 5, 40)))
    iterations = 0
    for _ in range(REFINEMENTS + 1):
        optimized, used, known = _sequential_convex(
            world,
            full,
            x_path,
            active,
            lower,
            upper,
            margin,
            max_iterations - iterations,
            deadline,
            solver,
            started if give_up_stalled else None,
        )
        iterations += used
        if optimized is None:
            return None
        x_path = optimized
        configurations = np.repeat(full[None, :], len(x_path), axis=0)
        configurations[:, active] = x_path
        if time.perf_counter() >= deadline:
            return None  # the certificate would end after the deadline
        # every segment in one batch: each level of halving is one batched distance evaluation
        # (its first level: the distances of the last iteration's evaluation of this path, no new evaluation)
        checks = check_segments(
            world,
            configurations[:-1],
            configurations[1:],
            margin,
            points=POINTS * margin,
            deadline=deadline,
            known=known,
        )
        if time.perf_counter() >= deadline:
            return None
        if all(c.valid for c in checks):
            return OptimizedPath(configurations, iterations, min(c.clearance for c in checks))
        # a dip between the evaluated points: evaluate there too (split the segment) and optimise on
        # the failed segment in quarters and its neighbours in halves: a dip bends the path around it
        failed = [not c.valid for c in checks]
        refined = [x_path[0]]
        for k in range(len(checks)):
            near = any(failed[max(k - 1, 0) : k + 2])
            pieces = 4 if failed[k] else 2 if near else 1
            refined += [x_path[k] + (x_path[k + 1] - x_path[k]) * i / pieces for i in range(1, pieces)]
            refined.append(x_path[k + 1])
        x_path = np.array(refined)
        if iterations >= max_iterations or time.perf_counter() >= deadline:
            return None
    return None


def _sequential_convex(
    world: CollisionWorld,
    full: np.ndarray,
    x_path: np.ndarray,
    active: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    margin: float,
    max_iterations: int,
    deadline: float,
    solver: str,
    stall_since: float | None = None,
) -> tuple[np.ndarray | None, int, KnownDistances | None]:
    """The SCP iterations from ``x_path`` (K, n active): (optimised path or None when still colliding, QPs, every
    pair's distances along the path's segments from its last evaluation, when the engine made it). With
    ``stall_since`` (``time.thread_time()`` at the optimisation's start) it gives up when stalled in collision
    (:func:`_stalled`) or still in collision after ``STALL_BUDGET`` (:func:`_over_budget`)."""
    K = len(x_path)
    problem = _Problem(x_path[0], x_path[-1], K)
    inset = np.minimum(LIMIT_INSET, (upper[active] - lower[active]) / 4)
    lo = np.tile(lower[active] + inset, K - 2)
    hi = np.tile(upper[active] - inset, K - 2)
    target = 2.0 * margin  # headroom so that the certified segments keep margin at their evaluations
    cutoff = target + ACTIVATION
    trust, mu = 0.2, 10.0
    x = x_path[1:-1].ravel()
    evaluations, known = _evaluate(world, full, x_path, active, cutoff)
    initial = _violation(evaluations, target)
    merit = problem.cost(x) + mu * initial
    iterations = 0
    longest = 0.0  # [s] the longest iteration so far: another starts only if that much is left before the deadline
    violations: list[float] = []  # of the kept path after each QP
    while iterations < max_iterations and time.perf_counter() + longest < deadline:
        stuck = stall_since is not None and (
            _stalled(violations)
            or _first_step_short([initial, *violations])
            or _over_budget([initial, *violations], time.thread_time() - stall_since)
        )
        if stuck:
            break
        begin = time.perf_counter()
        G_x, h = _linearised(problem, evaluations, x, target)
        # a seed waypoint inside the inset keeps its place as a bound: the box stays non-empty
        box_lo = np.minimum(np.maximum(lo, x - trust), x)
        box_hi = np.maximum(np.minimum(hi, x + trust), x)
        soft = _soft_rows(G_x, h, x)
        G_x, h, soft = _without_redundant_rows(G_x, h, soft, box_lo, box_hi)
        m = G_x.shape[0]
        s = soft.size
        E = np.zeros((m, s))
        E[soft, np.arange(s)] = -1.0
        q = np.concatenate([problem.q, np.full(s, mu)])
        backend = solver if solver != "auto" else ("daqp" if problem.N + s <= LARGE_QP else "osqp")
        if stall_since is not None and not iterations and problem.N + s > FIRST_QP_LIMIT:
            break  # a first QP only osqp takes: the deepest collisions
        iterations += 1
        if backend in DENSE_SOLVERS:
            P = np.zeros((problem.N + s, problem.N + s))
            P[: problem.N, : problem.N] = problem.P_dense
            P[problem.N :, problem.N :] = 1e-6 * np.eye(s)
            G = np.hstack([G_x, E])
        else:
            P = sp.block_diag([problem.P, sp.identity(s) * 1e-6]).tocsc()
            G = sp.hstack([sp.csr_matrix(G_x), sp.csr_matrix(E)]).tocsc() if m else sp.csc_matrix((0, problem.N))
        lb = np.concatenate([box_lo, np.zeros(s)])
        ub = np.concatenate([box_hi, np.full(s, np.inf)])
        # daqp stops at the deadline (one two-arm QP on the real body took 3.4 s under load): no solution, and the
        # next iteration does not start
        settings: dict[str, Any] = dict(OSQP_SETTINGS) if backend == "osqp" else {}
        if deadline < np.inf and backend in ("daqp", "osqp"):
            settings["time_limit"] = max(deadline - time.perf_counter(), 1e-3)
        with warnings.catch_warnings():
            # osqp warns when it stops short of its tolerances; that QP counts as failed (None): the trust shrinks
            warnings.filterwarnings("ignore", message="OSQP exited with status")
            z = qpsolvers.solve_qp(P, q, G if m else None, h if m else None, lb=lb, ub=ub, solver=backend, **settings)
        longest = max(longest, time.perf_counter() - begin)
        if z is None:
            violations.append(violations[-1] if violations else _violation(evaluations, target))
            trust /= 2
            if trust < 1e-3:
                break
            continue
        x_new, slack = z[: problem.N], z[problem.N :]
        predicted = merit - (problem.cost(x_new) + mu * float(np.maximum(slack, 0.0).sum()))
        candidate = np.vstack([x_path[0], x_new.reshape(K - 2, -1), x_path[-1]])
        new_evaluations, new_known = _evaluate(world, full, candidate, active, cutoff)
        new_violation = _violation(new_evaluations, target)
        new_merit = problem.cost(x_new) + mu * new_violation
        longest = max(longest, time.perf_counter() - begin)
        if merit - new_merit >= 0.1 * max(predicted, 0.0) and new_merit < merit:
            improvement = merit - new_merit
            x, evaluations, merit, x_path, known = x_new, new_evaluations, new_merit, candidate, new_known
            violations.append(new_violation)
            trust = min(trust * 1.5, 0.5)
            if _lowest(evaluations) >= margin and improvement < 1e-3 * max(merit, 1e-9):
                break
        else:
            violations.append(violations[-1] if violations else _violation(evaluations, target))
            trust = _shrunk_trust(trust, float(np.abs(x_new - x).max(initial=0.0)))
            if trust < 1e-3:
                if _lowest(evaluations) >= margin:
                    break
                mu *= 10.0  # stuck while infeasible: weigh the constraints more and start again
                trust = 0.1
                merit = problem.cost(x) + mu * _violation(evaluations, target)
                if mu > 1e4:
                    break
    return (x_path if _lowest(evaluations) >= margin else None), iterations, known


def _soft_rows(G_x: np.ndarray, h: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The rows of ``G_x x ≤ h`` that get a slack: those the current path ``x`` violates. The others hold at Δx = 0,
    so the QP stays feasible with them hard (the trust box contains Δx = 0); once the path keeps the target (most
    iterations) the QP has about half the variables: two-arm QPs of 300-500 variables go from osqp (10-40 ms) to
    daqp (7 ms), with the same paths on the 39 benchmark problems (an exact penalty is hard wherever its multiplier
    stays below μ; where it does not, a hard row keeps the path out of a collision it was clear of)."""
    return np.flatnonzero(G_x @ x > h)


def _without_redundant_rows(
    G_x: np.ndarray, h: np.ndarray, soft: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``G_x x ≤ h`` without the hard rows that no ``x`` in the box ``[lower, upper]`` can violate (the largest
    ``G_i x`` over the box, ``Σ_j max(G_ij lower_j, G_ij upper_j)``, is within ``h_i``): the same feasible set and
    optimum with fewer rows (pairs within the cutoff that the trust region keeps clear; a third of cubby #38's first
    QP: daqp 42 -> 37 ms); and the soft rows' new indices."""
    reach = np.maximum(G_x * lower, G_x * upper).sum(axis=1)
    keep = reach > h
    keep[soft] = True
    if keep.all():
        return G_x, h, soft
    return G_x[keep], h[keep], np.flatnonzero(np.isin(np.flatnonzero(keep), soft))


def _stalled(violations: list[float]) -> bool:
    """Whether the kept path's constraint violations after each QP so far [m] say the optimisation is stuck in
    collision: above ``STALL_FLOOR`` and more than ``STALL_RATIO`` of what it was ``STALL_WINDOW`` QPs before (the
    first QP's jump from the straight line not counted)."""
    if len(violations) <= STALL_WINDOW:
        return False
    now, before = violations[-1], violations[-1 - STALL_WINDOW]
    return now > STALL_FLOOR and now > STALL_RATIO * before


def _first_step_short(violations: list[float]) -> bool:
    """Whether an optimisation whose kept path's constraint violations [m] were ``violations`` (at its start, then
    after its first QP) is deep in a collision its first QP did not get it far out of: still above ``FIRST_FLOOR``
    and more than ``FIRST_RATIO`` of the start's."""
    if len(violations) != 2:
        return False
    return violations[1] > FIRST_FLOOR and violations[1] > FIRST_RATIO * violations[0]


def _over_budget(violations: list[float], spent: float) -> bool:
    """Whether an optimisation whose kept path's constraint violations [m] were ``violations`` (at its start, then
    after each QP) after ``spent`` [s] of its thread's CPU should give up: still above ``STALL_FLOOR`` after
    ``STALL_BUDGET``, and its last QP cut the violation to more than ``BUDGET_RATIO`` of what it was."""
    if len(violations) < 2 or spent <= STALL_BUDGET:
        return False
    return violations[-1] > STALL_FLOOR and violations[-1] > BUDGET_RATIO * violations[-2]


def _shrunk_trust(trust: float, step: float) -> float:
    """The trust region after a rejected ``step`` (max-norm) [rad]: halved, and halved again while it still contains
    the step (down to 1e-3). The rejected step stays the QP's optimum in every smaller trust region that contains it
    (a smaller feasible set of the same strictly convex QP): solving those would reject the same step again."""
    trust /= 2
    while step <= trust and trust >= 1e-3:
        trust /= 2
    return trust


def _linearised(
    problem: _Problem, evaluations: list[tuple[np.ndarray, np.ndarray]], x: np.ndarray, target: float
) -> tuple[np.ndarray, np.ndarray]:
    """Rows ``-J Δx - t ≤ d - target`` (without the slack column) as ``G x ≤ h``, G dense (m, N): a few hundred
    columns at most, and daqp takes dense matrices (building them through scipy.sparse cost more than the QP)."""
    K, n = problem.K, problem.n
    keeps = [np.any(J != 0.0, axis=1) for _, J in evaluations]  # pairs the moving joints cannot change: no row
    m = sum(int(np.count_nonzero(keep)) for keep in keeps)
    G = np.zeros((m, problem.N))
    h = np.empty(m)
    X = x.reshape(K - 2, n)
    r = 0
    for e, ((d, J), keep) in enumerate(zip(evaluations, keeps, strict=True)):
        Jk = J[keep]
        rows = len(Jk)
        if not rows:
            continue
        if e < K - 2:
            blocks = [(e, 1.0)]  # waypoint e + 1 is variable block e
        else:
            k = e - (K - 2)  # midpoint of waypoints k, k + 1
            blocks = [(b - 1, 0.5) for b in (k, k + 1) if 1 <= b <= K - 2]
        jx = np.zeros(rows)
        for block, weight in blocks:
            G[r : r + rows, block * n : (block + 1) * n] = -weight * Jk
            jx += weight * (Jk @ X[block])
        h[r : r + rows] = d[keep] - target - jx
        r += rows
    return G, h
