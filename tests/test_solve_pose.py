"""solve_pose: convergence on seeded FK targets, honest success flags, limits, restarts, bad inputs, the step model."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import taplan
from taplan.errors import InvalidInputError, TaplanError, UnknownNameError
from taplan.ik import IKResult, Kinematics, solve_pose
from taplan.ik._pose_step import PoseStep
from taplan.ik.solvers import get_solver

TOL_P = 1e-3  # [m], default position tolerance
TOL_R = 1e-2  # [rad], default orientation tolerance
POS_TOL = 1e-12  # [rad], joint limits must hold exactly (the step is clipped)
ERR_TOL = 1e-12  # [m]/[rad], reported vs independently recomputed errors
SEED_TOL = 1e-9  # [rad], same seed -> same result up to the QP backend's floating-point order
FRAMES = ("left_ee", "right_ee")


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _random_q(robot: taplan.Robot, rng: np.random.Generator) -> np.ndarray:
    lim = robot.planning_limits
    return rng.uniform(lim.lower, lim.upper)


def _errors(robot: taplan.Robot, q: np.ndarray, frame: str, T: np.ndarray) -> tuple[float, float]:
    """Independent check: distance [m] and rotation angle [rad] from the frame at q to T."""
    F = robot.frame_pose(q, frame)
    return float(np.linalg.norm(F[:3, 3] - T[:3, 3])), float(np.linalg.norm(pin.log3(F[:3, :3] @ T[:3, :3].T)))


def _check_honest(robot: taplan.Robot, res: IKResult, targets: dict, tol=(TOL_P, TOL_R)) -> None:
    """Reported errors are the true ones at res.q, and success is exactly 'every error within tolerance'."""
    assert robot.planning_limits.within(res.q, POS_TOL)
    met = True
    for frame, T in targets.items():
        p, r = _errors(robot, res.q, frame, T)
        assert res.position_error[frame] == pytest.approx(p, abs=ERR_TOL)
        assert res.orientation_error[frame] == pytest.approx(r, abs=ERR_TOL)
        met = met and p <= tol[0] and r <= tol[1]
    assert res.success == met


@pytest.mark.parametrize("frame", FRAMES)
def test_converges_on_one_arm_targets_and_keeps_the_other_arm(robot, frame):
    rng = np.random.default_rng(11 if frame == "left_ee" else 12)
    other = robot.group("right" if frame == "left_ee" else "left").indices
    for _ in range(15):
        T = robot.frame_pose(_random_q(robot, rng), frame)
        res = solve_pose(robot, {frame: T}, robot.home)
        assert res.success
        _check_honest(robot, res, {frame: T})
        np.testing.assert_array_equal(res.q[other], robot.home[other])  # no target depends on them


def test_converges_on_both_arms_at_once(robot):
    rng = np.random.default_rng(13)
    for _ in range(10):
        q_goal = _random_q(robot, rng)
        targets = {f: robot.frame_pose(q_goal, f) for f in FRAMES}
        res = solve_pose(robot, targets, robot.home)
        assert res.success
        _check_honest(robot, res, targets)


@pytest.mark.parametrize("second_order", [True, False])
def test_first_and_second_order_steps_both_converge(robot, second_order):
    rng = np.random.default_rng(14)
    for k in range(10):
        frame = FRAMES[k % 2]
        T = robot.frame_pose(_random_q(robot, rng), frame)
        res = solve_pose(robot, {frame: T}, robot.home, second_order=second_order)
        assert res.success
        _check_honest(robot, res, {frame: T})


def test_second_order_needs_fewer_iterations_on_seeded_targets(robot):
    """The curvature correction's purpose, on a fixed seeded set (a count of steps, not a timing)."""
    rng = np.random.default_rng(2026)
    first, second = [], []
    for k in range(40):
        frame = FRAMES[k % 2]
        T = robot.frame_pose(_random_q(robot, rng), frame)
        first.append(solve_pose(robot, {frame: T}, robot.home, second_order=False).iterations)
        second.append(solve_pose(robot, {frame: T}, robot.home).iterations)
    assert np.median(second) < np.median(first)


def test_success_is_never_reported_beyond_the_tolerance(robot):
    """With budgets too small to always converge, every result's flag matches the independently checked errors."""
    rng = np.random.default_rng(15)
    flags = []
    for k in range(30):
        frame = FRAMES[k % 2]
        T = robot.frame_pose(_random_q(robot, rng), frame)
        tol = (2e-4, 2e-3) if k % 3 else (TOL_P, TOL_R)
        res = solve_pose(robot, {frame: T}, robot.home, max_iterations=2, restarts=0, tolerance=tol)
        _check_honest(robot, res, {frame: T}, tol)
        assert res.iterations <= 2
        flags.append(res.success)
    assert 0 < sum(flags) < len(flags)  # both outcomes were exercised


def test_target_already_met_takes_no_iteration(robot):
    targets = {f: robot.frame_pose(robot.home, f) for f in FRAMES}
    res = solve_pose(robot, targets, robot.home)
    assert res.success and res.iterations == 0 and res.restarts == 0
    np.testing.assert_array_equal(res.q, robot.home)


