"""The fused builder (DifferentialIK's default hot path), with numpy and with its native kernel, builds the same
problems and steps as the generic one."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import taplan
from taplan.ik import DifferentialIK
from taplan.ik._fused import FusedBuilder
from taplan.ik._native import native_enabled
from taplan.ik.problem import ProblemBuilder

REL_TOL = 1e-9  # relative to the largest entry of the compared array
VEL_TOL = 1e-9  # [rad/s] between the two steppers' velocities (same QP, same solver)
# The native kernel's Jlog3 is exact to ~1e-15 at every angle (tests/test_ik_native.py); pinocchio's, which the numpy
# builders use, loses up to ~1e-8 between 1e-8 and 1e-3 rad to the cancellation in 1 - cos θ. Native comparisons
# allow for that (relative, and [rad/s] for the velocities).
NATIVE_TOL = 1e-7


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _close(a: np.ndarray, b: np.ndarray, columns: np.ndarray | None = None, tol: float = REL_TOL) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if columns is not None:
        a, b = a[..., columns], b[..., columns]
    if a.shape != b.shape:
        return False
    finite = np.isfinite(a) & np.isfinite(b)
    if not np.array_equal(np.isfinite(a), np.isfinite(b)) or not np.array_equal(a[~finite], b[~finite]):
        return False
    scale = max(1.0, float(np.abs(a[finite]).max(initial=0.0)))
    return bool(np.all(np.abs(a[finite] - b[finite]) <= tol * scale))


def _pair(robot, native: bool = False, **options) -> tuple[DifferentialIK, DifferentialIK]:
    fused = DifferentialIK(robot, solver="daqp", native=native, **options)
    generic = DifferentialIK(robot, solver="daqp", fused=False, **options)
    assert isinstance(fused.builder, FusedBuilder)
    assert isinstance(generic.builder, ProblemBuilder)
    assert fused.builder.native == native
    return fused, generic


def _random_targets(robot, rng, q) -> dict[str, np.ndarray]:
    out = {}
    for frame in ("left_ee", "right_ee"):
        if rng.random() < 0.8:
            T = robot.frame_pose(q, frame)
            T[:3, 3] += rng.normal(0.0, 0.03, 3)
            if rng.random() < 0.3:  # also rotate
                axis = rng.normal(size=3)
                T[:3, :3] = pin.exp3(axis / np.linalg.norm(axis) * rng.uniform(0, 0.3)) @ T[:3, :3]
            out[frame] = T
    return out


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"acceleration_limit": False},
        {"target_braking": False},
        {"collision": False, "dt": 0.002},
        {"posture_cost": [1e-2] * 7 + [3e-2] * 7, "damping": 0.0},
        {"position_cost": [1.0, 2.0, 0.5], "orientation_cost": 0.3},
    ],
    ids=["default", "acc-off", "no-braking", "no-collision-2ms", "posture-weights", "task-weights"],
)
@pytest.mark.parametrize(
    "native",
    [
        False,
        pytest.param(True, marks=pytest.mark.skipif(not native_enabled(), reason="no C compiler: numpy path only")),
    ],
    ids=["numpy", "native"],
)
def test_fused_and_generic_builders_agree(robot, options, native):
    rng = np.random.default_rng(7)
    lim = robot.planning_limits
    fused, generic = _pair(robot, native, **options)
    tol, vel_tol = (NATIVE_TOL, NATIVE_TOL) if native else (REL_TOL, VEL_TOL)
    compared = ambiguous = 0
    for episode in range(12):
        span = lim.upper - lim.lower
        outside = 0.1 if episode % 3 == 0 else 0.0  # a third of the episodes start outside the position limits
        q0 = rng.uniform(lim.lower - outside * span, lim.upper + outside * span)
        v0 = rng.uniform(-lim.velocity, lim.velocity) * (episode % 2)
        for ik in (fused, generic):
            ik.reset(q0, v0)
        q_meas = None
        for k in range(15):
            targets = _random_targets(robot, rng, q0) if k % 5 == 0 else {}
            twists = {"left_ee": rng.normal(0, 0.05, 6)} if k % 7 == 3 else None
            a = fused.step(targets, q=q_meas, target_velocities=twists)
            b = generic.step(targets, q=q_meas, target_velocities=twists)
            pa, pb = a.problem, b.problem
            # a joint already at its target (|v_free - v_ff| ~ 1e-16) is braked on the side of its rounding error's
            # sign, which may differ between the builders: compare the box elsewhere (the velocities everywhere)
            braking = [la for (name, la) in pa.layers if name == "target_braking"]
            same = np.ones(robot.nq, dtype=bool)
            if braking:
                lb = next(x for name, x in pb.layers if name == "target_braking")
                same = (np.isinf(braking[0]) == np.isinf(lb)).all(axis=0)
            for name in ("H", "c", "G", "h", "v_free"):
                assert _close(getattr(pa, name), getattr(pb, name), tol=tol), (name, episode, k)
            for name in ("lower", "upper", "minimiser"):
                assert _close(getattr(pa, name), getattr(pb, name), same, tol), (name, episode, k)
            assert pa.minimiser_exact == pb.minimiser_exact
            assert [n for n, _ in pa.layers] == [n for n, _ in pb.layers]
            for (_, la), (_, lb) in zip(pa.layers, pb.layers, strict=True):
                assert _close(la, lb, same, tol)
            ra, rb = pa.relaxations(), pb.relaxations()
            assert all(np.array_equal(ra[n][same], rb[n][same]) for n in ra)
            if same.all():
                assert np.abs(a.velocity - b.velocity).max() <= vel_tol
            else:  # the QPs differ in those joints' bounds: continue both from the fused step
                ambiguous += 1
                generic._q[:] = fused._q
                generic._v[:] = fused._v
            compared += 1
            q_meas = a.q if k % 4 == 1 else None  # sometimes feed back a "measured" q (same for both)
            if q_meas is not None:
                fused._q[:] = generic._q  # keep the integrated states identical
    assert compared == 12 * 15
    assert ambiguous < compared / 4  # most steps were compared in full


def test_extra_tasks_or_limits_use_the_generic_builder(robot):
    from taplan.ik import DampingTask

    ik = DifferentialIK(robot, extra_tasks=[DampingTask(robot.nq, 1e-3)])
    assert isinstance(ik.builder, ProblemBuilder)


def test_hot_path_validates_every_matrix_target(robot):
    from taplan.errors import InvalidInputError

    ik = DifferentialIK(robot)
    good = robot.frame_pose(robot.home, "left_ee")
    ik.step({"left_ee": good})  # the rotation block is now known: later targets with it check the translation only
    bad_cases = {
        "nan translation": (0, 3, np.nan),
        "inf translation": (2, 3, np.inf),
        "nan rotation": (1, 1, np.nan),
        "scaled rotation": (0, 0, 2.0 * good[0, 0] + 0.5),
        "last row": (3, 0, 0.1),
    }
    for label, (i, j, value) in bad_cases.items():
        T = good.copy()
        T[i, j] = value
        with pytest.raises(InvalidInputError, match=r"targets\['left_ee'\]"):
            ik.step({"left_ee": T})
        assert np.array_equal(ik.tasks["left_ee"].target, good), label  # the last good target is kept
    reflection = good.copy()
    reflection[:3, 0] *= -1.0  # orthonormal, determinant -1
    with pytest.raises(InvalidInputError, match="rotation"):
        ik.step({"left_ee": reflection})
    rotated = good.copy()
    rotated[:3, :3] = pin.exp3(np.array([0.0, 0.0, 0.2])) @ good[:3, :3]
    ik.step({"left_ee": rotated})  # a new valid rotation is accepted
    assert np.array_equal(ik.tasks["left_ee"].target, rotated)
    fortran = np.asfortranarray(good)  # memory order does not matter
    ik.step({"left_ee": fortran})
    assert np.array_equal(ik.tasks["left_ee"].target, good)


def test_vectorised_capsule_distances_match_the_scalar_reference(robot, rng):
    from taplan.ik import Kinematics
    from taplan.ik.limits import capsule_pair_distance
    from taplan.ik.limits.collision_limit import _PairArrays

    pairs = robot.capsule_pairs("left", "right")
    arrays = _PairArrays(robot.model, pairs)
    kin = Kinematics(robot.model)
    lim = robot.limits
    checked = close = 0
    for _ in range(300):
        kin.update(rng.uniform(lim.lower, lim.upper))
        d, grads = arrays.evaluate(kin)
        for i, (a, b) in enumerate(pairs):
            d_ref, g_ref, _, _ = capsule_pair_distance(kin, a, b)
            assert abs(d[i] - d_ref) <= 1e-12  # [m]
            assert np.abs(grads[i] - g_ref).max() <= 1e-10  # [m/rad]
            checked += 1
            close += d_ref < 0.1
    assert checked == 300 * len(pairs) and close > 0  # near pairs (the ones that matter) were among them
