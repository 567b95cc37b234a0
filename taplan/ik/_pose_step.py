"""One iteration of :func:`taplan.ik.solve_pose`: a second-order (geodesic-acceleration) Levenberg-Marquardt step.

Error of each frame: the SE(3) logarithm ``e = log6(T*⁻¹ T(q))`` (6,) ([m] and [rad], target axes), as mink and
pink use; its exact Jacobian is ``Jlog6(T*⁻¹ T) J_local`` with the frame's body Jacobian ``J_local``. The step
``Δq`` [rad] minimises

.. math::

    \\|J Δq + e + r\\|^2 + λ \\|Δq\\|^2 + w^2 \\|Δq - (q_0 - q)\\|^2

within the position limits and ``|Δq| <= max_step`` (a QP when those bounds bind; soft collision rows optionally),
with Levenberg-Marquardt damping ``λ`` proportional to ``‖e‖²`` and a posture weight ``w``.

``r`` is the second-order correction (geodesic acceleration, Transtrum & Sethna 2012): the first-order (Gauss-Newton)
step ``v`` assumes the frame's twist stays constant while the joints move, but a joint motion ``q + t v`` moves the
frame along ``T(t) ≈ T exp(t V + t²/2 A)`` with body twist ``V = J_local v`` and its rate ``A = J̇_local v``
(pinocchio's frame acceleration at ``q̈ = 0``; both from the same configuration, no further kinematics). ``r`` is what
this second-order model adds to the linear prediction at the full step:
``r = log6(T*⁻¹ T exp(V + A/2)) − e − J v``. Minimising with ``e + r`` bends the step so the second-order model (not
only the tangent) reaches the target. The correction is kept only if it changes the step by at most ``accept``
times the step's norm (else the plain damped Gauss-Newton step is taken). Near the solution ``r`` is second order in
``‖e‖`` and the damping vanishes (``λ ∝ ‖e‖²``), so the last steps converge quadratically.

Each step evaluates the kinematics (placements, Jacobians, ``J̇ v``) once and solves at most one QP: it counts as one
iteration.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin
from scipy.linalg import cho_factor, cho_solve

from taplan.errors import SolverError
from taplan.ik._kinematics import Kinematics
from taplan.ik.limits.limit import RowLimit, StepContext
from taplan.ik.problem import Problem
from taplan.ik.solvers import QPSolver

__all__ = ["PoseStep", "frame_errors"]

_LOCAL = pin.ReferenceFrame.LOCAL


def frame_errors(kin: Kinematics, frame_id: int, target: pin.SE3) -> tuple[float, float]:
    """Distance [m] and rotation angle [rad] from the frame (at the last ``kin.update``) to ``target``."""
    placement = kin.data.oMf[frame_id]
    p = float(np.linalg.norm(placement.translation - target.translation))
    r = float(np.linalg.norm(pin.log3(placement.rotation @ target.rotation.T)))
    return p, r


class PoseStep:
    """Computes steps toward fixed frame targets (see the module docstring).

    Args:
        kin: Kinematics of the robot (updated by :meth:`evaluate`).
        frame_ids: Pinocchio frame indices, one per target.
        targets: Target placements ``T_root_frame``, one per frame.
        lower: Position lower limits [rad] (nv,).
        upper: Position upper limits [rad] (nv,).
        max_step: Largest joint change per step [rad].
        posture_cost: Weight ``w`` per [rad] toward ``q_ref``.
        q_ref: Posture reference [rad] (nv,).
        lm_damping: Damping per squared error (``λ = 1e-9 + lm_damping ‖e‖²``).
        second_order: Apply the geodesic-acceleration correction.
        accept: Largest ratio ``‖correction‖ / ‖step‖`` for which the correction is kept.
        rows: Soft row limits (e.g. collision), built at ``dt = 1``.
        backend: QP backend used when the bounds or rows bind.
    """

    def __init__(
        self,
        kin: Kinematics,
        frame_ids: Sequence[int],
        targets: Sequence[pin.SE3],
        lower: np.ndarray,
        upper: np.ndarray,
        max_step: float,
        posture_cost: float,
        q_ref: np.ndarray,
        lm_damping: float,
        second_order: bool,
        accept: float,
        rows: Sequence[RowLimit],
        backend: QPSolver,
    ) -> None:
        self.kin = kin
        self.frame_ids = list(frame_ids)
        self.targets = list(targets)
        self.lower, self.upper = lower, upper
        self.max_step = float(max_step)
        self.w2 = float(posture_cost) ** 2
        self.q_ref = q_ref
        self.lm_damping = float(lm_damping)
        self.second_order = bool(second_order)
        self.accept = float(accept)
        self.rows = list(rows)
        self.backend = backend
        n = kin.nv
        k = len(self.frame_ids)
        self._e = np.zeros(6 * k)
        self._J = np.zeros((6 * k, n))
        self._D: list[pin.SE3] = [pin.SE3.Identity() for _ in range(k)]
        self._G = np.zeros((sum(lim.max_rows for lim in self.rows), n))
        self._h = np.zeros(self._G.shape[0])
        self._zeros = np.zeros(n)

    def evaluate(self, q: np.ndarray) -> tuple[list[float], list[float]]:
        """Update the kinematics at ``q`` [rad]; per frame the distance [m] and rotation angle [rad] to its target."""
        kin = self.kin
        kin.update(q)
        pos, rot = [], []
        for fid, target in zip(self.frame_ids, self.targets, strict=True):
            p, r = frame_errors(kin, fid, target)
            pos.append(p)
            rot.append(r)
        return pos, rot

    def linearise(self) -> tuple[np.ndarray, np.ndarray]:
        """Stacked errors ``log6(T*⁻¹ T)`` (6k,) and their Jacobian (6k, nv) at the last :meth:`evaluate` (buffers)."""
        model, data = self.kin.model, self.kin.data
        e, J = self._e, self._J
        for i, (fid, target) in enumerate(zip(self.frame_ids, self.targets, strict=True)):
            D = self._D[i] = target.actInv(data.oMf[fid])
            rows = slice(6 * i, 6 * i + 6)
            e[rows] = pin.log6(D).vector
            np.matmul(pin.Jlog6(D), pin.getFrameJacobian(model, data, fid, _LOCAL), out=J[rows])
        return e, J

    def step(self) -> np.ndarray:
        """The joint change Δq [rad] (nv,) from the configuration of the last :meth:`evaluate`.

        Raises:
            SolverError: the QP backend failed or returned a non-finite step.
        """
        kin = self.kin
        q = kin.q
        e, J = self.linearise()
        n = kin.nv
        H = J.T @ J
        H.flat[:: n + 1] += 1e-9 + self.lm_damping * float(e @ e) + self.w2
        c = J.T @ e
        c -= self.w2 * (self.q_ref - q)
        lo = np.maximum(self.lower - q, -self.max_step)
        hi = np.minimum(self.upper - q, self.max_step)
        factor = cho_factor(H)
        v = -cho_solve(factor, c)
        if self.second_order:
            r = self.model_residual(np.clip(v, lo, hi))
            if np.all(np.isfinite(r)):
                correction = cho_solve(factor, J.T @ r)
                if np.linalg.norm(correction) <= self.accept * np.linalg.norm(v):
                    c += J.T @ r
                    v -= correction
        m = 0
        if self.rows:
            ctx = StepContext(kin, 1.0, self._zeros, v)
            for lim in self.rows:
                m += lim.rows(ctx, self._G[m:], self._h[m:])
        feasible = bool(np.all(v >= lo) and np.all(v <= hi))
        if feasible and m and not bool(np.all(self._G[:m] @ v <= self._h[:m])):
            feasible = False
        if not (feasible and self.backend.exact_shortcut):
            problem = Problem(H, c, lo, hi, self._G[:m], self._h[:m], 1.0, self._zeros, v)
            v = np.array(self.backend.solve(problem), dtype=float)
        np.clip(v, lo, hi, out=v)
        if not np.all(np.isfinite(v)):
            raise SolverError(
                "the pose step is not finite", Problem(H, c, lo, hi, self._G[:m], self._h[:m], 1.0, self._zeros, v)
            )
        return v

    def model_residual(self, v: np.ndarray) -> np.ndarray:
        """Second-order model's error at the full step ``v`` [rad] (nv,) minus the linear prediction (6k,), after
        :meth:`linearise` at the same configuration."""
        kin = self.kin
        model, data = kin.model, kin.data
        pin.forwardKinematics(model, data, kin.q, v, self._zeros)  # same q: placements unchanged; velocities, J̇v
        r = np.empty_like(self._e)
        for i, fid in enumerate(self.frame_ids):
            V = pin.getFrameVelocity(model, data, fid, _LOCAL).vector
            A = pin.getFrameAcceleration(model, data, fid, _LOCAL).vector
            r[6 * i : 6 * i + 6] = pin.log6(self._D[i] * pin.exp6(V + 0.5 * A)).vector
        r -= self._e
        r -= self._J @ v
        return r
