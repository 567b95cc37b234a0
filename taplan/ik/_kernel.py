"""The fused builder's problem as one CasADi function, compiled to native code (see :mod:`taplan.ik._native`).

From the configuration, the previous velocity, the targets and their motion, the function computes what
:meth:`taplan.ik._fused.FusedBuilder.build` computes with numpy: the frame rows (kinematics, ``log3``, ``Jlog3``),
``H``, both right-hand sides and their Cholesky solve, the box layers (acceleration, velocity, position braking or
the outside-the-range bound, target braking and its objective scale) intersected in priority order with the same
relaxation, the scaled linear term and the minimiser. Its one flag asks for the numpy path: ``H`` not positive
definite, or an orientation error within 1e-4 rad of π, where the rotation axis is better taken from pinocchio's
``log3``.

Inputs (all float64 vectors): ``q`` (n), ``v_prev`` (n), ``q_ref`` (n, posture reference), ``params`` (see
:func:`param_layout`), ``step`` (``[dt, explicit_0, ...]``: 1 where the frame's motion is an explicit twist fed
forward in the objective), then per frame its target ``T`` (16, row-major 4x4) and motion ``[ṗ*, ω*]`` (6).
Outputs: ``H`` (n²), ``c`` (n), ``minimiser`` (n), ``[v_free, v_ff]`` (2n), the layers (L, 2, n) and the box
(2, n) in stacked form ``[upper, -lower]``, ``lower`` (n), the flag (1), and per frame its position [m] and
orientation [rad] error. With capsule pairs, the collision screening adds inputs and an output
(:func:`_collision_screening`).
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

import casadi as ca
import numpy as np
import pinocchio as pin

from taplan.ik._kernel_math import cholesky_solve, frame_kinematics, jlog3, joint_axes, log3

__all__ = ["param_layout", "step_function"]

_NEAR_PI = np.pi - 1e-4
_functions: dict[str, ca.Function | None] = {}


def param_layout(nv: int, frames: int, acceleration: bool, braking: bool, pairs: int = 0) -> dict[str, slice]:
    """Slices of the ``params`` input: Hessian diagonal ``w² + λ``, posture gain ``w² gain``, velocity limit,
    position bounds, accelerations of the acceleration limit, of position braking and of target braking, the
    position gain, the collision screening's reach (with capsule pairs), and per frame its 6 weights and its
    gain."""
    sizes = [("diagonal", nv), ("posture_gain", nv), ("velocity", nv), ("upper", nv), ("lower", nv)]
    if acceleration:
        sizes += [("acceleration", nv), ("position_acceleration", nv)]
    if braking:
        sizes.append(("braking_acceleration", nv))
    sizes.append(("position_gain", 1))
    if pairs:
        sizes.append(("reach", 1))
    for i in range(frames):
        sizes += [(f"weights{i}", 6), (f"gain{i}", 1)]
    layout, start = {}, 0
    for name, size in sizes:
        layout[name] = slice(start, start + size)
        start += size
    layout["size"] = slice(0, start)
    return layout


def _key(model: pin.Model, frame_ids: Sequence[int], acceleration: bool, braking: bool, pairs: int) -> str:
    options = (model.nv, tuple(frame_ids), acceleration, braking, pairs, ca.__version__)
    digest = hashlib.sha256(repr(options).encode())
    for i in range(1, model.njoints):
        digest.update(model.jointPlacements[i].homogeneous.tobytes())
        digest.update(f"{model.parents[i]},{model.joints[i].shortname()},{model.joints[i].idx_v}".encode())
    for fid in frame_ids:
        digest.update(model.frames[fid].placement.homogeneous.tobytes())
        digest.update(str(model.frames[fid].parentJoint).encode())
    return digest.hexdigest()


def _stacked_intersection(layers: Sequence[ca.SX]) -> ca.SX:
    """Intersect stacked boxes (2, n) in order, never emptying (``taplan.ik.limits.limit.intersect_stacked``)."""
    box = layers[0]
    for new in layers[1:]:
        flipped = -ca.vertcat(box[1, :], box[0, :])
        box = ca.fmax(ca.fmin(box, new), flipped)
    return box


def _checked_kinematics(model: pin.Model, frame_ids: Sequence[int]) -> tuple[ca.SX, list] | None:
    """The frames' SX kinematics, or None when the model has other joints or they disagree with pinocchio."""
    axes = joint_axes(model)
    if axes is None:
        return None
    q = ca.SX.sym("q", model.nv)
    frames = frame_kinematics(model, axes, q, frame_ids)
    check = ca.Function("fk", [q], [out for frame in frames for out in frame])
    data = model.createData()
    rng = np.random.default_rng(0)
    for _ in range(2):
        qv = rng.uniform(-2.0, 2.0, model.nv)
        pin.computeJointJacobians(model, data, qv)
        pin.updateFramePlacements(model, data)
        values = check(qv)
        for i, fid in enumerate(frame_ids):
            R, p, J = (np.array(v) for v in values[3 * i : 3 * i + 3])
            reference = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
            error = max(
                np.abs(R - data.oMf[fid].rotation).max(),
                np.abs(p.ravel() - data.oMf[fid].translation).max(),
                np.abs(J - reference).max(),
            )
            if not error < 1e-9:
                return None
    return q, frames


