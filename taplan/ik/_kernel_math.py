"""CasADi SX building blocks of the native IK kernel: a robot's kinematic chain from pinocchio's numbers, SO(3)
``log3``/``Jlog3``, and a dense Cholesky solve.

``pinocchio.casadi`` is not in the pip wheel, so the chain is rebuilt here from the model's joint placements and
motion axes (revolute and prismatic 1-DoF joints); :func:`joint_axes` returns None for any other joint, and
:func:`frame_kinematics` is checked against pinocchio by the kernel before it is used.
"""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca
import numpy as np
import pinocchio as pin

__all__ = ["cholesky_solve", "frame_kinematics", "jlog3", "joint_axes", "log3"]

JointAxis = tuple[str, np.ndarray]  # ("revolute" | "prismatic", unit axis in the joint frame)

_SMALL_ANGLE = 1e-3  # [rad] below it log3/Jlog3 use their Taylor expansions (error < 1e-16)


def joint_axes(model: pin.Model) -> list[JointAxis] | None:
    """Per joint (index 1..njoints-1) its type and unit axis, or None if a joint is not a 1-DoF revolute or prismatic
    joint with ``idx_q == idx_v`` (read from the motion subspace; the kernel checks the resulting chain against
    pinocchio's forward kinematics before using it)."""
    out: list[JointAxis] = []
    for i in range(1, model.njoints):
        joint = model.joints[i]
        if joint.nq != 1 or joint.nv != 1 or joint.idx_q != joint.idx_v:
            return None
        data = joint.createData()
        joint.calc(data, np.zeros(1))
        S = np.asarray(data.S, dtype=float).reshape(6)
        linear, angular = S[:3], S[3:]
        if np.allclose(linear, 0.0, atol=1e-12) and abs(np.linalg.norm(angular) - 1.0) < 1e-12:
            kind, axis = "revolute", angular.copy()
        elif np.allclose(angular, 0.0, atol=1e-12) and abs(np.linalg.norm(linear) - 1.0) < 1e-12:
            kind, axis = "prismatic", linear.copy()
        else:
            return None
        out.append((kind, axis))
    return out


def _skew(a: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def frame_kinematics(
    model: pin.Model, axes: Sequence[JointAxis], q: ca.SX, frame_ids: Sequence[int]
) -> list[tuple[ca.SX, ca.SX, ca.SX]]:
    """Per frame its rotation (3, 3), position (3,) [m] and Jacobian (6, nv) (linear velocity of the frame's
    origin and angular velocity, root axes: pinocchio's LOCAL_WORLD_ALIGNED) as SX expressions of ``q``."""
    n = model.nv
    rotations: list[ca.SX] = [ca.SX.eye(3)]
    origins: list[ca.SX] = [ca.SX.zeros(3)]
    world_axes: list[ca.SX | None] = [None]
    for i in range(1, model.njoints):
        kind, axis = axes[i - 1]
        placement, parent = model.jointPlacements[i], model.parents[i]
        R = ca.mtimes(rotations[parent], ca.DM(placement.rotation))
        p = origins[parent] + ca.mtimes(rotations[parent], ca.DM(placement.translation))
        qi = q[model.joints[i].idx_v]
        if kind == "revolute":
            K = _skew(axis)  # Rodrigues: I + sin(q) K + (1 - cos(q)) K²
            R_joint = ca.DM(np.eye(3)) + ca.sin(qi) * ca.DM(K) + (1.0 - ca.cos(qi)) * ca.DM(K @ K)
            rotations.append(ca.mtimes(R, R_joint))
            origins.append(p)
        else:
            rotations.append(R)
            origins.append(p + qi * ca.mtimes(R, ca.DM(axis)))
        world_axes.append(ca.mtimes(R, ca.DM(axis)))
    out = []
    for fid in frame_ids:
        frame = model.frames[fid]
        joint = frame.parentJoint
        R = ca.mtimes(rotations[joint], ca.DM(frame.placement.rotation))
        p = origins[joint] + ca.mtimes(rotations[joint], ca.DM(frame.placement.translation))
        J = ca.SX.zeros(6, n)
        for k in model.supports[joint]:
            if k == 0:
                continue
            col = model.joints[k].idx_v
            if axes[k - 1][0] == "revolute":
                J[:3, col] = ca.cross(world_axes[k], p - origins[k])
                J[3:, col] = world_axes[k]
            else:
                J[:3, col] = world_axes[k]
        out.append((R, p, J))
    return out


def log3(M: ca.SX) -> tuple[ca.SX, ca.SX]:
    """Rotation vector ω (3,) [rad] and angle θ of a rotation matrix (accurate for θ < π - 1e-4; the kernel hands
    larger angles to pinocchio's ``log3``)."""
    vee = ca.vertcat(M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1])  # 2 sin θ · axis
    sin2 = ca.norm_2(vee)
    cos2 = M[0, 0] + M[1, 1] + M[2, 2] - 1.0
    theta = ca.atan2(sin2, cos2)
    factor = ca.if_else(theta < _SMALL_ANGLE, 0.5 + theta * theta / 12.0, theta / ca.fmax(sin2, 1e-300))
    return factor * vee, theta


