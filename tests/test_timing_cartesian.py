"""taplan.planning.cartesian: straight lines through IK, deviation checked independently, limits, errors."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import taplan
from taplan.errors import InfeasibleError, InvalidInputError, TimingError, UnknownNameError
from taplan.planning.cartesian import CartesianResult, cartesian_line, cartesian_offset, line_deviation
from taplan.timing import limit_usage

CHECK_RATE = 1000.0  # [Hz] independent FK sampling of the timed trajectories
DEVIATION_BOUND = 1e-4  # [m] stated bound for these lines (the default max_deviation is 1 mm)
ANGLE_BOUND = 1e-3  # [rad]
DEFAULT_LINE_DEVIATION = 1e-3  # [m] cartesian_line's default max_deviation
ENDPOINT_TOL = (1e-5, 1e-4)  # ([m], [rad]) goal reached
LIMIT_TOL = 1e-6  # relative
REST_TOL = 1e-9  # [rad]/[s] velocity at the ends
HELD_TOL = 0.0  # [rad] joints of a held arm do not move at all
READY = np.array([0.41, 1.16, -0.47, 0.90, 0.23, -0.15, 0.60, -0.50, -0.92, 0.52, -1.28, 0.32, 0.55, -0.52])


def fk_along(robot: taplan.Robot, traj: taplan.Trajectory, frame: str) -> tuple[np.ndarray, np.ndarray]:
    """Positions (k, 3) and rotations (k, 3, 3) of ``frame`` sampled at CHECK_RATE, via Robot.frame_pose."""
    t = traj.sample_times(CHECK_RATE)
    poses = np.array([robot.frame_pose(q, frame) for q in traj(t)])
    return poses[:, :3, 3], poses[:, :3, :3]


def distance_to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = b - a
    lam = np.clip((p - a) @ d / (d @ d), 0.0, 1.0)
    return np.linalg.norm(p - (a + lam[:, None] * d), axis=1), lam


@pytest.fixture(scope="module")
def both_down(teleavatar: taplan.Robot) -> tuple[CartesianResult, dict[str, np.ndarray]]:
    start = teleavatar.frame_poses(teleavatar.home, ["left_ee", "right_ee"])
    res = cartesian_offset(teleavatar, teleavatar.home, {"left_ee": [0, 0, -0.12], "right_ee": [0, 0, -0.12]})
    return res, start


@pytest.fixture(scope="module")
def right_down_up(teleavatar: taplan.Robot) -> CartesianResult:
    offsets = [{"right_ee": [0.0, 0.0, -0.10]}, {"right_ee": [0.0, 0.0, 0.10]}]
    return cartesian_offset(teleavatar, teleavatar.home, offsets, method="topp")


def test_both_hands_follow_the_line_within_the_bound(teleavatar: taplan.Robot, both_down) -> None:
    res, start = both_down
    for frame in ("left_ee", "right_ee"):
        a = start[frame][:3, 3]
        b = a + np.array([0.0, 0.0, -0.12])
        p, R = fk_along(teleavatar, res.trajectory, frame)
        dist, _ = distance_to_segment(p, a, b)
        assert dist.max() <= DEVIATION_BOUND
        angle = [np.linalg.norm(pin.log3(start[frame][:3, :3].T @ Rk)) for Rk in R]  # orientation is constant
        assert max(angle) <= ANGLE_BOUND
        np.testing.assert_allclose(dist.max(), res.position_deviation[frame], atol=1e-7)
    assert res.max_position_deviation <= DEVIATION_BOUND


def test_both_hands_reach_their_goals_together(teleavatar: taplan.Robot, both_down) -> None:
    res, start = both_down
    q_end = res.trajectory(res.trajectory.times[-1])
    for frame in ("left_ee", "right_ee"):
        T = teleavatar.frame_pose(q_end, frame)
        goal = start[frame][:3, 3] + np.array([0.0, 0.0, -0.12])
        assert np.linalg.norm(T[:3, 3] - goal) <= ENDPOINT_TOL[0]
        assert np.linalg.norm(pin.log3(start[frame][:3, :3].T @ T[:3, :3])) <= ENDPOINT_TOL[1]
    # one line parameter: halfway in time-independent terms, both hands have moved the same height
    p_left, _ = fk_along(teleavatar, res.trajectory, "left_ee")
    p_right, _ = fk_along(teleavatar, res.trajectory, "right_ee")
    drop_left = start["left_ee"][2, 3] - p_left[:, 2]
    drop_right = start["right_ee"][2, 3] - p_right[:, 2]
    np.testing.assert_allclose(drop_left, drop_right, atol=1e-3)


def test_jerk_limited_line_respects_every_limit(teleavatar: taplan.Robot, both_down) -> None:
    res, _ = both_down
    limits = teleavatar.planning_limits
    usage = limit_usage(res.trajectory, limits)
    assert usage.within(LIMIT_TOL, jerk=True)
    assert float(usage.position.max()) == 0.0
    for t in res.trajectory.times[[0, -1]]:
        np.testing.assert_allclose(res.trajectory(t, 1), 0.0, atol=REST_TOL)
        np.testing.assert_allclose(res.trajectory(t, 2), 0.0, atol=1e-6)


def test_down_then_up_holds_the_other_arm(teleavatar: taplan.Robot, right_down_up) -> None:
    res = right_down_up
    left = teleavatar.group("left").indices
    q = res.trajectory(res.trajectory.sample_times(CHECK_RATE))
    assert np.abs(q[:, left] - teleavatar.home[left]).max() <= HELD_TOL
    assert set(res.moving_joints) == set(teleavatar.group("right").joint_names)
    assert len(res.leg_durations) == 2
    # back where it started, passing through the lower point
    np.testing.assert_allclose(
        teleavatar.frame_pose(q[-1], "right_ee")[:3, 3], teleavatar.frame_pose(q[0], "right_ee")[:3, 3], atol=1e-5
    )
    p, _ = fk_along(teleavatar, res.trajectory, "right_ee")
    a = p[0]
    dist, lam = distance_to_segment(p, a, a + np.array([0.0, 0.0, -0.10]))
    assert dist.max() <= DEVIATION_BOUND
    assert lam.max() == pytest.approx(1.0, abs=1e-4)
    assert limit_usage(res.trajectory, teleavatar.planning_limits).within(LIMIT_TOL)


def test_rotation_follows_slerp(teleavatar: taplan.Robot) -> None:
    T0 = teleavatar.frame_pose(teleavatar.home, "right_ee")
    goal = T0.copy()
    goal[:3, :3] = T0[:3, :3] @ pin.exp3(np.array([0.2, 0.0, 0.3]))
    res = cartesian_line(teleavatar, teleavatar.home, {"right_ee": goal}, method="topp")
    p, R = fk_along(teleavatar, res.trajectory, "right_ee")
    assert np.linalg.norm(p - T0[:3, 3], axis=1).max() <= DEVIATION_BOUND  # pure rotation: the point stays
    omega = pin.log3(T0[:3, :3].T @ goal[:3, :3])
    for Rk in R:  # each orientation lies on the geodesic R0 exp(λ ω)
        log = pin.log3(T0[:3, :3].T @ Rk)
        lam = float(np.clip(log @ omega / (omega @ omega), 0.0, 1.0))
        assert np.linalg.norm(pin.log3((T0[:3, :3] @ pin.exp3(lam * omega)).T @ Rk)) <= ANGLE_BOUND
    dist, angle = line_deviation(teleavatar, res.trajectory, "right_ee", T0, goal)
    assert dist.max() <= DEVIATION_BOUND and angle.max() <= ANGLE_BOUND


def test_unreachable_target_raises_naming_the_sample(teleavatar: taplan.Robot) -> None:
    with pytest.raises(InfeasibleError, match=r"sample \d+ at λ=.*right_ee"):
        cartesian_offset(teleavatar, teleavatar.home, {"right_ee": [0.8, 0.0, 0.0]})


def test_joint_limit_blocking_the_line_is_reported(teleavatar: taplan.Robot) -> None:
    # from the vendor's ready pose l_joint7 sits on its bound, and straight down needs it to go further
    with pytest.raises(InfeasibleError, match="l_joint7"):
        cartesian_offset(teleavatar, READY, {"left_ee": [0.0, 0.0, -0.12]}, refinements=0)


@pytest.mark.parametrize(("seed", "method"), [(0, "jerk"), (3, "topp"), (4, "jerk"), (5, "topp")])
def test_lines_from_starts_on_the_bounds_are_timed_inside_every_limit(teleavatar, seed: int, method: str) -> None:
    # issue 21 (bench_timing's Cartesian sweep in small): r_joint4 on a bound, r_joint7 0.5 mrad from one; the
    # timing stays inside every limit (exact peaks, positions included) and the hand on its line
    rng = np.random.default_rng(seed)
    limits = teleavatar.planning_limits
    joints = np.array([teleavatar.joint_names.index(n) for n in teleavatar.group("right").joint_names])
    q = teleavatar.home.copy()
    q[joints] = rng.uniform(limits.lower[joints], limits.upper[joints])
    gap = np.array([0, 0, 0, 0, 0, 0, 5e-4])
    near = np.where(rng.random(7) < 0.5, limits.upper[joints] - gap, limits.lower[joints] + gap)
    q[joints[[3, 6]]] = near[[3, 6]]
    direction = rng.normal(size=3)
    res = cartesian_offset(teleavatar, q, {"right_ee": 0.03 * direction / np.linalg.norm(direction)}, method=method)
    usage = limit_usage(res.trajectory, limits)
    assert usage.within(LIMIT_TOL, jerk=method == "jerk") and usage.position.max() <= 1e-9
    assert res.max_position_deviation <= DEFAULT_LINE_DEVIATION
    np.testing.assert_array_equal(res.trajectory(0.0), q)


def test_joint_starting_outside_planning_bounds_is_widened(teleavatar: taplan.Robot) -> None:
    res = cartesian_offset(teleavatar, READY, {"right_ee": [0.0, 0.0, 0.05]}, method="topp", refinements=0)
    assert "l_joint7" in res.widened
    assert res.max_position_deviation <= DEVIATION_BOUND


def test_discontinuous_joint_path_raises(teleavatar: taplan.Robot) -> None:
    with pytest.raises(TimingError, match="discontinuous joint path"):
        cartesian_offset(
            teleavatar, teleavatar.home, {"right_ee": [0, 0, -0.05]}, max_joint_step=1e-4, max_bisections=0
        )


@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"targets": {"nope": np.eye(4)}}, UnknownNameError),
        ({"targets": {}}, InvalidInputError),
        ({"targets": []}, InvalidInputError),
        ({"targets": {"right_ee": np.full((4, 4), np.nan)}}, InvalidInputError),
        ({"method": "linear"}, UnknownNameError),
        ({"max_deviation": (0.0, 1.0)}, InvalidInputError),
        ({"step": -1.0}, InvalidInputError),
        ({"start_q": np.full(14, np.nan)}, InvalidInputError),
        ({"start_q": np.zeros(14)}, InvalidInputError),  # outside the hardware limits (joint 4)
    ],
)
def test_bad_inputs_raise(teleavatar: taplan.Robot, kwargs: dict, error: type[Exception]) -> None:
    args = {"start_q": teleavatar.home, "targets": {"right_ee": teleavatar.frame_pose(teleavatar.home, "right_ee")}}
    args["targets"]["right_ee"][2, 3] -= 0.02
    args.update(kwargs)
    start_q, targets = args.pop("start_q"), args.pop("targets")
    with pytest.raises(error):
        cartesian_line(teleavatar, start_q, targets, **args)


def test_zero_motion_raises(teleavatar: taplan.Robot) -> None:
    with pytest.raises(InvalidInputError, match="equal to the start"):
        cartesian_offset(teleavatar, teleavatar.home, {"right_ee": [0.0, 0.0, 0.0]})


def test_cartesian_line_respects_a_scene(teleavatar) -> None:
    """With a scene the line is certified collision-free, or refused with the pair and the distance in mm."""
    from taplan.errors import CollisionError, PlanningError
    from taplan.scene import Box, CollisionWorld, Scene

    q = teleavatar.home
    hand = teleavatar.frame_pose(q, "right_ee")[:3, 3]
    below = Scene()
    below.add("slab", Box((0.3, 0.3, 0.02)), ((hand + [0.0, 0.0, -0.14]).tolist(), [0, 0, 0, 1]))
    world = CollisionWorld(teleavatar, below)
    free = cartesian_offset(teleavatar, q, {"right_ee": [0.0, 0.0, 0.05]}, scene=world, clearance=0.005)
    assert free.min_clearance > 0.005  # certified [m]
    assert free.min_clearance_pair != ("", "")
    samples = free.trajectory(np.linspace(0.0, free.trajectory.duration, 200))
    assert min(world.min_distance(s)[0] for s in samples) > 0.005  # independent samples [m]
    with pytest.raises(PlanningError, match=r"comes within -?\d+\.\d mm of collision \(.* / slab at t = "):
        cartesian_offset(teleavatar, q, {"right_ee": [0.0, 0.0, -0.08]}, scene=below)
    inside = Scene()
    inside.add("block", Box((0.1, 0.1, 0.1)), (hand.tolist(), [0, 0, 0, 1]))
    with pytest.raises(CollisionError, match=r"start_q: .* collides with block"):
        cartesian_offset(teleavatar, q, {"right_ee": [0.0, 0.0, 0.05]}, scene=inside)
    with pytest.raises(InvalidInputError, match="scene"):
        cartesian_offset(teleavatar, q, {"right_ee": [0.0, 0.0, 0.05]}, scene="table.yaml")
    with pytest.raises(InvalidInputError, match="clearance"):
        cartesian_offset(teleavatar, q, {"right_ee": [0.0, 0.0, 0.05]}, scene=below, clearance=-1.0)
