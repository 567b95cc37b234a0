"""taplan.trajectory: interpolation, validation, waypoints, selection, polynomial form, concatenation, save/load."""

from __future__ import annotations

import numpy as np
import pytest

from taplan.errors import ConfigError, InvalidInputError, UnknownNameError
from taplan.trajectory import Trajectory, concatenate

POS_TOL = 1e-12  # [rad]
VEL_TOL = 1e-9  # [rad]/[s]
ACC_TOL = 1e-9  # [rad]/[s]^2

TIMES = np.array([0.0, 0.5, 1.5])
Q = np.array([[0.0, 1.0], [0.5, 0.0], [1.0, 2.0]])
V = np.array([[0.0, 0.0], [1.0, -1.0], [0.0, 0.0]])
A = np.array([[0.0, 0.0], [0.5, 2.0], [0.0, 0.0]])


@pytest.fixture(params=["linear", "cubic", "quintic"])
def traj(request: pytest.FixtureRequest) -> Trajectory:
    fields = {"linear": (None, None), "cubic": (V, None), "quintic": (V, A)}[request.param]
    return Trajectory(TIMES, Q, *fields, joint_names=["a", "b"])


def test_interpolates_samples_and_fields(traj: Trajectory) -> None:
    np.testing.assert_allclose(traj(TIMES), Q, atol=POS_TOL)
    if traj.velocities is not None:
        np.testing.assert_allclose(traj(TIMES, 1), V, atol=VEL_TOL)
    if traj.accelerations is not None:
        np.testing.assert_allclose(traj(TIMES, 2), A, atol=ACC_TOL)
    assert traj.duration == 1.5
    assert traj(5.0).tolist() == Q[-1].tolist()  # held after the end


def test_linear_midpoint() -> None:
    traj = Trajectory(TIMES, Q)
    np.testing.assert_allclose(traj(0.25), [0.25, 0.5], atol=POS_TOL)
    np.testing.assert_allclose(traj(0.25, 1), [1.0, -2.0], atol=VEL_TOL)


def test_velocity_is_derivative_of_position(traj: Trajectory) -> None:
    t = np.linspace(0.01, 1.49, 50)
    h = 1e-6
    fd = (traj(t + h) - traj(t - h)) / (2 * h)
    np.testing.assert_allclose(traj(t, 1), fd, atol=1e-5)


@pytest.mark.parametrize(
    ("times", "positions", "match"),
    [
        ([0.0, 1.0, 1.0], Q, "strictly increasing"),
        ([0.0, 2.0, 1.0], Q, "strictly increasing"),
        ([0.0, 1.0, np.nan], Q, "finite"),
        (TIMES, Q[:2], "one row per time"),
        ([0.0], Q[:1], "at least 2"),
        (TIMES, [[0.0, np.inf], [0, 0], [0, 0]], "finite"),
    ],
)
def test_validation(times: object, positions: object, match: str) -> None:
    with pytest.raises(InvalidInputError, match=match):
        Trajectory(times, positions)


def test_validation_of_fields() -> None:
    with pytest.raises(InvalidInputError, match="velocities"):
        Trajectory(TIMES, Q, V[:, :1])
    with pytest.raises(InvalidInputError, match="accelerations"):
        Trajectory(TIMES, Q, None, A)
    with pytest.raises(InvalidInputError, match="joint_names"):
        Trajectory(TIMES, Q, joint_names=["a", "a"])
    with pytest.raises(InvalidInputError, match="order"):
        Trajectory(TIMES, Q)(0.0, order=4)


def test_waypoints_round_trip(traj: Trajectory) -> None:
    wps = traj.waypoints(velocities=True, accelerations=True)
    assert [w.time_from_start for w in wps] == TIMES.tolist()
    again = Trajectory.from_waypoints(wps, traj.joint_names)
    np.testing.assert_allclose(again(TIMES), Q, atol=POS_TOL)


def test_select_and_shift(traj: Trajectory) -> None:
    sub = traj.select(["b"])
    np.testing.assert_allclose(sub(0.7), traj(0.7)[1:], atol=POS_TOL)
    with pytest.raises(UnknownNameError):
        traj.select(["c"])
    shifted = traj.shifted(2.0)
    np.testing.assert_allclose(shifted(2.7), traj(0.7), atol=POS_TOL)