def test_unreachable_target_is_reported_honestly(robot):
    T = robot.frame_pose(robot.home, "right_ee")
    T[:3, 3] = [0.0, -2.0, 0.5]  # [m], far outside the workspace
    res = solve_pose(robot, {"right_ee": T}, robot.home, max_iterations=20, restarts=2)
    assert not res.success
    assert res.restarts == 2
    assert res.iterations > 0
    assert res.position_error["right_ee"] > 1.0
    _check_honest(robot, res, {"right_ee": T})


def test_restarts_are_seeded(robot):
    T = robot.frame_pose(robot.home, "left_ee")
    T[:3, 3] += [0.0, 0.0, 3.0]  # [m], unreachable: every restart is used
    a = solve_pose(robot, {"left_ee": T}, robot.home, max_iterations=5, restarts=3, seed=4)
    b = solve_pose(robot, {"left_ee": T}, robot.home, max_iterations=5, restarts=3, seed=4)
    np.testing.assert_allclose(a.q, b.q, atol=SEED_TOL)
    assert a.iterations == b.iterations


def test_start_outside_the_limits_is_clipped_and_the_result_stays_inside(robot):
    rng = np.random.default_rng(16)
    lim = robot.planning_limits
    q0 = lim.upper + 0.01  # [rad], just outside (inside the hardware limits)
    T = robot.frame_pose(_random_q(robot, rng), "left_ee")
    res = solve_pose(robot, {"left_ee": T}, q0)
    assert res.success
    _check_honest(robot, res, {"left_ee": T})


def test_other_backends_and_pose_formats(robot):
    rng = np.random.default_rng(17)
    T = robot.frame_pose(_random_q(robot, rng), "right_ee")
    quat = pin.Quaternion(T[:3, :3]).coeffs()  # xyzw
    for solver in ("daqp", get_solver("quadprog")):
        res = solve_pose(robot, {"right_ee": (T[:3, 3], quat)}, robot.home, solver=solver)
        assert res.success
        _check_honest(robot, res, {"right_ee": T})


def test_collision_option_keeps_the_arms_apart(robot):
    """Targets from a configuration where the arms are apart: met with the arms' capsules never crossing."""
    from taplan.ik.limits import capsule_pair_distance

    rng = np.random.default_rng(18)
    kin = Kinematics(robot.model)
    pairs = robot.capsule_pairs("left", "right")
    for _ in range(3):
        while True:
            q_goal = _random_q(robot, rng)
            kin.update(q_goal)
            if min(capsule_pair_distance(kin, a, b)[0] for a, b in pairs) > 0.1:  # [m]
                break
        targets = {f: robot.frame_pose(q_goal, f) for f in FRAMES}
        res = solve_pose(robot, targets, robot.home, collision=True)
        _check_honest(robot, res, targets)
        kin.update(res.q)
        assert min(capsule_pair_distance(kin, a, b)[0] for a, b in pairs) > 0.0


def test_second_order_model_matches_the_kinematics_to_third_order(robot):
    """The correction r(v) = e(q + v) - e(q) - J v up to O(|v|³): halving v cuts the mismatch about 8 times."""
    rng = np.random.default_rng(19)
    q = _random_q(robot, rng)
    T = robot.frame_pose(_random_q(robot, rng), "left_ee")
    target = pin.SE3(T[:3, :3], T[:3, 3])
    kin = Kinematics(robot.model)
    lim = robot.planning_limits
    step = PoseStep(
        kin, [robot.frame_id("left_ee")], [target], lim.lower, lim.upper, 1.0, 0.0, q, 0.0, True, 1.0, [], None
    )
    direction = rng.normal(size=robot.nq)
    mismatch = []
    for scale in (0.02, 0.01):  # [rad]
        v = scale * direction
        step.evaluate(q)
        e, J = step.linearise()
        r = step.model_residual(v)
        e_true = pin.log6(target.actInv(pin.SE3(robot.frame_pose(q + v, "left_ee")))).vector
        mismatch.append(np.linalg.norm(e + J @ v + r - e_true))
    assert mismatch[1] < mismatch[0] / 6.0


@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"targets": {}}, InvalidInputError),
        ({"targets": "left_ee"}, InvalidInputError),
        ({"targets": {"nope": np.eye(4)}}, UnknownNameError),
        ({"targets": {"left_ee": np.full((4, 4), np.nan)}}, InvalidInputError),
        ({"q0": np.zeros(3)}, InvalidInputError),
        ({"tolerance": (0.0, 1e-2)}, InvalidInputError),
        ({"tolerance": "tight"}, InvalidInputError),
        ({"max_iterations": 0}, InvalidInputError),
        ({"max_iterations": 2.5}, InvalidInputError),
        ({"restarts": -1}, InvalidInputError),
        ({"max_step": 0.0}, InvalidInputError),
        ({"posture_cost": -1.0}, InvalidInputError),
        ({"lm_damping": np.inf}, InvalidInputError),
        ({"solver": "nope"}, UnknownNameError),
        ({"limits": "planning"}, InvalidInputError),
    ],
)
def test_bad_inputs_raise_taplan_errors(robot, kwargs, error):
    args = {"targets": {"left_ee": robot.frame_pose(robot.home, "left_ee")}, **kwargs}
    with pytest.raises(error) as info:
        solve_pose(robot, args.pop("targets"), **args)
    assert isinstance(info.value, TaplanError)
