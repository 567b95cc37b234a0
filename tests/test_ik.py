"""Differential IK: Jacobians, each limit's effect, seeded sweeps, bad inputs, solve_pose."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import taplan
from taplan.errors import InvalidInputError, SolverError, UnknownNameError
from taplan.ik import (
    DifferentialIK,
    FrameTask,
    Kinematics,
    PostureTask,
    RelativeFrameTask,
    VelocityLimit,
    available_solvers,
    build_ik,
    solve_ik,
    solve_pose,
)
from taplan.ik.limits import capsule_pair_distance
from taplan.scene.capsules import capsule_distance

FD_STEP = 1e-6  # [rad]
JAC_TOL = 1e-5  # [m]/[rad] and [rad]/[rad], finite differences vs analytic
VEL_TOL = 1e-9  # [rad]/[s]
ACC_REL_TOL = 1e-9  # relative to the acceleration limit
POS_TOL = 1e-9  # [rad]
DIST_TOL = 2e-4  # [m], linearisation error allowed below the collision margin in one step
DT = 0.01  # [s]


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _random_q(robot: taplan.Robot, rng: np.random.Generator, outside: float = 0.0) -> np.ndarray:
    lim = robot.planning_limits
    span = lim.upper - lim.lower
    return rng.uniform(lim.lower - outside * span, lim.upper + outside * span)


def _fd_jacobian(f, q: np.ndarray) -> np.ndarray:
    cols = []
    for i in range(q.size):
        dq = np.zeros(q.size)
        dq[i] = FD_STEP
        cols.append((f(q + dq) - f(q - dq)) / (2 * FD_STEP))
    return np.stack(cols, axis=-1)


# ------------------------------------------------------------------------------------------------------ Jacobians
@pytest.mark.parametrize("frame", ["left_ee", "right_tcp"])
def test_frame_task_jacobian_matches_finite_differences(robot, rng, frame):
    kin = Kinematics(robot.model)
    task = FrameTask(robot.frame_id(frame))
    for _ in range(3):
        q = _random_q(robot, rng)
        task.set_target(robot.frame_pose(_random_q(robot, rng), frame))

        def err(x):
            kin.update(x)
            return task.compute_error(kin)

        kin.update(q)
        np.testing.assert_allclose(task.compute_jacobian(kin), _fd_jacobian(err, q), atol=JAC_TOL)


def test_frame_task_fill_matches_error_and_jacobian(robot, rng):
    kin = Kinematics(robot.model)
    task = FrameTask(robot.frame_id("left_ee"), position_cost=[1.0, 2.0, 3.0], orientation_cost=0.5, gain=0.7)
    task.set_target(robot.frame_pose(_random_q(robot, rng), "left_ee"))
    kin.update(_random_q(robot, rng))
    A, b = np.empty((6, robot.nq)), np.empty(6)
    task.fill(kin, A, b)
    w = np.array([1.0, 2.0, 3.0, 0.5, 0.5, 0.5])
    np.testing.assert_allclose(A, w[:, None] * task.compute_jacobian(kin), atol=1e-12)
    np.testing.assert_allclose(b, -0.7 * w * task.compute_error(kin), atol=1e-12)


def test_relative_frame_task_jacobian_matches_finite_differences(robot, rng):
    kin = Kinematics(robot.model)
    task = RelativeFrameTask(robot.frame_id("left_ee"), robot.frame_id("right_ee"))
    task.set_target(robot.relative_pose(_random_q(robot, rng), "left_ee", "right_ee"))
    q = _random_q(robot, rng)

    def err(x):
        kin.update(x)
        return task.compute_error(kin)

    kin.update(q)
    np.testing.assert_allclose(task.compute_jacobian(kin), _fd_jacobian(err, q), atol=JAC_TOL)


def test_collision_distance_jacobian_matches_finite_differences(robot, rng):
    kin = Kinematics(robot.model)
    checked = 0
    for first, second in robot.capsule_pairs("left", "right"):
        q = _random_q(robot, rng)

        def dist(x, first=first, second=second):
            kin.update(x)
            return np.array([capsule_pair_distance(kin, first, second)[0]])

        kin.update(q)
        d, grad, pa, pb = capsule_pair_distance(kin, first, second)
        assert d == pytest.approx(capsule_distance(kin.data, first, second))
        np.testing.assert_allclose(grad, _fd_jacobian(dist, q)[0], atol=JAC_TOL)
        checked += 1
    assert checked == len(robot.capsule_pairs("left", "right")) == 106  # the arm-arm pairs the SRDF keeps


# ------------------------------------------------------------------------------------------------- limit effects
def _shifted(robot, q, frame, offset):
    T = robot.frame_pose(q, frame)
    T[:3, 3] += offset
    return T


def test_velocity_limit_has_effect(robot):
    q = robot.home
    target = {"left_ee": _shifted(robot, q, "left_ee", [0.0, 0.0, 0.2])}
    kin = Kinematics(robot.model)
    task = FrameTask(robot.frame_id("left_ee"))
    task.set_target(target["left_ee"])
    posture = PostureTask(robot.nq, 1e-2, q)
    vmax = np.full(robot.nq, 0.5)  # [rad/s]
    free = solve_ik(build_ik(kin, q, [task, posture], [], DT, damping=1e-3))
    limited = solve_ik(build_ik(kin, q, [task, posture], [VelocityLimit(vmax)], DT, damping=1e-3))
    assert np.abs(free).max() > 2 * vmax.max()
    assert np.all(np.abs(limited) <= vmax + VEL_TOL)


def test_acceleration_limit_has_effect(robot):
    q = robot.home
    target = {"left_ee": _shifted(robot, q, "left_ee", [0.0, 0.0, 0.1])}
    lim = robot.planning_limits
    on = DifferentialIK(robot, dt=DT, collision=False, acceleration_limit=True)
    off = DifferentialIK(robot, dt=DT, collision=False, acceleration_limit=False)
    v_on = on.step(target).velocity
    v_off = off.step(target).velocity
    assert np.all(np.abs(v_on) <= lim.acceleration * DT * (1 + ACC_REL_TOL))
    assert np.any(np.abs(v_off) > 2 * lim.acceleration * DT)


def test_position_limit_braking_has_effect(robot):
    """Near the upper bound of a joint and moving toward it, braking slows it down before the bound."""
    lim = robot.planning_limits
    q = robot.home
    j = 3  # l_joint4
    q[j] = lim.upper[j] - 0.01
    v0 = np.zeros(robot.nq)
    v0[j] = 0.3  # [rad/s], slow enough that braking can still stop before the bound
    kin = Kinematics(robot.model)
    posture = PostureTask(robot.nq, 1.0, q + np.where(np.arange(robot.nq) == j, 1.0, 0.0))  # pulls past the bound
    from taplan.ik import AccelerationLimit, PositionLimit

    plain = solve_ik(
        build_ik(kin, q, [posture], [PositionLimit(lim.lower, lim.upper), AccelerationLimit(lim.acceleration)], DT, v0)
    )
    braking = solve_ik(
        build_ik(
            kin,
            q,
            [posture],
            [PositionLimit(lim.lower, lim.upper, lim.acceleration), AccelerationLimit(lim.acceleration)],
            DT,
            v0,
        )
    )
    assert braking[j] < plain[j] - 1e-3
    # the braking step stays able to stop before the bound
    remaining = lim.upper[j] - (q[j] + braking[j] * DT)
    assert braking[j] ** 2 / (2 * lim.acceleration[j]) <= remaining + POS_TOL


def test_collision_limit_has_effect(robot):
    """Both hands pushed through the sagittal plane: with avoidance the arms stay apart."""
    q = robot.home
    targets = {
        "left_ee": _shifted(robot, q, "left_ee", [0.0, -0.45, 0.0]),
        "right_ee": _shifted(robot, q, "right_ee", [0.0, 0.45, 0.0]),
    }
    margin = 0.02  # [m]

    def run(collision):
        ik = DifferentialIK(robot, dt=DT, collision=collision, collision_margin=margin)
        kin = Kinematics(robot.model)
        dmin = np.inf
        for _ in range(300):
            out = ik.step(targets)
            kin.update(out.q)
            d = min(capsule_pair_distance(kin, a, b)[0] for a, b in robot.capsule_pairs("left", "right"))
            dmin = min(dmin, d)
        return dmin

    assert run(False) < 0.0  # they would collide
    assert run(True) >= margin - DIST_TOL


def test_target_braking_prevents_overshoot(robot):
    q = robot.home
    step = np.array([0.0, 0.0, 0.15])  # [m]
    target = {"left_ee": _shifted(robot, q, "left_ee", step)}
    start = robot.frame_pose(q, "left_ee")[:3, 3]
    direction = step / np.linalg.norm(step)

    def overshoot(braking):
        ik = DifferentialIK(robot, dt=0.002, collision=False, target_braking=braking, frames=("left_ee",))
        worst = -np.inf
        for _ in range(1500):
            out = ik.step(target)
            p = robot.frame_pose(out.q, "left_ee")[:3, 3]
            worst = max(worst, float((p - start) @ direction) - np.linalg.norm(step))
        return worst

    assert overshoot(False) > 5e-3  # [m]
    assert overshoot(True) <= 1e-3  # [m]


CIRCLE_RADIUS = 0.05  # [m]
CIRCLE_FREQUENCY = 0.5  # [Hz]
TRACKING_LAG_TOL = 2e-3  # [m], both hands on 5 cm circles with acceleration limits (11 mm if braking ignores motion)


def _circle_targets(robot, t):
    w = 2 * np.pi * CIRCLE_FREQUENCY * t
    out = {}
    for f in ("left_ee", "right_ee"):
        T = robot.frame_pose(robot.home, f)
        T[:3, 3] += CIRCLE_RADIUS * np.array([0.0, np.cos(w) - 1.0, np.sin(w)])
        out[f] = T
    return out


@pytest.mark.parametrize("dt", [0.01, 0.002])
def test_moving_target_is_tracked_with_small_lag_under_acceleration_limits(robot, dt):
    """Target braking is relative to the target's motion: acceleration-limited tracking lags by millimetres."""
    lim = robot.planning_limits
    ik = DifferentialIK(robot, dt=dt)
    n = int(round(3.0 / dt))
    settle = int(round(1.0 / dt))
    worst = 0.0
    v_prev = np.zeros(robot.nq)
    for k in range(n):
        targets = _circle_targets(robot, k * dt)
        out = ik.step(targets)
        assert np.all(np.abs(out.velocity - v_prev) <= lim.acceleration * dt * (1 + ACC_REL_TOL))
        assert np.all(np.abs(out.velocity) <= lim.velocity + VEL_TOL)
        v_prev = out.velocity
        if k >= settle:
            for f, T in targets.items():
                worst = max(worst, float(np.linalg.norm(robot.frame_pose(out.q, f)[:3, 3] - T[:3, 3])))
    assert worst <= TRACKING_LAG_TOL


