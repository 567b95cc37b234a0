"""The native IK kernel: its SX building blocks against independent computations, its fallbacks, and steps equal to
the numpy path's (the full problem comparison is in tests/test_ik_fused.py)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

import taplan
from taplan.ik import DifferentialIK, _native
from taplan.ik._kernel import step_function
from taplan.ik._kernel_math import cholesky_solve, frame_kinematics, jlog3, joint_axes, log3
from taplan.ik._native import native_enabled

needs_compiler = pytest.mark.skipif(not native_enabled(), reason="no C compiler: numpy path only")


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _rotation(rng: np.random.Generator, angle: float) -> np.ndarray:
    axis = rng.normal(size=3)
    return pin.exp3(angle * axis / np.linalg.norm(axis))


def _chain_model() -> pin.Model:
    """Revolute (aligned and unaligned) and prismatic joints with offsets: the joint kinds the kernel supports."""
    model = pin.Model()
    rng = np.random.default_rng(0)
    parent = 0
    joints = [
        pin.JointModelRZ(),
        pin.JointModelPY(),
        pin.JointModelRevoluteUnaligned(np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])),
        pin.JointModelPrismaticUnaligned(np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)),
        pin.JointModelRX(),
    ]
    for i, joint in enumerate(joints):
        placement = pin.SE3(_rotation(rng, 0.7), rng.uniform(-0.2, 0.2, 3))
        parent = model.addJoint(parent, joint, placement, f"j{i}")
    model.addFrame(pin.Frame("tip", parent, pin.SE3(_rotation(rng, 0.4), np.array([0.1, 0.0, 0.05])), pin.OP_FRAME))
    return model


# ----------------------------------------------------------------------------------------------- building blocks
@pytest.mark.parametrize("which", ["teleavatar", "mixed-chain"])
def test_frame_kinematics_match_pinocchio(robot, which):
    model = robot.model if which == "teleavatar" else _chain_model()
    frames = [robot.frame_id("left_ee"), robot.frame_id("right_ee")] if which == "teleavatar" else [model.nframes - 1]
    axes = joint_axes(model)
    assert axes is not None
    q = ca.SX.sym("q", model.nv)
    f = ca.Function("fk", [q], [x for frame in frame_kinematics(model, axes, q, frames) for x in frame])
    data = model.createData()
    rng = np.random.default_rng(1)
    for _ in range(20):
        qv = rng.uniform(-3.0, 3.0, model.nv)
        pin.computeJointJacobians(model, data, qv)
        pin.updateFramePlacements(model, data)
        values = f(qv)
        for i, fid in enumerate(frames):
            R, p, J = (np.array(v) for v in values[3 * i : 3 * i + 3])
            np.testing.assert_allclose(R, data.oMf[fid].rotation, atol=1e-12)
            np.testing.assert_allclose(p.ravel(), data.oMf[fid].translation, atol=1e-12)  # [m]
            reference = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
            np.testing.assert_allclose(J, reference, atol=1e-12)


def test_unsupported_joints_leave_the_numpy_path():
    model = pin.Model()
    parent = model.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "ball")
    model.addJoint(parent, pin.JointModelRZ(), pin.SE3.Identity(), "hinge")
    assert joint_axes(model) is None
    assert step_function(model, [0], acceleration=True, braking=True) is None


def _series_jlog3(omega: np.ndarray) -> np.ndarray:
    """Inverse of the right Jacobian of SO(3), ``Jr = Σ_k (-[ω]×)^k / (k+1)!``, summed to float64 precision (an
    independent reference for small angles, where the closed forms cancel)."""
    K = -pin.skew(omega)
    term, total = np.eye(3), np.eye(3)
    for k in range(1, 30):
        term = term @ K / (k + 1)
        total = total + term
    return np.linalg.inv(total)


def test_log3_and_jlog3_are_exact_at_every_angle():
    M = ca.SX.sym("M", 3, 3)
    omega, theta = log3(M)
    f = ca.Function("f", [M], [omega, theta, jlog3(theta, omega)])
    rng = np.random.default_rng(2)
    for angle in [0.0, 1e-12, 1e-8, 1e-6, 1.7e-4, 9.9e-4, 1.01e-3, 1e-2, 0.3, 1.0, 2.0, 3.0, np.pi - 2e-4]:
        R = _rotation(rng, angle)
        w, t, J = (np.array(v) for v in f(R))
        np.testing.assert_allclose(w.ravel(), pin.log3(R), atol=1e-12)  # [rad]
        assert abs(t.item() - np.linalg.norm(pin.log3(R))) <= 1e-12
        reference = _series_jlog3(pin.log3(R)) if angle < 0.1 else pin.Jlog3(R)
        np.testing.assert_allclose(J, reference, atol=1e-13)


def test_pinocchio_jlog3_is_the_less_accurate_one_at_small_angles():
    """Why the native comparisons allow 1e-7: pinocchio's Jlog3 loses digits between 1e-8 and 1e-3 rad."""
    rng = np.random.default_rng(3)
    R = _rotation(rng, 1.7e-4)
    exact = _series_jlog3(pin.log3(R))
    M = ca.SX.sym("M", 3, 3)
    omega, theta = log3(M)
    ours = np.array(ca.Function("f", [M], [jlog3(theta, omega)])(R))
    assert np.abs(ours - exact).max() < 1e-14
    assert np.abs(pin.Jlog3(R) - exact).max() < 1e-7  # the allowance of tests/test_ik_fused.py


