"""taplan check PLAN --scene: the plan's clearance along its whole timed trajectory, the closest pair and time, FAIL
below the margin; and :func:`taplan.planning.scene_clearance` against dense independent samples."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import taplan
from taplan.cli import main
from taplan.errors import InvalidInputError
from taplan.planning import scene_clearance
from taplan.scene import CollisionWorld, load_scene

SCENE = Path(__file__).resolve().parents[1] / "models" / "teleavatar" / "scenes" / "table.yaml"
# the right arm across the box [rad]: joint 2 at -1.537 (the docs' old pose) put the upper arm into the shoulders'
# body; at -1.42 it is 11 mm clear of it, and the straight plan still cuts 49 mm into the box
ACROSS_THE_BOX = [-0.694, -1.42, 1.399, -1.306, -0.263, -0.369, -0.403]
SAMPLE_TOL = 1e-9  # [m]: the reported minimum is one of the evaluated distances, none of the samples is lower


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


@pytest.fixture(scope="module")
def world(robot) -> CollisionWorld:
    return CollisionWorld(robot, load_scene(SCENE, robot))


def _waypoints(tmp_path: Path, robot) -> Path:
    path = tmp_path / "waypoints.csv"
    rows = np.array([robot.home[7:], ACROSS_THE_BOX])
    np.savetxt(path, rows, delimiter=",", header=",".join(robot.joint_names[7:]), comments="")
    return path


def test_scene_clearance_finds_the_deepest_instant(robot, world) -> None:
    from taplan.timing import jerk_limited

    straight = jerk_limited(
        np.array([robot.home[7:], ACROSS_THE_BOX]), robot.planning_limits.subset(robot.joint_names[7:])
    )
    trajectory = straight.trajectory
    result = scene_clearance(world, trajectory)
    assert not result.passed and result.min_clearance < -0.04 and result.pair[1] == "box"
    times = np.linspace(trajectory.times[0], trajectory.times[-1], 801)  # independent, 8x denser than its samples
    q = np.repeat(robot.home[None], len(times), axis=0)
    q[:, 7:] = trajectory(times)
    dense = np.array([world.min_distance(c)[0] for c in q])
    assert result.min_clearance <= dense.min() + 2e-3  # its 100 Hz samples land within 2 mm of the true deepest
    k = int(np.argmin(dense))
    assert abs(result.time - times[k]) < 0.05  # [s]
    with pytest.raises(InvalidInputError, match="margin"):
        scene_clearance(world, trajectory, margin=-0.01)


def test_check_scene_fails_a_plan_through_the_box_and_passes_the_scene_plan(tmp_path: Path, capsys, robot) -> None:
    waypoints = _waypoints(tmp_path, robot)
    blind, planned = tmp_path / "blind.json", tmp_path / "planned.json"
    assert main(["plan", str(waypoints), "-o", str(blind)]) == 0
    assert main(["check", str(blind), "--no-png"]) == 0  # limits alone pass: the plan looks fine without a scene
    capsys.readouterr()
    report = tmp_path / "report.json"
    assert main(["check", str(blind), "--no-png", "--scene", str(SCENE), "--json", str(report)]) == 1
    out = capsys.readouterr().out
    assert "scene clearance: FAIL" in out and "mm inside (right_" in out and "/ box at t = " in out
    data = json.loads(report.read_text())["scene"]
    assert data["passed"] is False and data["min_clearance"] < -0.04 and data["pair"][1] == "box"

    assert main(["plan", str(waypoints), "--scene", str(SCENE), "-o", str(planned)]) == 0
    assert "1 leg -> " in capsys.readouterr().out
    assert main(["check", str(planned), "--no-png", "--scene", str(SCENE)]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert line.startswith("scene clearance: PASS: closest ")
    closest = float(line.split("closest ")[1].split(" mm")[0])
    assert closest >= 2.5  # [mm]: the planner's hard floor
    assert main(["check", str(planned), "--no-png", "--scene", str(SCENE), "--margin", "0.05"]) == 1  # 5 cm asked


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--margin", "0.02"], "--margin: expected no --margin without --scene"),
        (["--scene", str(SCENE), "--margin", "-1"], "--margin: expected a clearance >= 0"),
        (["--scene", "nope.yaml"], "--scene: file not found"),
        (["--update-rate", "50"], "--update-rate: expected no controller rate without a --controller"),
    ],
)
def test_check_scene_options_are_refused_when_meaningless(tmp_path: Path, capsys, robot, extra, message) -> None:
    plan = tmp_path / "plan.json"
    rest = np.array([robot.home[7:], robot.home[7:]])
    taplan.Trajectory(np.array([0.0, 1.0]), rest, joint_names=robot.joint_names[7:]).save(plan)
    assert main(["check", str(plan), "--no-png", *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith("taplan check: error: ") and message in err