def test_explicit_target_twist_feeds_forward(robot):
    """Given the targets' twists, the step aims at where the target will be: the pose one dt later is tracked."""
    dt = 0.01
    ik = DifferentialIK(robot, dt=dt)
    w = 2 * np.pi * CIRCLE_FREQUENCY
    worst_next = 0.0
    for k in range(300):
        t = k * dt
        twist = np.zeros(6)
        twist[1:3] = CIRCLE_RADIUS * w * np.array([-np.sin(w * t), np.cos(w * t)])
        out = ik.step(_circle_targets(robot, t), target_velocities={"left_ee": twist, "right_ee": twist})
        if k >= 100:
            nxt = _circle_targets(robot, t + dt)
            for f, T in nxt.items():
                worst_next = max(worst_next, float(np.linalg.norm(robot.frame_pose(out.q, f)[:3, 3] - T[:3, 3])))
    assert worst_next <= TRACKING_LAG_TOL
    with pytest.raises(InvalidInputError):
        ik.step(target_velocities={"left_ee": np.full(6, np.nan)})
    with pytest.raises(UnknownNameError):
        ik.step(target_velocities={"nope": np.zeros(6)})


def test_stopping_moving_target_is_not_overshot(robot):
    """A target moving at 0.1 m/s that stops smoothly (within what the arm can follow) is reached without overshoot."""
    dt = 0.002
    ik = DifferentialIK(robot, dt=dt, collision=False, frames=("left_ee",))
    start = robot.frame_pose(robot.home, "left_ee")
    direction = np.array([0.0, 0.0, 1.0])
    speed, decel, cruise = 0.1, 0.5, 0.5  # [m/s], [m/s²], [s]
    t_stop = cruise + speed / decel
    stop = speed * cruise + speed**2 / (2 * decel)  # [m] travelled by the target
    worst = -np.inf
    for k in range(int(round((t_stop + 1.5) / dt))):
        t = k * dt
        if t <= cruise:
            s = speed * t
        elif t <= t_stop:
            s = speed * cruise + speed * (t - cruise) - 0.5 * decel * (t - cruise) ** 2
        else:
            s = stop
        T = start.copy()
        T[:3, 3] += s * direction
        out = ik.step({"left_ee": T})
        worst = max(worst, float((robot.frame_pose(out.q, "left_ee")[:3, 3] - start[:3, 3]) @ direction) - stop)
    assert worst <= 1e-3  # [m]
    assert worst >= -1e-3  # and it got there


