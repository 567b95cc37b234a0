"""taplan.timing: retime (TOPP-RA) limits, boundary conditions, analytic cases, jerk-limited, sync, bad inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest

import taplan
from benchmarks._paths import random_walk
from taplan.errors import InvalidInputError, TimingError
from taplan.timing import Path, jerk_limited, limit_usage, retime, sampled_limit_usage, synchronise

LIMIT_TOL = 1e-6  # relative: sampled |qd|/v and |qdd|/a must stay <= 1 + LIMIT_TOL
POS_TOL = 1e-9  # [rad]
VEL_TOL = 1e-6  # [rad]/[s]
ACC_TOL = 1e-6  # [rad]/[s]^2
DURATION_RTOL = 2e-3  # relative, analytic bang-bang durations
JERK_DURATION_RATIO = 1.15  # jerk-limited duration / TOPP-RA duration


@pytest.fixture(scope="module")
def arm_limits(teleavatar: taplan.Robot) -> taplan.JointLimits:
    return teleavatar.planning_limits.subset(teleavatar.group("left").joint_names)


def single_joint_limits(velocity: float, acceleration: float) -> taplan.JointLimits:
    return taplan.JointLimits.from_arrays(["j"], [-10.0], [10.0], [velocity], [acceleration])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_retime_never_exceeds_limits_on_random_paths(arm_limits: taplan.JointLimits, seed: int) -> None:
    traj = retime(random_walk(arm_limits, 8, seed), arm_limits)
    sampled = sampled_limit_usage(traj, arm_limits, rate=1000.0)
    exact = limit_usage(traj, arm_limits)
    assert sampled.max_velocity <= 1 + LIMIT_TOL
    assert sampled.max_acceleration <= 1 + LIMIT_TOL
    assert exact.within(LIMIT_TOL)
    assert exact.max_acceleration > 0.99  # time-optimal: some joint uses its acceleration limit


def test_retime_velocity_limited_path_holds_limits(arm_limits: taplan.JointLimits) -> None:
    slow = arm_limits.replace(velocity=arm_limits.velocity * 0.05)
    traj = retime(random_walk(arm_limits, 6, 7), slow)
    usage = sampled_limit_usage(traj, slow)
    assert usage.within(LIMIT_TOL)
    assert usage.max_velocity > 0.99


def test_retime_passes_through_waypoints_and_rests_at_ends(arm_limits: taplan.JointLimits) -> None:
    q = random_walk(arm_limits, 5, 3)
    traj = retime(q, arm_limits)
    for row in q:
        assert np.min(np.max(np.abs(traj.positions - row), axis=1)) <= POS_TOL
    np.testing.assert_allclose(traj(0.0), q[0], atol=POS_TOL)
    np.testing.assert_allclose(traj(traj.duration), q[-1], atol=POS_TOL)
    np.testing.assert_allclose(traj(0.0, 1), 0.0, atol=VEL_TOL)
    np.testing.assert_allclose(traj(traj.duration, 1), 0.0, atol=VEL_TOL)
    assert traj.joint_names == arm_limits.names


@pytest.mark.parametrize(
    ("distance", "velocity", "acceleration"),
    [(1.0, 2.0, 3.0), (3.0, 1.0, 4.0)],  # triangular (never reaches v), trapezoidal
)
def test_single_joint_rest_to_rest_is_bang_bang(distance: float, velocity: float, acceleration: float) -> None:
    limits = single_joint_limits(velocity, acceleration)
    traj = retime([[0.0], [distance]], limits)
    if distance >= velocity**2 / acceleration:
        expected = distance / velocity + velocity / acceleration
    else:
        expected = 2 * np.sqrt(distance / acceleration)
    np.testing.assert_allclose(traj.duration, expected, rtol=DURATION_RTOL)
    assert sampled_limit_usage(traj, limits).within(LIMIT_TOL)


def test_retime_non_zero_boundary_velocities(arm_limits: taplan.JointLimits) -> None:
    q = random_walk(arm_limits, 4, 5)
    d0, d1 = q[1] - q[0], q[-1] - q[-2]
    v0 = 0.1 * d0 / np.max(np.abs(d0) / arm_limits.velocity)  # along the first chord, 10 % of the tightest limit
    v1 = 0.05 * d1 / np.max(np.abs(d1) / arm_limits.velocity)
    traj = retime(q, arm_limits, start_velocity=v0, end_velocity=v1)
    np.testing.assert_allclose(traj(0.0, 1), v0, atol=1e-6 * np.max(np.abs(v0)) + VEL_TOL)
    np.testing.assert_allclose(traj(traj.duration, 1), v1, atol=1e-6 * np.max(np.abs(v1)) + VEL_TOL)
    assert sampled_limit_usage(traj, arm_limits).within(LIMIT_TOL)


def test_retime_accepts_path_and_checks_tangency(arm_limits: taplan.JointLimits) -> None:
    path = Path(random_walk(arm_limits, 4, 6))
    tangent = path(0.0, 1)
    traj = retime(path, arm_limits, start_velocity=0.01 * tangent)
    np.testing.assert_allclose(traj(0.0, 1), 0.01 * tangent, atol=VEL_TOL)
    with pytest.raises(InvalidInputError, match="start_velocity"):
        retime(path, arm_limits, start_velocity=np.roll(0.01 * tangent, 1) + 0.01)


def test_retime_save_load_round_trip(arm_limits: taplan.JointLimits, tmp_path) -> None:  # noqa: ANN001
    traj = retime(random_walk(arm_limits, 4, 8), arm_limits)
    t = traj.sample_times(1000.0)
    for suffix in (".json", ".npz"):
        loaded = taplan.trajectory.Trajectory.load(traj.save(tmp_path / f"traj{suffix}"))
        np.testing.assert_allclose(loaded(t, 2), traj(t, 2), atol=ACC_TOL)
        assert loaded.interpolation == "polynomial"


@pytest.mark.parametrize(
    ("waypoints", "match"),
    [
        ([[0.0] * 7, [np.nan] * 7], "finite"),
        ([[0.0] * 7], "at least 2"),
        ([[0.1] * 7, [0.1] * 7, [0.1] * 7], "all equal"),
        ([[0.0] * 6, [0.1] * 6], "shape"),
        ([0.0, 0.1], "shape"),
    ],
)
def test_retime_rejects_bad_waypoints(arm_limits: taplan.JointLimits, waypoints: list, match: str) -> None:
    with pytest.raises(InvalidInputError, match=match):
        retime(waypoints, arm_limits)


def test_retime_rejects_bad_limits_and_velocities(arm_limits: taplan.JointLimits) -> None:
    q = random_walk(arm_limits, 3, 9)
    with pytest.raises(InvalidInputError, match="limits"):
        retime(q, {"velocity": 1.0})  # type: ignore[arg-type]
    with pytest.raises(TimingError, match="exceeds the velocity limit"):
        retime(q, arm_limits, start_velocity=2 * arm_limits.velocity)
    with pytest.raises(InvalidInputError, match="start_velocity"):
        retime(q, arm_limits, start_velocity=[0.1] * 6)


def test_retime_rejects_path_outside_position_limits(arm_limits: taplan.JointLimits) -> None:
    q = np.array([arm_limits.lower + 0.1, arm_limits.upper + 0.05])
    with pytest.raises(TimingError, match="position limits"):
        retime(q, arm_limits)


def test_retime_infeasible_end_velocity_raises(arm_limits: taplan.JointLimits) -> None:
    q = np.array([arm_limits.lower + 0.5, arm_limits.lower + 0.5001])
    v1 = np.sign(q[1] - q[0]) * 0.999 * arm_limits.velocity * 0  # zero end velocity keeps it feasible
    traj = retime(q, arm_limits, end_velocity=v1)
    assert traj.duration > 0
    v_big = (q[1] - q[0]) / np.max(np.abs(q[1] - q[0]) / arm_limits.velocity) * 0.999
    with pytest.raises(TimingError, match="TOPP-RA failed"):
        retime(q, arm_limits, start_velocity=v_big)  # cannot stop within 1e-4 rad


def _closest_distances(traj, points: np.ndarray) -> np.ndarray:
    """Max-norm distance [rad] from each point to the trajectory, on 50,001 samples (independent of taplan)."""
    q = traj(np.linspace(0.0, traj.duration, 50001))
    return np.array([np.min(np.max(np.abs(q - p), axis=1)) for p in points])


@pytest.mark.parametrize("method", ["joint", "path"])
def test_jerk_limited_holds_all_limits_and_is_near_optimal(arm_limits: taplan.JointLimits, method: str) -> None:
    q = random_walk(arm_limits, 6, 11)
    result = jerk_limited(q, arm_limits, method=method)
    assert result.method == method
    traj = result.trajectory
    usage = sampled_limit_usage(traj, arm_limits)
    assert usage.within(LIMIT_TOL, jerk=True)
    assert limit_usage(traj, arm_limits).within(LIMIT_TOL, jerk=True)
    np.testing.assert_allclose(traj(0.0, 2), 0.0, atol=ACC_TOL)
    np.testing.assert_allclose(traj(traj.duration, 2), 0.0, atol=ACC_TOL)
    np.testing.assert_allclose(traj(traj.duration, 1), 0.0, atol=VEL_TOL)
    np.testing.assert_allclose(traj(0.0), q[0], atol=POS_TOL)
    np.testing.assert_allclose(traj(traj.duration), q[-1], atol=POS_TOL)
    inner = traj.times[1:-1]
    left = traj(inner - 1e-9, 2)
    right = traj(inner + 1e-9, 2)
    assert np.max(np.abs(left - right)) < 1e-5  # continuous acceleration [rad]/[s]^2
    assert result.duration_ratio <= JERK_DURATION_RATIO
    distances = _closest_distances(traj, q[1:-1])
    if method == "path":
        assert np.max(distances) < 1e-3  # passes every waypoint [rad]
        assert result.deviation == 0.0
    else:
        assert np.max(distances) <= result.deviation + 1e-4  # the reported deviation [rad], up to sampling
        assert result.deviation <= 0.05  # the default max_deviation [rad]


def test_jerk_limited_joint_method_duration_is_topp_plus_less_than_the_filter_width(
    arm_limits: taplan.JointLimits,
) -> None:
    q = random_walk(arm_limits, 30, 5)
    result = jerk_limited(q, arm_limits)
    width = float(np.max(2 * arm_limits.acceleration / arm_limits.jerk))
    assert result.width == pytest.approx(width)
    topp = result.topp_duration * result.time_scale
    # the filter adds its width; ruckig's starts and stops (full jerk instead of the filter's half) take some back
    assert topp + 0.5 * width < result.trajectory.duration < topp + width - 0.02
    assert 1.0 <= result.time_scale < 1.01  # only toppra's rounding excess is scaled away
    assert result.duration_ratio < 1.05
    usage = limit_usage(result.trajectory, arm_limits)
    assert usage.within(LIMIT_TOL, jerk=True)
    assert usage.max_acceleration > 0.95  # still time-optimal where the filter does not act


@pytest.mark.parametrize("max_deviation", [0.01, 0.005])
def test_jerk_limited_max_deviation_slows_the_corners(arm_limits: taplan.JointLimits, max_deviation: float) -> None:
    q = random_walk(arm_limits, 12, 3)
    loose = jerk_limited(q, arm_limits)
    tight = jerk_limited(q, arm_limits, max_deviation=max_deviation)
    assert loose.deviation > max_deviation  # the corners of this path are cut more by default
    assert np.max(_closest_distances(tight.trajectory, q[1:-1])) <= max_deviation + 1e-4
    assert tight.trajectory.duration > loose.trajectory.duration
    # slowing the corners never makes it slower than passing every waypoint exactly (the path method)
    exact = jerk_limited(q, arm_limits, method="path")
    assert tight.trajectory.duration <= exact.trajectory.duration + 1e-9
    assert tight.method == ("joint" if tight.trajectory.duration < exact.trajectory.duration else "path")
    assert limit_usage(tight.trajectory, arm_limits).within(LIMIT_TOL, jerk=True)


def test_jerk_limited_zero_deviation_passes_every_waypoint(arm_limits: taplan.JointLimits) -> None:
    q = random_walk(arm_limits, 5, 8)
    result = jerk_limited(q, arm_limits, max_deviation=0.0)
    assert result.method == "path"
    assert np.max(_closest_distances(result.trajectory, q[1:-1])) < 1e-3


def test_jerk_limited_plans_a_thousand_waypoints(arm_limits: taplan.JointLimits) -> None:
    q = random_walk(arm_limits, 1000, 4)
    result = jerk_limited(q, arm_limits)
    assert result.duration_ratio < 1.01
    assert limit_usage(result.trajectory, arm_limits).within(LIMIT_TOL, jerk=True)


@pytest.mark.parametrize(
    ("kwargs", "argument"),
    [
        ({"method": "spline"}, "method"),
        ({"max_deviation": -0.1}, "max_deviation"),
        ({"max_deviation": float("nan")}, "max_deviation"),
        ({"points_per_segment": 0}, "points_per_segment"),
        ({"min_grid_segments": 0}, "min_grid_segments"),
        ({"min_grid_segments": 2.5}, "min_grid_segments"),
    ],
)
def test_jerk_limited_rejects_bad_options(arm_limits: taplan.JointLimits, kwargs: dict, argument: str) -> None:
    with pytest.raises(InvalidInputError, match=argument) as info:
        jerk_limited(random_walk(arm_limits, 4, 1), arm_limits, **kwargs)
    assert info.value.argument == argument


def test_synchronise_together_and_independent(teleavatar: taplan.Robot) -> None:
    limits = {g: teleavatar.planning_limits.subset(teleavatar.group(g).joint_names) for g in ("left", "right")}
    home = teleavatar.home
    wp = {
        "left": np.array([home[:7], home[:7] + 0.3, home[:7] + 0.1]),
        "right": np.array([home[7:], home[7:] - 0.1, home[7:] + 0.05]),
    }
    together = synchronise(wp, limits, mode="together")
    assert together["left"].duration == together["right"].duration
    np.testing.assert_array_equal(together["left"].times, together["right"].times)
    for g, traj in together.items():
        assert traj.joint_names == limits[g].names
        assert sampled_limit_usage(traj, limits[g]).within(LIMIT_TOL)
    independent = synchronise(wp, limits, mode="independent")
    assert independent["right"].duration < together["right"].duration
    with pytest.raises(InvalidInputError, match="mode"):
        synchronise(wp, limits, mode="sometimes")
    with pytest.raises(InvalidInputError, match="same number"):
        synchronise({"left": wp["left"], "right": wp["right"][:2]}, limits)


@pytest.mark.parametrize("seed", range(4))
def test_jerk_limited_within_5_percent_of_topp_on_10_waypoints(arm_limits: taplan.JointLimits, seed: int) -> None:
    from tests.test_timing_any_path import finite_difference_excess

    q = random_walk(arm_limits, 10, 10_000 + seed)  # the benchmark's 10-waypoint paths
    result = jerk_limited(q, arm_limits)
    assert result.duration_ratio <= 1.05  # the goal (the filter alone: 1.05-1.065)
    assert limit_usage(result.trajectory, arm_limits).within(0.0, jerk=True)  # exact peaks, no tolerance
    assert finite_difference_excess(result.trajectory, arm_limits, jerk=True) <= 0.0
    np.testing.assert_allclose(result.trajectory(0.0), q[0], atol=1e-12)
    np.testing.assert_allclose(result.trajectory(result.trajectory.duration), q[-1], atol=1e-9)
    assert np.max(_closest_distances(result.trajectory, q[1:-1])) <= result.deviation + 1e-4 <= 0.05 + 1e-4


def test_position_range_of_high_degree_pieces_is_exact() -> None:
    """The batched companion-matrix roots find every interior extreme (checked against dense sampling), also for
    pieces whose leading coefficients vanish."""
    from types import SimpleNamespace

    from taplan.timing._polynomial import _position_range_roots

    rng = np.random.default_rng(0)
    for trial in range(12):
        m, d, n = int(rng.integers(1, 6)), int(rng.integers(5, 9)), int(rng.integers(1, 6))
        c = rng.normal(size=(m, d, n))
        if trial % 3 == 0:
            c[:, -1, :] = 0.0
        if trial % 4 == 0:
            c[:, 3:, 0] = 0.0
        h = rng.uniform(0.1, 1.0, m)
        low, high = _position_range_roots(SimpleNamespace(coefficients=c, times=np.concatenate([[0.0], np.cumsum(h)])))
        samples = np.concatenate(
            [
                np.stack(
                    [np.polynomial.polynomial.polyval(np.linspace(0, h[k], 20001), c[k, :, j]) for j in range(n)], 1
                )
                for k in range(m)
            ]
        )
        assert np.all(low <= samples.min(axis=0) + 1e-9) and np.all(high >= samples.max(axis=0) - 1e-9)
        assert np.all(samples.min(axis=0) - low < 1e-5) and np.all(high - samples.max(axis=0) < 1e-5)


def _counted_solves(monkeypatch: pytest.MonkeyPatch, module: object) -> list[float]:
    """The durations of every TOPP-RA solve ``module`` makes from now on, in order."""
    solves: list[float] = []
    profile = module.time_optimal_profile

    def counted(*args: object, **kwargs: object) -> object:
        out = profile(*args, **kwargs)
        solves.append(out.duration)
        return out

    monkeypatch.setattr(module, "time_optimal_profile", counted)
    return solves


@pytest.mark.parametrize(("count", "seed"), [(12, 3), (25, 7), (30, 2)])
def test_jerk_limited_skips_a_path_filter_that_cannot_beat_the_joint_method(
    arm_limits: taplan.JointLimits, count: int, seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The path filter is stopped once its lower bound (a round's TOPP-RA duration plus the narrowest width) reaches
    the joint method's duration: jerk_limited returns what comparing with the whole path filter returns."""
    import sys

    from taplan.timing.toppra_retime import as_path

    module = sys.modules["taplan.timing.jerk_limited"]
    q = random_walk(arm_limits, count, seed)
    path, _, _ = as_path(q, arm_limits.size)
    factors, repairs = module.DEFAULT_WIDTH_FACTORS, module.DEFAULT_REPAIRS
    solves = _counted_solves(monkeypatch, module)
    stopped = 0
    for max_deviation in (0.02, 0.01, 0.005):
        joint, _ = module._joint_filter(path, arm_limits, max_deviation, (16, 128), None)
        solves.clear()
        whole = module._path_filter(path, arm_limits, factors, 1.0, repairs, (16, 128), None)
        whole_solves = len(solves)
        expected = joint if joint is not None and joint.trajectory.duration <= whole.trajectory.duration else whole
        result = jerk_limited(q, arm_limits, max_deviation=max_deviation)
        assert result.method == expected.method
        assert result.trajectory.duration == pytest.approx(expected.trajectory.duration, abs=1e-12)
        np.testing.assert_allclose(result.trajectory.coefficients, expected.trajectory.coefficients, atol=1e-12)
        beat = math.inf if joint is None else joint.trajectory.duration
        solves.clear()
        cut = module._path_filter(path, arm_limits, factors, 1.0, repairs, (16, 128), None, beat)
        if cut is None or cut.trajectory.duration >= beat:  # it cannot win: stopped, fewer TOPP-RA solves
            stopped += 1
            assert whole.trajectory.duration >= beat and len(solves) < whole_solves
        else:
            assert cut.trajectory.duration == pytest.approx(whole.trajectory.duration, abs=1e-12)
    assert stopped >= 1  # the bound ends the path filter early on these paths


