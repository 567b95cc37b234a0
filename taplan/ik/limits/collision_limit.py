"""Arm-arm collision avoidance: capsule pairs keep a minimum distance (velocity damper on the distance)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from taplan.errors import InvalidInputError
from taplan.ik._kinematics import Kinematics
from taplan.ik.limits.limit import RowLimit, StepContext
from taplan.scene.capsules import Capsule, segment_closest_points

__all__ = ["CollisionLimit", "capsule_pair_distance"]


def capsule_pair_distance(
    kin: Kinematics, first: Capsule, second: Capsule
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Distance between two capsules and its Jacobian at the configuration held by ``kin``.

    Returns:
        (distance [m] (negative when overlapping), its gradient ``dd/dq`` (nv,), the closest point on the first
        capsule's axis [m] (3,), the closest point on the second [m] (3,)).
    """
    data = kin.data
    Ma, Mb = data.oMi[first.joint], data.oMi[second.joint]
    pa, pb, _, _ = segment_closest_points(
        Ma.act(first.start), Ma.act(first.end), Mb.act(second.start), Mb.act(second.end)
    )
    delta = pa - pb
    norm = float(np.linalg.norm(delta))
    if norm > 1e-9:
        n = delta / norm
    else:  # axes intersect: any direction; use the one between the joint origins
        n = Ma.translation - Mb.translation
        n = n / max(float(np.linalg.norm(n)), 1e-12)
    grad = np.zeros(kin.nv)
    for joint, point, sign in ((first.joint, pa, 1.0), (second.joint, pb, -1.0)):
        if joint == 0:
            continue
        J = kin.joint_jacobian(joint)
        r = point - data.oMi[joint].translation
        rxn = np.array([r[1] * n[2] - r[2] * n[1], r[2] * n[0] - r[0] * n[2], r[0] * n[1] - r[1] * n[0]])
        grad += sign * (n @ J[:3] + rxn @ J[3:])
    return norm - first.radius - second.radius, grad, pa, pb


def check_damper(margin: float, influence: float, gain: float) -> None:
    """Validate a velocity damper's margin [m], influence distance [m] (> margin) and gain in (0, 1]."""
    if not (np.isfinite(margin) and margin >= 0.0):
        raise InvalidInputError("margin", margin, "a distance >= 0 [m]")
    if not (np.isfinite(influence) and influence > margin):
        raise InvalidInputError("influence", influence, f"a distance > margin ({margin}) [m]")
    if not (np.isfinite(gain) and 0.0 < gain <= 1.0):
        raise InvalidInputError("gain", gain, "a number in (0, 1]")