# --------------------------------------------------------------------------------------------------------- sweeps
@pytest.mark.parametrize("dt", [0.01, 0.002])
def test_sweep_limits_always_hold(robot, dt):
    """Random states (10 % outside the limits), random previous velocities within the limits, random targets."""
    rng = np.random.default_rng(7 if dt == 0.01 else 8)
    lim = robot.planning_limits
    ik = DifferentialIK(robot, dt=dt)
    kin = Kinematics(robot.model)
    pairs = robot.capsule_pairs("left", "right")
    margin = 0.02
    for _ in range(150):
        q = _random_q(robot, rng, outside=0.1 if rng.random() < 0.3 else 0.0)
        moving = rng.random() < 0.5
        v0 = rng.uniform(-lim.velocity, lim.velocity) * rng.random() if moving else np.zeros(robot.nq)
        ik.reset(q, v0)
        targets = {f: robot.frame_pose(_random_q(robot, rng), f) for f in ("left_ee", "right_ee") if rng.random() < 0.8}
        kin.update(q)
        d0 = min(capsule_pair_distance(kin, a, b)[0] for a, b in pairs)
        v_prev = v0
        for _ in range(2):
            out = ik.step(targets)
            assert np.all(np.isfinite(out.velocity)) and np.all(np.isfinite(out.q))
            assert np.all(np.abs(out.velocity) <= lim.velocity + VEL_TOL)
            assert np.all(np.abs(out.velocity - v_prev) <= lim.acceleration * dt * (1 + ACC_REL_TOL))
            v_prev = out.velocity
        if lim.within(q) and not moving:  # from rest within the limits, braking keeps it there
            assert lim.within(out.q, POS_TOL)
        kin.update(out.q)
        d1 = min(capsule_pair_distance(kin, a, b)[0] for a, b in pairs)
        if d0 >= margin and not moving:
            assert d1 >= margin - DIST_TOL