def test_jerk_limited_on_a_coarser_grid_holds_every_limit(arm_limits: taplan.JointLimits) -> None:
    """The planner's grid (4 segments per interval, at least 64): every limit held, fewer TOPP-RA gridpoints, and
    a duration within 5 % of the default grid's (this random walk's sharp corners: 3 % longer; the optimiser's
    densified paths of the benchmark: within 1 %)."""
    from taplan.timing.toppra_retime import as_path, grid_for

    q = random_walk(arm_limits, 20, 4)
    path, _, _ = as_path(q, arm_limits.size)
    assert len(grid_for(path, 4, 64)) - 1 == 4 * 19 < len(grid_for(path, 4)) - 1
    coarse = jerk_limited(q, arm_limits, points_per_segment=4, min_grid_segments=64)
    default = jerk_limited(q, arm_limits, points_per_segment=4)
    assert limit_usage(coarse.trajectory, arm_limits).within(LIMIT_TOL, jerk=True)
    assert coarse.trajectory.duration == pytest.approx(default.trajectory.duration, rel=0.05)
    np.testing.assert_allclose(coarse.trajectory(0.0), q[0], atol=POS_TOL)
    np.testing.assert_allclose(coarse.trajectory(coarse.trajectory.duration), q[-1], atol=POS_TOL)