class CollisionLimit(RowLimit):
    r"""Keep every capsule pair at least ``margin`` apart.

    For each pair closer than ``influence`` the distance ``d`` and its Jacobian ``J_d`` give one row of the
    velocity-damper constraint

    .. math::

        J_d v \ge -\min\left(\gamma \frac{d - d_m}{dt},\ \sqrt{2 \alpha (d - d_m)}\right)

    with ``d_m = margin``: one step closes at most the fraction ``γ`` of the gap, and (with an acceleration limit)
    the approach speed is one the arms can still brake from at ``α = ½ Σ_j |J_d,j| a_j`` [m/s²]. Below the margin
    the right-hand side becomes a separation speed. Rows are soft (one penalised slack each) so they never make the
    QP infeasible; with the acceleration bound hard, an approach faster than the arms can brake is the only case
    where the margin can be crossed.

    The exact distances are only recomputed when they could have changed enough to matter: a point on an arm moves
    at most ``reach Σ_j |Δq_j|`` (``reach`` bounds the distance from any arm joint to any capsule point), so until
    ``reach ‖q − q_eval‖₁`` reaches the clearance ``min d − influence`` found at ``q_eval`` no pair can enter the
    influence distance. With an acceleration limit a pair is also evaluated (and constrained) early enough to brake:
    each pair's distance must exceed ``influence + 1.5 s² / (2α) + 2 s dt`` with the approach speed bounded by
    ``s = Σ_j |J_d,j| |v_prev,j|`` (gradients of the last evaluation).

    Args:
        pairs: Capsule pairs (e.g. ``robot.capsule_pairs("left", "right")``).
        model: Pinocchio model (to bound the reach).
        margin: Minimum distance between capsule surfaces [m], >= 0.
        influence: Distance below which a pair is constrained [m], > margin.
        gain: Fraction ``γ`` of the gap a step may close, in (0, 1].
        acceleration: Joint acceleration limits [rad/s²] (nv,), or None (no braking term).
        buffer: Extra distance [m] added to the margin inside the constraint, absorbing the first-order
            (linearisation) error of one step so the true distance stays above ``margin``.
    """

    name = "collision"

    def __init__(
        self,
        pairs: Sequence[tuple[Capsule, Capsule]],
        model: pin.Model,
        margin: float = 0.02,
        influence: float = 0.10,
        gain: float = 0.5,
        acceleration: np.ndarray | None = None,
        buffer: float = 1e-3,
    ) -> None:
        check_damper(margin, influence, gain)
        self.pairs = list(pairs)
        self.margin, self.influence, self.gain = float(margin), float(influence), float(gain)
        self.buffer = float(buffer)
        self.acceleration = None if acceleration is None else np.asarray(acceleration, dtype=float)
        self.max_rows = len(self.pairs)
        self.reach = _reach_bound(model, self.pairs)
        self._q_eval = np.full(model.nv, np.nan)
        self._clearance = -np.inf
        self._min_distance = np.inf
        self._scratch = np.empty(model.nv)
        self.distances = np.full(len(self.pairs), np.inf)
        self._inv_two_alpha = np.zeros(len(self.pairs))
        m = len(self.pairs)
        self._abs_grads = np.zeros((m, model.nv))
        self._braking_factor = np.zeros(m)
        self._speed = np.zeros(m)
        self._horizon = np.zeros(m)
        self._distances_eval = np.full(m, np.inf)
        self._pairs = _PairArrays(model, self.pairs)

    def reset(self) -> None:
        """Forget the last exact evaluation (e.g. after a jump in configuration)."""
        self._q_eval[:] = np.nan
        self._clearance = -np.inf

    @property
    def min_distance(self) -> float:
        """A lower bound of the smallest pair distance at the last step's configuration [m]."""
        return self._min_distance

    def rows(self, ctx: StepContext, G: np.ndarray, h: np.ndarray) -> int:
        if not self.pairs:
            return 0
        travel, closest = self.screen(ctx)
        return self.screened_rows(ctx, G, h, travel, closest)

    def screen(self, ctx: StepContext) -> tuple[float, float]:
        """``(travel, closest)`` of the screening (see the class docstring): ``reach ‖q − q_eval‖₁`` [m] and, with
        an acceleration limit, the smallest pair distance at the last evaluation minus its braking horizon [m]
        (else inf). The native IK kernel computes the same two numbers from the same buffers."""
        q = ctx.kin.q
        s = self._scratch
        np.subtract(q, self._q_eval, out=s)
        np.abs(s, out=s)
        travel = self.reach * sum(s.tolist())
        if self.acceleration is None:
            return travel, np.inf
        np.abs(ctx.v_prev, out=s)
        speed = self._speed
        np.matmul(self._abs_grads, s, out=speed)  # per pair, a bound of the approach speed [m/s]
        horizon = self._horizon
        np.multiply(speed, self._braking_factor, out=horizon)  # 1.5 s / (2 α)
        horizon += 2.0 * ctx.dt
        horizon *= speed
        np.subtract(self._distances_eval, horizon, out=horizon)
        return travel, min(horizon.tolist())

    def screened_rows(self, ctx: StepContext, G: np.ndarray, h: np.ndarray, travel: float, closest: float) -> int:
        """:meth:`rows` given the screening's ``(travel, closest)`` (:meth:`screen`)."""
        if self.acceleration is None:
            skip = travel < self._clearance  # nan-safe: nan fails the test and forces an evaluation
        else:  # also leave room to brake (see the class docstring)
            skip = closest - travel > self.influence  # nan-safe as above
        if skip:
            self._min_distance = self._clearance + self.influence - travel
            return 0
        dt = ctx.dt
        ctx.kin.refresh()
        d, grads = self._pairs.evaluate(ctx.kin)
        self.distances[:] = d
        np.abs(grads, out=self._abs_grads)
        gap = d - (self.margin + self.buffer)
        rate = gap * (self.gain / dt)
        active = d < self.influence
        if self.acceleration is not None:
            alpha = 0.5 * (self._abs_grads @ self.acceleration)
            np.divide(1.0, np.maximum(2.0 * alpha, 1e-9), out=self._inv_two_alpha)
            approach = np.maximum(-(grads @ ctx.v_prev), 0.0)
            active |= gap < 1.5 * approach * approach * self._inv_two_alpha + 2.0 * approach * dt
            np.minimum(rate, np.sqrt(2.0 * alpha * np.maximum(gap, 0.0)), out=rate, where=gap > 0.0)
        k = int(np.count_nonzero(active))
        if k:
            np.negative(grads[active], out=G[:k])
            h[:k] = rate[active]
        self._q_eval[:] = ctx.kin.q
        if self.acceleration is not None:
            np.multiply(self._inv_two_alpha, 1.5, out=self._braking_factor)
            self._distances_eval[:] = self.distances
        d_min = float(self.distances.min())
        self._clearance = d_min - self.influence
        self._min_distance = d_min
        return k