def test_rollouts_from_rest_keep_margin_and_limits(robot):
    rng = np.random.default_rng(11)
    lim = robot.planning_limits
    pairs = robot.capsule_pairs("left", "right")
    kin = Kinematics(robot.model)
    ik = DifferentialIK(robot, dt=0.01)
    for _ in range(6):
        ik.reset(robot.home)
        # targets that pull the hands toward and through each other
        targets = {
            "left_ee": _shifted(robot, robot.home, "left_ee", rng.uniform([-0.1, -0.6, -0.2], [0.2, -0.2, 0.2])),
            "right_ee": _shifted(robot, robot.home, "right_ee", rng.uniform([-0.1, 0.2, -0.2], [0.2, 0.6, 0.2])),
        }
        v_prev = np.zeros(robot.nq)
        for _ in range(150):
            out = ik.step(targets)
            assert np.all(np.abs(out.velocity - v_prev) <= lim.acceleration * 0.01 * (1 + ACC_REL_TOL))
            assert lim.within(out.q, POS_TOL)
            v_prev = out.velocity
            kin.update(out.q)
            assert min(capsule_pair_distance(kin, a, b)[0] for a, b in pairs) >= 0.02 - DIST_TOL


# ---------------------------------------------------------------------------------------------------- bad inputs
def test_bad_inputs_raise_taplan_errors(robot):
    ik = DifferentialIK(robot, dt=DT)
    T = robot.frame_pose(robot.home, "left_ee")
    with pytest.raises(UnknownNameError):
        ik.step({"nope": T})
    bad = T.copy()
    bad[0, 3] = np.nan
    with pytest.raises(InvalidInputError):
        ik.step({"left_ee": bad})
    bad[0, 3] = np.inf
    with pytest.raises(InvalidInputError):
        ik.step({"left_ee": bad})
    with pytest.raises(InvalidInputError):
        ik.step({"left_ee": np.eye(3)})
    with pytest.raises(InvalidInputError):
        ik.step({"left_ee": ([0.1, 0.2], [0, 0, 0, 1])})
    with pytest.raises(InvalidInputError):
        ik.step({"left_ee": ([0.1, 0.2, 0.3], [0, 0, 0, 0])})
    with pytest.raises(InvalidInputError):
        ik.step({"left_ee": T}, q=np.zeros(3))
    with pytest.raises(InvalidInputError):
        ik.reset(np.full(robot.nq, np.nan))
    with pytest.raises(InvalidInputError):
        ik.step("left_ee")  # type: ignore[arg-type]
    for dt in (0.0, -0.01, np.nan):
        with pytest.raises(InvalidInputError):
            DifferentialIK(robot, dt=dt)
    with pytest.raises(UnknownNameError):
        DifferentialIK(robot, frames=("nope",))
    with pytest.raises(UnknownNameError):
        DifferentialIK(robot, solver="nope")
    with pytest.raises(UnknownNameError):
        solve_pose(robot, {"nope": T})
    with pytest.raises(InvalidInputError):
        solve_pose(robot, {"left_ee": bad})


