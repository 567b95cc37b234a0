"""taplan plan --scene: collision-free legs between waypoints, and the errors a user sees."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import taplan
from taplan.cli import main
from taplan.planning import verify_trajectory
from taplan.scene import CollisionWorld, load_scene

SCENE = Path(__file__).resolve().parents[1] / "models" / "teleavatar" / "scenes" / "table.yaml"


def _waypoints(tmp_path: Path, rows: list[np.ndarray]) -> Path:
    path = tmp_path / "waypoints.csv"
    header = ",".join(f"l_joint{i}" for i in range(1, 8))
    np.savetxt(path, np.array(rows), delimiter=",", header=header, comments="")
    return path


def test_plan_with_a_scene_writes_a_verified_trajectory(tmp_path: Path, capsys) -> None:
    robot = taplan.Robot.teleavatar()
    home = robot.home[:7]
    path = _waypoints(tmp_path, [home, home + [0.4, 0.2, 0.0, -0.3, 0.0, 0.2, 0.0], home])
    out = tmp_path / "planned.json"
    assert main(["plan", str(path), "--scene", str(SCENE), "-o", str(out)]) == 0
    assert "2 legs" in capsys.readouterr().out
    trajectory = taplan.Trajectory.load(out)
    np.testing.assert_allclose(trajectory(0.0)[:7], home, atol=1e-9)
    verdict = verify_trajectory(CollisionWorld(robot, load_scene(SCENE)), trajectory, floor=0.0)
    assert verdict.collision_free and verdict.min_clearance > 0.0


def test_plan_with_a_waypoint_in_the_table_names_the_pair(tmp_path: Path, capsys) -> None:
    robot = taplan.Robot.teleavatar()
    world = CollisionWorld(robot, load_scene(SCENE))
    rng = np.random.default_rng(0)
    lower, upper = robot.planning_limits.lower[:7], robot.planning_limits.upper[:7]
    for _ in range(500):  # a seeded left-arm configuration that reaches into the table
        q = robot.home.copy()
        q[:7] = lower + rng.uniform(0, 1, 7) * (upper - lower)
        distance, pair = world.min_distance(q)
        if distance < -0.005 and pair[1] in ("table", "box"):
            break
    else:
        raise AssertionError("no colliding configuration found")
    path = _waypoints(tmp_path, [robot.home[:7], q[:7]])
    assert main(["plan", str(path), "--scene", str(SCENE)]) == 2
    err = capsys.readouterr().err
    assert "goal" in err and pair[1] in err and "mm" in err


def test_plan_refuses_a_scene_in_an_unknown_frame(tmp_path: Path, capsys) -> None:
    robot = taplan.Robot.teleavatar()
    scene = tmp_path / "world.yaml"
    scene.write_text(SCENE.read_text().replace("frame: shoulder_base", "frame: world"))
    path = _waypoints(tmp_path, [robot.home[:7], robot.home[:7] + 0.1])
    assert main(["plan", str(path), "--scene", str(scene)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("taplan plan: error: ") and "'world'" in err and "base_link" in err
    assert not (tmp_path / "waypoints_planned.json").exists()


def test_hardware_limits_never_plan_slower_than_the_planning_limits(tmp_path: Path, capsys) -> None:
    """Issue 23: with the hardware limits the fastest timing cut the box and the retry crawled (20.2 s against
    0.93 s); now the fallback is the fastest timing that verifies. (That goal, joint 2 at -1.537, put the upper arm
    into the shoulders' real body; at -1.42 the fastest timing verifies at once, so no fallback is reported here.)"""
    robot = taplan.Robot.teleavatar()
    rows = [robot.home[7:], np.array([-0.694, -1.42, 1.399, -1.306, -0.263, -0.369, -0.403])]  # across the box
    path = tmp_path / "waypoints.csv"
    np.savetxt(path, np.array(rows), delimiter=",", header=",".join(robot.joint_names[7:]), comments="")
    durations = {}
    for limits in ("planning", "hardware"):
        out = tmp_path / f"{limits}.json"
        assert main(["plan", str(path), "--scene", str(SCENE), "--limits", limits, "-o", str(out)]) == 0
        durations[limits] = taplan.Trajectory.load(out).duration
        capsys.readouterr()
    assert durations["hardware"] <= durations["planning"]  # [s]
    hardware = taplan.Trajectory.load(tmp_path / "hardware.json")
    world = CollisionWorld(robot, load_scene(SCENE))
    assert verify_trajectory(world, hardware, floor=0.0).collision_free


def test_a_timing_fallback_is_reported_in_the_plan_and_on_the_command_line(tmp_path: Path, capsys, monkeypatch) -> None:
    """Issue 23: whenever a plan falls back to a slower timing, the report and the CLI say so. On the real body no
    goal we tried makes the fastest timing cut the box, so the fastest timing's certificate is made to fail here (the
    first verification of the timed path: an independent refusal, as a too-close corner would be)."""
    import dataclasses

    import taplan.planning.motion as motion

    real = motion.verify_trajectory
    refused: list[float] = []

    def refuse_the_first_timing(world, trajectory, **options):  # noqa: ANN001, ANN202 (a stand-in)
        check = real(world, trajectory, **options)
        if not refused and options.get("floor", 0.0) < 0.01:  # the timed path's certificate (floor = margin / 4)
            refused.append(trajectory.duration)
            return dataclasses.replace(check, collision_free=False, min_clearance=0.001, pair=("right_link6", "box"))
        return check

    monkeypatch.setattr(motion, "verify_trajectory", refuse_the_first_timing)
    monkeypatch.setattr(motion, "_on_certified_segment", lambda *args: False)  # the straight certificate is not reused
    robot = taplan.Robot.teleavatar()
    rows = [robot.home[7:], np.array([-0.694, -1.42, 1.399, -1.306, -0.263, -0.369, -0.403])]  # across the box
    path = tmp_path / "waypoints.csv"
    np.savetxt(path, np.array(rows), delimiter=",", header=",".join(robot.joint_names[7:]), comments="")
    out = tmp_path / "plan.json"
    assert main(["plan", str(path), "--scene", str(SCENE), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert refused, "the fastest timing was never verified"
    assert "timing fell back to" in printed and f"the fastest timing, {refused[0]:.3f} s" in printed
    assert taplan.Trajectory.load(out).duration >= refused[0] - 1e-9  # [s] the fallback is no faster than the refused

    world = CollisionWorld(robot, load_scene(SCENE))
    refused.clear()
    plan = taplan.planning.plan_motion(robot, robot.home, np.concatenate([robot.home[:7], rows[1]]), world=world)
    assert plan.report.timing_fallback.startswith("timing fell back to")
    assert plan.report.timing_fallback in plan.report.notes
