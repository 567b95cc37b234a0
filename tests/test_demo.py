"""`taplan demo`: plans pass their checks, the guide's approaches show the velocity steps taplan's plans avoid."""

from __future__ import annotations

import json

import numpy as np
import pytest

import taplan
from taplan.cli import main
from taplan.demo import run_demo

POSE_TOL = 1e-3  # [m]


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    return run_demo(tmp_path_factory.mktemp("demo"), plots=False)


def test_every_plan_passes_every_reference_controller(demo):
    assert [p.name for p in demo.plans] == ["reach", "line", "pick", "scene", "seen"]
    for plan in demo.plans:
        for label, report in plan.reports.items():
            assert report.passed, (plan.name, label, report.failures)


def test_plans_respect_the_planning_limits_and_start_at_home(demo):
    robot = taplan.Robot.teleavatar()
    limits = robot.planning_limits
    for plan in demo.plans:
        traj = plan.trajectory
        t = np.linspace(traj.times[0], traj.times[-1], 3001)
        if plan.name != "line":  # the line starts where the reach ends
            np.testing.assert_allclose(traj.positions[0], robot.home, atol=1e-12)
        assert np.all(np.abs(traj(t, 1)) <= limits.velocity * (1 + 1e-6))
        assert np.all(np.abs(traj(t, 2)) <= limits.acceleration * (1 + 1e-6))
        assert np.all(np.abs(traj(t, 3)) <= limits.jerk * (1 + 1e-6))
        assert traj.duration * 100 == pytest.approx(round(traj.duration * 100), abs=1e-6)  # on the 10 ms grid


def test_the_reach_plan_reaches_its_pose_targets(demo):
    from taplan.demo import READY_POSE

    robot = taplan.Robot.teleavatar()
    end = demo.plans[0].trajectory.positions[-1]
    for frame in ("left_ee", "right_ee"):
        error = robot.frame_pose(end, frame)[:3, 3] - robot.frame_pose(READY_POSE, frame)[:3, 3]
        assert np.linalg.norm(error) < POSE_TOL


def test_guide_linear_interpolation_has_velocity_steps_taplan_does_not(demo):
    by_name = {c.approach: c for c in demo.comparisons}
    linear = by_name["guide: linear @50 Hz, position target"].report
    ours = by_name["taplan: jerk-limited @100 Hz"].report
    assert not linear.passed and ours.passed
    worst = max(linear.joints, key=lambda j: j.max_velocity_step / j.acceleration_limit)
    assert worst.max_velocity_step > 5 * max(j.max_velocity_step for j in ours.joints)
    # a step the arm cannot follow within its acceleration ceiling in one 10 ms update
    assert worst.max_velocity_step > worst.acceleration_limit * 0.01
    assert all(j.max_velocity_step <= j.acceleration_limit * 0.01 for j in ours.joints)


def test_outputs_are_written(demo):
    names = {p.name for p in demo.files}
    assert {"reach_100hz.csv", "line_100hz.csv", "pick_100hz.csv", "report.json", "scene.html"} <= names
    report = json.loads((demo.out_dir / "report.json").read_text())
    assert set(report["plans"]) == {"reach", "line", "pick", "scene", "seen"}
    reloaded = taplan.Trajectory.load(demo.out_dir / "pick_100hz.csv")
    np.testing.assert_allclose(reloaded.positions[-1], demo.plans[2].trajectory.positions[-1], atol=1e-9)


def test_cli_demo_exit_code_and_report(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "out"), "--no-plots"]) == 0
    out = capsys.readouterr().out
    assert "guide: linear @50 Hz" in out and "PASS" in out
    assert (tmp_path / "out" / "report.json").exists()


def test_scene_plan_is_collision_free_and_reaches_across_the_box(demo):
    from taplan.demo import SCENE_FILE, SCENE_REACH_RIGHT
    from taplan.planning import check_segment, verify_trajectory
    from taplan.scene import CollisionWorld, load_scene

    robot = taplan.Robot.teleavatar()
    world = CollisionWorld(robot, load_scene(SCENE_FILE))
    plan = next(p for p in demo.plans if p.name == "scene")
    assert verify_trajectory(world, plan.trajectory, floor=0.0, hold=robot.home).collision_free
    goal = robot.home.copy()
    goal[7:] = SCENE_REACH_RIGHT
    assert not check_segment(world, robot.home, goal, 0.01).valid  # the straight motion would collide
    end = robot.frame_pose(plan.trajectory(plan.trajectory.duration), "right_tcp")[:3, 3]
    np.testing.assert_allclose(end, robot.frame_pose(goal, "right_tcp")[:3, 3], atol=POSE_TOL)


def test_seen_plan_avoids_the_true_scene_it_was_perceived_from(demo):
    from taplan.demo import SCENE_FILE, SCENE_REACH_RIGHT
    from taplan.planning import verify_trajectory
    from taplan.scene import CollisionWorld, load_scene

    robot = taplan.Robot.teleavatar()
    plan = next(p for p in demo.plans if p.name == "seen")
    truth = CollisionWorld(robot, load_scene(SCENE_FILE))
    assert verify_trajectory(truth, plan.trajectory, floor=0.0, hold=robot.home).collision_free
    assert "voxels" in plan.notes[0] and "collision-free" in plan.notes[1]
    goal = robot.home.copy()
    goal[7:] = SCENE_REACH_RIGHT
    end = robot.frame_pose(plan.trajectory(plan.trajectory.duration), "right_tcp")[:3, 3]
    np.testing.assert_allclose(end, robot.frame_pose(goal, "right_tcp")[:3, 3], atol=POSE_TOL)


def test_the_report_a_person_reads(demo, tmp_path):
    """report.md beside report.json: per plan a table of every check and its pictures, then the guide comparison."""
    from taplan.demo import write_markdown_report

    text = (demo.out_dir / "report.md").read_text()
    for plan in demo.plans:
        assert f"## {plan.name}: {plan.description}" in text
        for label in plan.reports:
            assert f"| {label} | " in text
    assert "| guide: linear @50 Hz, position target | " in text and "**PASS**" in text and "**FAIL**" in text
    assert "![" not in text  # no pictures were drawn (plots=False): none linked
    with_plots = write_markdown_report(tmp_path / "report.md", demo.plans, demo.comparisons, plots=True).read_text()
    pictures = [line[line.index("(") + 1 : -1] for line in with_plots.splitlines() if line.startswith("![")]
    expected = {f"{p.name}_{kind}.png" for p in demo.plans for kind in ("plan", "jtc")} | {"guide_vs_taplan.png"}
    assert set(pictures) == expected  # the names write_outputs saves the plots under