def test_position_quaternion_target_equals_matrix(robot):
    T = _shifted(robot, robot.home, "left_ee", [0.0, 0.0, 0.05])
    quat = pin.Quaternion(T[:3, :3]).coeffs()  # x, y, z, w
    a = DifferentialIK(robot, dt=DT).step({"left_ee": T})
    b = DifferentialIK(robot, dt=DT).step({"left_ee": (T[:3, 3], quat)})
    c = DifferentialIK(robot, dt=DT).step({"left_ee": np.concatenate([T[:3, 3], quat])})
    np.testing.assert_allclose(a.velocity, b.velocity, atol=1e-7)
    np.testing.assert_allclose(a.velocity, c.velocity, atol=1e-7)


def test_solver_failure_is_a_taplan_error_with_problem(robot):
    class Broken(taplan.ik.QPSolver):
        name = "broken"

        def solve(self, problem):
            return np.full(problem.nv, np.nan)

    ik = DifferentialIK(robot, dt=DT, solver=Broken())
    with pytest.raises(SolverError) as info:
        ik.step()
    assert info.value.problem is not None and info.value.problem.H.shape == (robot.nq, robot.nq)


# ------------------------------------------------------------------------------------------------------ backends
@pytest.mark.parametrize("solver", [s for s in available_solvers() if s != "proxqp"])
def test_backends_agree_with_proxqp(robot, rng, solver):
    q = robot.home
    targets = {f: _shifted(robot, q, f, rng.uniform(-0.05, 0.05, 3)) for f in ("left_ee", "right_ee")}
    v0 = rng.uniform(-0.2, 0.2, robot.nq)
    ref = DifferentialIK(robot, dt=DT, solver="proxqp")
    other = DifferentialIK(robot, dt=DT, solver=solver)
    ref.reset(q, v0)
    other.reset(q, v0)
    tol = 1e-4 if solver == "osqp" else 1e-6  # [rad]/[s]
    np.testing.assert_allclose(other.step(targets).velocity, ref.step(targets).velocity, atol=tol)