def jlog3(theta: ca.SX, omega: ca.SX) -> ca.SX:
    """pinocchio's ``Jlog3`` (the inverse right Jacobian of SO(3)) from the angle and rotation vector of ``log3``:
    ``d I + β ω ωᵀ + ½ [ω]×`` with ``d = θ sin θ / (2 (1 - cos θ))`` and ``β = 1/θ² - sin θ / (2 θ (1 - cos θ))``."""
    small = theta < _SMALL_ANGLE
    t = ca.fmax(theta, _SMALL_ANGLE)
    half_sine = ca.sin(0.5 * t)
    s, one_minus_c = ca.sin(t), 2.0 * half_sine * half_sine  # 1 - cos θ without cancellation
    diagonal = ca.if_else(small, 1.0 - theta * theta / 12.0, t * s / (2.0 * one_minus_c))
    beta = ca.if_else(small, 1.0 / 12.0 + theta * theta / 720.0, 1.0 / (t * t) - s / (2.0 * t * one_minus_c))
    half = 0.5 * omega
    skew = ca.vertcat(
        ca.horzcat(0.0, -half[2], half[1]),
        ca.horzcat(half[2], 0.0, -half[0]),
        ca.horzcat(-half[1], half[0], 0.0),
    )
    return diagonal * ca.SX.eye(3) + beta * ca.mtimes(omega, omega.T) + skew


def cholesky_solve(H: ca.SX, B: ca.SX) -> tuple[ca.SX, ca.SX]:
    """``X = H⁻¹ B`` for symmetric positive definite ``H`` (n, n) by Cholesky, and the smallest squared pivot (<= 0
    when ``H`` is not positive definite: X is then not valid)."""
    n = H.shape[0]
    L = [[ca.SX(0.0)] * n for _ in range(n)]
    pivots = []
    for j in range(n):
        pivot = H[j, j] - sum((L[j][k] * L[j][k] for k in range(j)), ca.SX(0.0))
        pivots.append(pivot)
        L[j][j] = ca.sqrt(pivot)
        for i in range(j + 1, n):
            L[i][j] = (H[i, j] - sum((L[i][k] * L[j][k] for k in range(j)), ca.SX(0.0))) / L[j][j]
    columns = []
    for c in range(B.shape[1]):
        y = [ca.SX(0.0)] * n
        for i in range(n):
            y[i] = (B[i, c] - sum((L[i][k] * y[k] for k in range(i)), ca.SX(0.0))) / L[i][i]
        x = [ca.SX(0.0)] * n
        for i in reversed(range(n)):
            x[i] = (y[i] - sum((L[k][i] * x[k] for k in range(i + 1, n)), ca.SX(0.0))) / L[i][i]
        columns.append(ca.vertcat(*x))
    return ca.horzcat(*columns), ca.mmin(ca.vertcat(*pivots))