def step_function(
    model: pin.Model, frame_ids: Sequence[int], acceleration: bool, braking: bool, pairs: int = 0
) -> ca.Function | None:
    """The kernel for this model, task frames, limit set and number of capsule pairs screened for collision (cached
    per process), or None if the model's joints are not supported (then the numpy path is used)."""
    key = _key(model, frame_ids, acceleration, braking, pairs)
    if key not in _functions:
        _functions[key] = _build(model, frame_ids, acceleration, braking, pairs)
    return _functions[key]


def _build(
    model: pin.Model, frame_ids: Sequence[int], acceleration: bool, braking: bool, pairs: int
) -> ca.Function | None:
    checked = _checked_kinematics(model, frame_ids)
    if checked is None:
        return None
    q, frames = checked
    n, nf = model.nv, len(frame_ids)
    layout = param_layout(n, nf, acceleration, braking, pairs)
    v_prev, q_ref = ca.SX.sym("v_prev", n), ca.SX.sym("q_ref", n)
    params = ca.SX.sym("params", layout["size"].stop)
    step = ca.SX.sym("step", 1 + nf)
    targets = [ca.SX.sym(f"target{i}", 16) for i in range(nf)]
    motions = [ca.SX.sym(f"motion{i}", 6) for i in range(nf)]

    def par(name: str) -> ca.SX:
        return params[layout[name]]

    dt = step[0]
    rows, rhs, rhs_ff = [], [], []
    near_pi = ca.SX(0.0)
    errors = []  # per frame: position error [m], orientation error [rad]
    for i, (R, p, J) in enumerate(frames):
        T = targets[i]
        R_target = ca.vertcat(ca.horzcat(T[0], T[1], T[2]), ca.horzcat(T[4], T[5], T[6]), ca.horzcat(T[8], T[9], T[10]))
        p_target = ca.vertcat(T[3], T[7], T[11])
        M = ca.mtimes(R, R_target.T)
        omega, theta = log3(M)
        near_pi = ca.fmax(near_pi, theta > _NEAR_PI)
        errors += [ca.norm_2(p_target - p), theta]
        JlogT = jlog3(theta, omega).T
        W, gain = par(f"weights{i}"), par(f"gain{i}")
        rows.append(W * ca.vertcat(J[:3, :], ca.mtimes(JlogT, J[3:, :])))
        b = gain * (W * ca.vertcat(p_target - p, -omega))
        motion = motions[i]
        b_ff = W * ca.vertcat(motion[:3], ca.mtimes(JlogT, ca.mtimes(M, motion[3:])))
        rhs.append(b + step[1 + i] * (b_ff * dt))  # an explicit twist: aim at the target one dt later
        rhs_ff.append(b_ff)
    A = ca.vertcat(*rows)
    H = ca.mtimes(A.T, A) + ca.diag(par("diagonal"))
    rhs0 = (ca.mtimes(A.T, ca.vertcat(*rhs)) + par("posture_gain") * (q_ref - q)) * (1.0 / dt)
    rhs1 = ca.mtimes(A.T, ca.vertcat(*rhs_ff))
    X, min_pivot = cholesky_solve(H, ca.horzcat(rhs0, rhs1))
    v_free, v_ff = X[:, 0], X[:, 1]

    velocity = par("velocity")
    distance = ca.horzcat(par("upper") - q, q - par("lower")).T  # (2, n)
    layers = []
    kappa = ca.SX(1.0)
    if acceleration:
        adt = par("acceleration") * dt
        layers.append(ca.horzcat(v_prev + adt, adt - v_prev).T)
    layers.append(ca.horzcat(velocity, velocity).T)
    if acceleration:
        a = ca.repmat(par("position_acceleration").T, 2, 1)
        adt = a * dt
        clamped = ca.fmax(distance, 0.0)
        two_a_d = 2.0 * a * clamped
        inside = two_a_d / (ca.sqrt(two_a_d + adt * adt) + adt)  # no cancellation near the bound
        outside = ca.sqrt(two_a_d + adt * adt) - adt + ca.fmin(distance, 0.0) * (par("position_gain") / dt)
        layers.append(ca.if_else(ca.mmin(distance) < 0.0, outside, inside))
    else:
        layers.append(distance * (par("position_gain") / dt))
    if braking:
        a = par("braking_acceleration")
        relative = v_free - v_ff
        adt = a * dt
        two_adt_speed = 2.0 * adt * ca.fabs(relative)
        root = ca.sqrt(two_adt_speed + adt * adt) + adt
        bound = two_adt_speed / root
        kappa = ca.mmin(2.0 * adt / root)
        unbounded = ca.inf * ca.SX.ones(n)  # moving away from the target: no bound on that side
        upper = ca.if_else(relative < 0.0, unbounded, bound) + v_ff
        lower = ca.if_else(relative > 0.0, unbounded, bound) - v_ff
        layers.append(ca.horzcat(upper, lower).T)
    box = _stacked_intersection(layers)
    scale = ca.if_else(kappa >= 1.0, 1.0, kappa * (1.0 - 1e-12))
    scaled = kappa < 1.0
    c = ca.if_else(scaled, -scale * (rhs0 - rhs1) - rhs1, -rhs0)
    minimiser = ca.if_else(scaled, (v_free - v_ff) * scale + v_ff, v_free)
    fallback = ca.fmax(near_pi, min_pivot <= 0.0)
    stack = ca.vertcat(*[ca.vec(layer.T) for layer in layers])  # C order of a (L, 2, n) array
    inputs = [q, v_prev, q_ref, params, step, *[x for pair in zip(targets, motions, strict=True) for x in pair]]
    outputs = [ca.vec(H), c, minimiser, ca.vertcat(v_free, v_ff), stack, ca.vec(box.T), -box[1, :].T, fallback]
    outputs.append(ca.vertcat(*errors))
    if pairs:
        screening = _collision_screening(n, pairs, q, v_prev, dt, par("reach"), acceleration)
        inputs += screening[:4]
        outputs.append(screening[4])
    return ca.Function("taplan_ik_step", inputs, outputs)


def _collision_screening(
    n: int, pairs: int, q: ca.SX, v_prev: ca.SX, dt: ca.SX, reach: ca.SX, acceleration: bool
) -> tuple[ca.SX, ...]:
    """Inputs (the collision limit's buffers: ``q_eval`` (n), ``|∂d/∂q|`` (pairs, n) in C order, braking factor
    (pairs), distances (pairs), all at its last evaluation) and the output ``[travel, closest]`` of
    :meth:`~taplan.ik.limits.CollisionLimit.screen`."""
    q_eval, abs_grads = ca.SX.sym("q_eval", n), ca.SX.sym("abs_grads", pairs * n)
    factor, distances = ca.SX.sym("braking_factor", pairs), ca.SX.sym("distances", pairs)
    travel = reach * ca.sum1(ca.fabs(q - q_eval))
    if acceleration:
        speed = ca.mtimes(ca.reshape(abs_grads, n, pairs).T, ca.fabs(v_prev))  # per pair [m/s]
        closest = ca.mmin(distances - (speed * factor + 2.0 * dt) * speed)
    else:
        closest = ca.SX(ca.inf)
    return q_eval, abs_grads, factor, distances, ca.vertcat(travel, closest)