# ---------------------------------------------------------------------------------------------------- solve_pose
def test_solve_pose_converges_on_fk_targets(robot):
    rng = np.random.default_rng(3)
    for _ in range(10):
        q_goal = _random_q(robot, rng)
        targets = {f: robot.frame_pose(q_goal, f) for f in ("left_ee", "right_ee")}
        res = solve_pose(robot, targets, robot.home)
        assert res.success
        assert max(res.position_error.values()) <= 1e-3
        assert max(res.orientation_error.values()) <= 1e-2
        assert robot.planning_limits.within(res.q, POS_TOL)
        for f, T in targets.items():
            np.testing.assert_allclose(robot.frame_pose(res.q, f)[:3, 3], T[:3, 3], atol=1e-3)


def test_solve_pose_reports_unreachable_honestly(robot):
    T = robot.frame_pose(robot.home, "left_ee")
    T[:3, 3] = [2.0, 0.0, 0.0]  # [m], far outside the workspace
    res = solve_pose(robot, {"left_ee": T}, robot.home, max_iterations=30, restarts=1)
    assert not res.success
    assert res.position_error["left_ee"] > 0.5
    assert res.iterations > 0


# ------------------------------------------------------------------------------------------------------- shortcut
def test_shortcut_equals_the_qp_solution(robot):
    """Skipping the QP when the unconstrained minimiser is feasible gives the QP's own answer (it is exact)."""
    from taplan.ik import get_solver

    class Always(taplan.ik.QPSolver):  # a custom backend: never skipped
        name = "always"

        def __init__(self):
            self.inner = get_solver("proxqp")

        def solve(self, problem):
            return self.inner.solve(problem)

    fast = DifferentialIK(robot, dt=DT)
    slow = DifferentialIK(robot, dt=DT, solver=Always())
    for k in range(60):
        targets = {f: _shifted(robot, robot.home, f, [0.0, 0.03 * np.sin(0.1 * k), 0.02]) for f in ("left_ee",)}
        a, b = fast.step(targets), slow.step(targets)
        np.testing.assert_allclose(a.velocity, b.velocity, atol=1e-7)  # [rad/s], proxqp's tolerance
    assert slow.qp_solves == 60
    # This fast target keeps the arm at its acceleration limit (QPs on every step while it moves, since braking is
    # relative to the target's motion); then it holds still, the arm settles and the shortcut is taken: each
    # shortcut velocity is the optimum of the QP it skipped (solved here to a tight tolerance).
    tight = Always()
    tight.inner = get_solver("proxqp", eps_abs=1e-12)
    for _ in range(60):
        a = fast.step()
        np.testing.assert_allclose(a.velocity, solve_ik(a.problem.copy(), tight), atol=1e-7)  # [rad/s]
    assert fast.qp_solves < 120  # the shortcut was taken


@pytest.mark.parametrize("solver", [s for s in available_solvers() if s in ("quadprog", "osqp", "daqp")])
def test_backends_solve_boxes_pinned_to_one_point(solver):
    """A relaxed intersection can pin a joint (lower == upper); quadprog used to report "no solution" there."""
    from taplan.ik.problem import Problem
    from taplan.ik.solvers import get_solver

    rng = np.random.default_rng(5)
    n = 14
    c = rng.normal(size=n)
    lower, upper = -np.full(n, 0.5), np.full(n, 0.5)
    pinned = [1, 4, 9]
    lower[pinned] = upper[pinned] = rng.uniform(-0.3, 0.3, len(pinned))
    problem = Problem(np.eye(n), c, lower, upper, np.zeros((0, n)), np.zeros(0), DT, np.zeros(n), -c)
    v = get_solver(solver).solve(problem)
    # with H = I the optimum is the projection of -c onto the box (independent closed form)
    tol = 1e-5 if solver == "osqp" else 1e-9  # [rad/s]
    np.testing.assert_allclose(v, np.clip(-c, lower, upper), atol=tol)