def test_a_path_filter_that_loses_in_its_first_round_costs_one_toppra_solve(
    arm_limits: taplan.JointLimits, monkeypatch: pytest.MonkeyPatch
) -> None:
    """When the first round's TOPP-RA with the jerk terms already reaches ``beat``, the path filter stops after that
    one solve (the TOPP-RA without them, faster, could not decide alone), and returns None as before."""
    import sys

    from taplan.timing.toppra_retime import as_path

    module = sys.modules["taplan.timing.jerk_limited"]
    path, _, _ = as_path(random_walk(arm_limits, 12, 3), arm_limits.size)
    factors, repairs = module.DEFAULT_WIDTH_FACTORS, module.DEFAULT_REPAIRS
    solves = _counted_solves(monkeypatch, module)
    whole = module._path_filter(path, arm_limits, factors, 1.0, repairs, (4, 64), None)
    with_jerk, without = solves[0], solves[1]  # the first round's solve, then the reference TOPP-RA
    assert without < with_jerk and whole.topp_duration == without
    width = min(factors) * float(np.max(arm_limits.acceleration / arm_limits.jerk))
    beat = (without + with_jerk) / 2 + width  # the reference alone would not rule the filter out
    solves.clear()
    assert module._path_filter(path, arm_limits, factors, 1.0, repairs, (4, 64), None, beat) is None
    assert len(solves) == 1  # [s] the first round's duration + width >= beat: stopped there