def test_cholesky_solve_matches_numpy():
    rng = np.random.default_rng(4)
    n = 9
    H = ca.SX.sym("H", n, n)
    B = ca.SX.sym("B", n, 2)
    X, pivot = cholesky_solve(H, B)
    f = ca.Function("f", [H, B], [X, pivot])
    A = rng.normal(size=(n, n))
    Hv = A @ A.T + 0.1 * np.eye(n)
    Bv = rng.normal(size=(n, 2))
    Xv, pv = f(Hv, Bv)
    np.testing.assert_allclose(np.array(Xv), np.linalg.solve(Hv, Bv), rtol=1e-10, atol=1e-12)
    assert float(pv) > 0.0
    _, pv = f(-Hv, Bv)
    assert float(pv) <= 0.0  # not positive definite: reported, so the builder uses numpy


# -------------------------------------------------------------------------------------------- the native stepper
@needs_compiler
def test_native_steps_equal_numpy_steps_and_errors(robot):
    native = DifferentialIK(robot, solver="daqp")
    reference = DifferentialIK(robot, solver="daqp", native=False)
    assert native.builder.native and not reference.builder.native
    rng = np.random.default_rng(5)
    for k in range(150):
        targets = {}
        for frame in ("left_ee", "right_ee"):
            T = robot.frame_pose(robot.home, frame)
            T[:3, 3] += 0.05 * np.array([np.cos(0.05 * k), np.sin(0.05 * k), 0.0]) + rng.normal(0.0, 1e-3, 3)
            # turned too: a joint exactly at its target (e.g. the tool roll) has its braking side set by rounding
            T[:3, :3] = pin.exp3(rng.normal(0.0, 0.02, 3)) @ T[:3, :3]
            targets[frame] = T
        a, b = native.step(targets), reference.step(targets)
        # at k = 0 the targets' estimated motion is their jump from the held pose, so v_ff = v_free and every
        # joint's braking side is set by rounding (a tie either side may take): compare from k = 1
        if k > 0:
            np.testing.assert_allclose(a.velocity, b.velocity, atol=1e-7)  # [rad/s]
        ea, eb = native.step_errors(), reference.step_errors()
        for frame in ea:
            np.testing.assert_allclose(ea[frame], eb[frame], atol=1e-9)  # [m], [rad]
        native._q[:], native._v[:] = reference._q, reference._v
    assert native.builder.native_steps == 150


@needs_compiler
def test_orientation_error_near_pi_is_left_to_pinocchio(robot):
    ik = DifferentialIK(robot, solver="daqp")
    reference = DifferentialIK(robot, solver="daqp", native=False)
    T = robot.frame_pose(robot.home, "left_ee")
    T[:3, :3] = T[:3, :3] @ pin.exp3(np.array([0.0, 0.0, np.pi - 1e-5]))  # half a turn about the tool axis
    a, b = ik.step({"left_ee": T}), reference.step({"left_ee": T})
    assert ik.builder.native_steps == 0  # the kernel flagged the step; numpy built it
    np.testing.assert_allclose(a.velocity, b.velocity, atol=1e-12)
    assert not ik.kin.stale  # the numpy path evaluated pinocchio's data


@needs_compiler
def test_collision_screening_in_the_kernel_matches_numpy(robot):
    ik = DifferentialIK(robot, solver="daqp")
    collision = ik.collision
    assert collision is not None
    rng = np.random.default_rng(6)
    q = robot.home.copy()
    compared = 0
    for _ in range(60):
        q = np.clip(q + rng.normal(0.0, 2e-3, robot.nq), robot.planning_limits.lower, robot.planning_limits.upper)
        ik.step(q=q)
        travel, closest = ik.builder._screen.tolist()
        ref_travel, ref_closest = collision.screen(ik.builder._ctx)
        # the numpy screening reads the buffers as the step left them; when the step re-evaluated the pairs they
        # changed after the kernel read them, so compare only steps that skipped the evaluation
        if collision._q_eval[0] != q[0]:
            assert travel == pytest.approx(ref_travel, rel=1e-12, abs=1e-15)  # [m]
            assert closest == pytest.approx(ref_closest, rel=1e-12)  # [m]
            compared += 1
    assert compared > 30  # most steps were screened without re-evaluating the pairs


def test_native_can_be_switched_off(robot, monkeypatch):
    assert not DifferentialIK(robot, native=False).builder.native
    monkeypatch.setenv("TAPLAN_NATIVE", "0")
    assert not native_enabled()
    assert not DifferentialIK(robot).builder.native


def test_a_failing_compiler_warns_and_keeps_numpy(robot, monkeypatch, tmp_path):
    monkeypatch.setenv("TAPLAN_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", "false")  # exists, exits 1
    monkeypatch.setattr(_native, "_by_function", {})  # forget the libraries this process already loaded
    monkeypatch.setattr(_native, "_loaded", {})
    with pytest.warns(RuntimeWarning, match="using the numpy path"):
        ik = DifferentialIK(robot)
    assert not ik.builder.native
    ik.step()  # and it still steps