class _PairArrays:
    """All capsule pairs' distances and gradients at once (the same closed form as
    :func:`~taplan.scene.capsules.segment_closest_points` and :func:`capsule_pair_distance`, vectorised over pairs).

    Gradients use the world-frame joint Jacobians of ``computeJointJacobians``: a point ``x`` carried by joint
    ``k``'s chain moves at ``J_v,j + J_ω,j × x`` per unit of joint ``j``, so ``∂(n·x)/∂q_j = n·J_v,j + J_ω,j·(x × n)``.
    """

    def __init__(self, model: pin.Model, pairs: Sequence[tuple[Capsule, Capsule]]) -> None:
        capsules = list({id(c): c for pair in pairs for c in pair}.values())
        index = {id(c): i for i, c in enumerate(capsules)}
        self.joints = [c.joint for c in capsules]
        self.local = np.stack([np.stack([c.start, c.end], axis=1) for c in capsules])  # (C, 3, 2)
        self.first = np.array([index[id(a)] for a, _ in pairs], dtype=int)
        self.second = np.array([index[id(b)] for _, b in pairs], dtype=int)
        self.radii = np.array([a.radius + b.radius for a, b in pairs])
        support = np.zeros((len(capsules), model.nv))
        for i, capsule in enumerate(capsules):
            for joint in model.supports[capsule.joint]:
                if joint > 0:
                    support[i, model.joints[joint].idx_v] = 1.0
        self.support_first, self.support_second = support[self.first], support[self.second]
        self.pairs = list(pairs)
        self._R = np.zeros((len(capsules), 3, 3))
        self._t = np.zeros((len(capsules), 3, 1))
        self._V = np.zeros((len(pairs), 3, 3))

    def evaluate(self, kin: Kinematics) -> tuple[np.ndarray, np.ndarray]:
        """Distances [m] (P,) (negative when overlapping) and their gradients ``dd/dq`` (P, nv) at ``kin``'s state."""
        data = kin.data
        oMi = data.oMi
        R, t = self._R, self._t
        for i, joint in enumerate(self.joints):
            placement = oMi[joint]
            R[i] = placement.rotation
            t[i, :, 0] = placement.translation
        world = R @ self.local + t  # (C, 3, 2): segment end points
        p0, q0 = world[self.first, :, 0], world[self.second, :, 0]
        V = self._V  # per pair the rows d1, d2, r, whose Gram matrix holds every dot product needed
        np.subtract(world[self.first, :, 1], p0, out=V[:, 0])
        np.subtract(world[self.second, :, 1], q0, out=V[:, 1])
        np.subtract(p0, q0, out=V[:, 2])
        gram = V @ V.transpose(0, 2, 1)
        d1, d2 = V[:, 0], V[:, 1]
        a, b, c = gram[:, 0, 0], gram[:, 0, 1], gram[:, 0, 2]
        e, f = gram[:, 1, 1], gram[:, 1, 2]
        eps = 1e-12
        if not (a.min() > eps and e.min() > eps):  # a degenerate segment: the scalar reference handles it
            return self._scalar(kin)
        denom = a * e - b * b
        s = np.zeros_like(a)
        np.divide(b * f - c * e, denom, out=s, where=denom > eps)
        np.clip(s, 0.0, 1.0, out=s)
        t_ = (b * s + f) / e
        below, above = t_ < 0.0, t_ > 1.0
        s = np.where(below, np.clip(-c / a, 0.0, 1.0), np.where(above, np.clip((b - c) / a, 0.0, 1.0), s))
        np.clip(t_, 0.0, 1.0, out=t_)
        pa = p0 + s[:, None] * d1
        pb = q0 + t_[:, None] * d2
        delta = pa - pb
        norm = np.sqrt((delta * delta).sum(axis=1))
        if not norm.min() > 1e-9:  # intersecting axes: the scalar reference picks the direction
            return self._scalar(kin)
        n = delta / norm[:, None]
        J = data.J
        along = n @ J[:3]  # n·J_v, (P, nv)
        points = np.concatenate([pa, pb])
        normals = np.concatenate([n, n])
        moment = np.empty_like(points)  # x × n for both closest points
        moment[:, 0] = points[:, 1] * normals[:, 2] - points[:, 2] * normals[:, 1]
        moment[:, 1] = points[:, 2] * normals[:, 0] - points[:, 0] * normals[:, 2]
        moment[:, 2] = points[:, 0] * normals[:, 1] - points[:, 1] * normals[:, 0]
        turn = moment @ J[3:]  # (2P, nv)
        m = len(self.pairs)
        grads = self.support_first * (along + turn[:m]) - self.support_second * (along + turn[m:])
        return norm - self.radii, grads

    def _scalar(self, kin: Kinematics) -> tuple[np.ndarray, np.ndarray]:
        out = [capsule_pair_distance(kin, a, b) for a, b in self.pairs]
        return np.array([o[0] for o in out]), np.stack([o[1] for o in out])


def _reach_bound(model: pin.Model, pairs: Sequence[tuple[Capsule, Capsule]]) -> float:
    """Upper bound [m] of the distance from any joint origin on a capsule's chain to any point of that capsule."""
    reach = 0.0
    for capsule in {id(c): c for pair in pairs for c in pair}.values():
        chain = 0.0
        j = capsule.joint
        while j > 0:
            chain += float(np.linalg.norm(model.jointPlacements[j].translation))
            j = model.parents[j]
        reach = max(reach, chain + max(float(np.linalg.norm(capsule.start)), float(np.linalg.norm(capsule.end))))
    return reach