def test_resample_keeps_motion() -> None:
    traj = Trajectory(TIMES, Q, V, A)
    res = traj.resample(100.0)
    assert res.interpolation == "quintic"
    t = np.linspace(0, 1.5, 31)
    np.testing.assert_allclose(res(t), traj(t), atol=1e-6)


def test_polynomial_form_matches_hermite(traj: Trajectory) -> None:
    poly = Trajectory.from_polynomials(
        traj.times, traj.coefficients, traj.joint_names, continuous_velocity=traj.interpolation != "linear"
    )
    assert poly.interpolation == "polynomial"
    t = np.linspace(0.0, 1.5, 101)
    for order in (0, 1, 2, 3):
        inner = t[(t > 0) & (t < 1.5)]
        np.testing.assert_allclose(poly(inner, order), traj(inner, order), atol=1e-9)


def test_polynomial_rejects_jumps() -> None:
    c = np.zeros((2, 2, 1))
    c[1, 0, 0] = 1.0  # second segment starts at 1, first ends at 0
    with pytest.raises(InvalidInputError, match="position jump"):
        Trajectory.from_polynomials([0.0, 1.0, 2.0], c)


def test_concatenate_is_exact() -> None:
    first = Trajectory(TIMES, Q, V, A)
    second = Trajectory([0.0, 1.0], [Q[-1], Q[0]], np.zeros((2, 2)), np.zeros((2, 2)))
    joined = concatenate([first, second])
    assert joined.duration == pytest.approx(2.5)
    np.testing.assert_allclose(joined(2.5), Q[0], atol=POS_TOL)
    np.testing.assert_allclose(joined(0.7), first(0.7), atol=POS_TOL)
    np.testing.assert_allclose(joined(2.0), second(0.5), atol=POS_TOL)
    with pytest.raises(InvalidInputError, match="trajectories"):
        concatenate([first, first])


@pytest.mark.parametrize("suffix", [".csv", ".json", ".npz"])
def test_save_load_round_trip(traj: Trajectory, suffix: str, tmp_path) -> None:  # noqa: ANN001
    loaded = Trajectory.load(traj.save(tmp_path / f"t{suffix}"))
    assert loaded.joint_names == traj.joint_names
    assert loaded.interpolation == traj.interpolation
    t = np.linspace(0, 1.5, 37)
    np.testing.assert_allclose(loaded(t), traj(t), atol=1e-12)


@pytest.mark.parametrize("suffix", [".json", ".npz"])
def test_polynomial_save_load_is_exact(suffix: str, tmp_path) -> None:  # noqa: ANN001
    c = np.zeros((2, 7, 1))
    c[0, 6, 0] = 1.0
    c[1, 0, 0] = 1.0
    c[1, 1, 0] = 6.0
    c[1, 2, 0] = 15.0
    traj = Trajectory.from_polynomials([0.0, 1.0, 2.0], c, ["j"])
    loaded = Trajectory.load(traj.save(tmp_path / f"p{suffix}"))
    t = np.linspace(0, 2, 41)
    np.testing.assert_allclose(loaded(t, 2), traj(t, 2), atol=ACC_TOL)


def test_load_errors(tmp_path) -> None:  # noqa: ANN001
    with pytest.raises(ConfigError, match="not found"):
        Trajectory.load(tmp_path / "missing.json")
    bad = tmp_path / "bad.csv"
    bad.write_text("t,a\n0,1\n")
    with pytest.raises(ConfigError):
        Trajectory.load(bad)
    with pytest.raises(InvalidInputError, match="path"):
        Trajectory(TIMES, Q).save(tmp_path / "x.txt")


def test_stretched_scales_derivatives_exactly():
    t = np.array([0.0, 0.4, 1.0])
    q = np.array([[0.0], [0.3], [0.5]])
    v = np.array([[0.0], [0.6], [0.0]])
    a = np.zeros((3, 1))
    base = Trajectory(t, q, v, a)
    slow = base.stretched(2.0)
    assert slow.duration == pytest.approx(2.0)
    probe = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(slow(2.0 * probe), base(probe), atol=1e-12)
    np.testing.assert_allclose(slow(2.0 * probe, 1), base(probe, 1) / 2.0, atol=1e-12)
    np.testing.assert_allclose(slow(2.0 * probe, 2), base(probe, 2) / 4.0, atol=1e-12)
    np.testing.assert_allclose(slow(2.0 * probe, 3), base(probe, 3) / 8.0, atol=1e-9)
    with pytest.raises(InvalidInputError, match="factor"):
        base.stretched(0.0)
