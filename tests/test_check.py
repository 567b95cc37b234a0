"""taplan.check: metrics on analytic profiles, pass/fail, report serialisation, bad inputs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from taplan.check import Report, Thresholds, check, ldlj, sparc
from taplan.errors import InvalidInputError
from taplan.limits import JointLimits
from taplan.reference import IndustrialSimulator, JointStateSamples, Replay
from taplan.trajectory import Trajectory, Waypoint

JERK_TOL = 1e-6  # [rad]/[s]³ relative
VEL_TOL = 1e-9  # [rad]/[s]
LDLJ_TOL = 0.02  # [-]

NAMES = ("a", "b")


def limits(vel: float = 10.0, acc: float = 100.0, jerk: float = 1000.0) -> JointLimits:
    return JointLimits.from_arrays(NAMES, [-5, -5], [5, 5], [vel, vel], [acc, acc], [jerk, jerk])


def min_jerk(D: float = 1.0, T: float = 2.0) -> Trajectory:
    """The quintic minimum-jerk reach 0 -> D in T, as a 2-knot quintic (second joint still)."""
    return Trajectory([0.0, T], [[0.0, 0.0], [D, 0.0]], np.zeros((2, 2)), np.zeros((2, 2)), NAMES)


def test_quintic_peak_jerk_velocity_and_ldlj() -> None:
    D, T = 1.0, 2.0
    report = check(min_jerk(D, T), limits(), rate=1000.0)
    a = report.joint("a")
    assert a.peak_jerk == pytest.approx(60 * D / T**3, rel=JERK_TOL)  # at both ends
    assert a.peak_velocity == pytest.approx(1.875 * D / T, rel=1e-9)
    assert a.peak_acceleration == pytest.approx(10 / np.sqrt(3) * D / T**2, rel=1e-5)
    assert a.ldlj == pytest.approx(-np.log(720 / 1.875**2), abs=LDLJ_TOL)  # -5.32
    assert -2.0 < a.sparc < -1.3  # a smooth single-peaked profile
    assert np.isnan(report.joint("b").sparc) and np.isnan(report.joint("b").ldlj)
    assert report.passed


def test_velocity_step_of_a_linear_plan_is_measured_at_the_waypoint() -> None:
    traj = Trajectory([0.0, 1.0, 2.0], [[0.0, 0.0], [1.0, 0.0], [1.5, 0.0]], joint_names=NAMES)
    report = check(traj, limits(acc=10.0), rate=100.0)  # step limit 10 * 0.01 = 0.1 rad/s
    a = report.joint("a")
    assert a.max_velocity_step_at_waypoint == pytest.approx(0.5, abs=1e-6)  # slope 1 -> 0.5
    assert a.max_velocity_step == pytest.approx(0.5, abs=1e-6)
    assert not a.passed and any("velocity step" in f for f in a.failures)


def test_limit_violations_fail_per_joint() -> None:
    report = check(min_jerk(D=1.0, T=2.0), limits(vel=0.5))
    assert not report.passed
    assert any(f.startswith("a: velocity") for f in report.failures)
    assert report.joint("b").passed
    out = check(Trajectory([0, 1], [[0.0, 0.0], [6.0, 0.0]], joint_names=NAMES), limits(), rate=100.0)
    assert out.joint("a").position_violation == pytest.approx(1.0)


def test_stream_velocity_step_and_timing() -> None:
    t = np.arange(1, 101) * 0.01
    v = np.where(t < 0.5, 0.0, 1.0)  # a 1 rad/s velocity step at 0.5 s
    q = np.cumsum(v) * 0.01
    r = Replay("test", NAMES, t, np.c_[q, q * 0], np.c_[v, v * 0], None, 100.0, np.zeros(2), np.zeros(2))
    report = check(r, limits(acc=1000.0))
    assert report.joint("a").max_velocity_step == pytest.approx(1.0, abs=VEL_TOL)
    assert report.timing is not None and report.timing.passed and report.timing.jitter_rms < 1e-12
    gap = np.delete(t, [40, 41, 42])  # a 40 ms gap
    r2 = Replay("gap", NAMES, gap, np.zeros((97, 2)), np.zeros((97, 2)), None, 100.0, np.zeros(2), np.zeros(2))
    rep2 = check(r2, limits())
    assert rep2.timing.gaps == 1 and not rep2.passed


def test_dropped_waypoints_fail_the_report() -> None:
    wps = [Waypoint(0.0, np.zeros(2)), Waypoint(0.5, np.ones(2))]
    r = IndustrialSimulator().replay(wps, joint_names=NAMES)
    report = check(r, limits())
    assert report.dropped_waypoints == (1,) and not report.passed


def test_report_table_and_json_roundtrip() -> None:
    report = check(min_jerk(), limits())
    text = str(report)
    assert "PASS" in text and "SPARC" in text and text == report.table()
    data = json.loads(report.to_json())
    assert data["passed"] is True and data["joints"][1]["sparc"] is None  # NaN -> null
    assert data["thresholds"]["gap_factor"] == Thresholds().gap_factor
    assert isinstance(report, Report)


def test_samples_source_and_joint_state_samples() -> None:
    traj = Trajectory([0.0, 1.0], [[0.0, 0.0], [0.5, 0.0]], [[0.0, 0.0], [0.0, 0.0]], joint_names=NAMES)
    r = IndustrialSimulator().replay(traj)
    rep = check(r, limits(), source="samples")
    assert rep.source == "samples" and rep.rate == pytest.approx(10.0)
    s = r.samples
    rep2 = check(JointStateSamples(s.times, s.positions, s.velocities, 10.0, joint_names=NAMES), limits())
    assert rep2.timing.passed


def test_sparc_and_ldlj_direct() -> None:
    t = np.linspace(0, 1, 1001)
    v = 30 * t**2 * (1 - t) ** 2  # minimum-jerk velocity, D = 1, T = 1
    j = 60 - 360 * t + 360 * t**2
    assert ldlj(v, j, 1000.0) == pytest.approx(-np.log(204.8), abs=LDLJ_TOL)
    assert sparc(v, 1000.0) > sparc(v + 0.3 * np.sin(2 * np.pi * 4 * t), 1000.0) + 0.2  # ripple is less smooth
    assert np.isnan(sparc(np.zeros(10), 100.0))


@pytest.mark.parametrize(
    "bad",
    [
        lambda: check(Trajectory([0, 1], [[0.0, 0.0], [1.0, 0.0]], joint_names=NAMES), limits(), rate=0.0),
        lambda: check("not a plan", limits()),  # type: ignore[arg-type]
        lambda: sparc([0.0, np.nan, 1.0], 100.0),
        lambda: ldlj([0.0, 1.0], [0.0], 100.0),
        lambda: check(
            Replay(
                "x",
                NAMES,
                np.array([0.02, 0.01]),
                np.zeros((2, 2)),
                np.zeros((2, 2)),
                None,
                100.0,
                np.zeros(2),
                np.zeros(2),
            ),
            limits(),
        ),
        lambda: check(
            Replay(
                "x",
                NAMES,
                np.array([0.01, 0.02]),
                np.full((2, 2), np.nan),
                np.zeros((2, 2)),
                None,
                100.0,
                np.zeros(2),
                np.zeros(2),
            ),
            limits(),
        ),
    ],
)
def test_bad_inputs_raise(bad) -> None:  # noqa: ANN001
    with pytest.raises(InvalidInputError):
        bad()


def test_default_limits_are_teleavatar_hardware(teleavatar) -> None:  # noqa: ANN001
    names = teleavatar.joint_names[:2]
    traj = Trajectory([0, 1], [teleavatar.home[:2], teleavatar.home[:2] + 0.1], joint_names=names)
    report = check(traj)
    assert report.joint(names[0]).velocity_limit == pytest.approx(teleavatar.limits.velocity[0])
