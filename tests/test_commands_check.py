"""`taplan check` / `taplan replay` exit codes and outputs (run() called directly)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from taplan.commands import check as check_cmd
from taplan.commands import replay as replay_cmd
from taplan.trajectory import Trajectory


def parse(module, argv: list[str]) -> argparse.Namespace:  # noqa: ANN001
    parser = argparse.ArgumentParser()
    module.add_arguments(parser)
    return parser.parse_args(argv)


@pytest.fixture
def smooth_plan(tmp_path: Path, teleavatar) -> Path:  # noqa: ANN001
    names = teleavatar.joint_names[:7]
    q0 = teleavatar.home[:7]
    traj = Trajectory([0.0, 2.0], [q0, q0 + 0.1], np.zeros((2, 7)), np.zeros((2, 7)), names)
    return traj.save(tmp_path / "plan.json")


@pytest.fixture
def bad_plan(tmp_path: Path, teleavatar) -> Path:  # noqa: ANN001
    names = teleavatar.joint_names[:7]
    q0 = teleavatar.home[:7]
    traj = Trajectory([0.0, 0.05], [q0, q0 + 1.5], joint_names=names)  # 30 rad/s, beyond every limit
    return traj.save(tmp_path / "bad.csv")


def test_check_passes_and_writes_png_and_json(smooth_plan: Path, capsys) -> None:  # noqa: ANN001
    out_json = smooth_plan.with_name("report.json")
    code = check_cmd.run(parse(check_cmd, [str(smooth_plan), "--json", str(out_json)]))
    assert code == 0
    assert "PASS" in capsys.readouterr().out
    assert smooth_plan.with_name("plan_check.png").stat().st_size > 1000
    assert json.loads(out_json.read_text())["passed"] is True


def test_check_fails_with_exit_code_1(bad_plan: Path) -> None:
    assert check_cmd.run(parse(check_cmd, [str(bad_plan), "--no-png"])) == 1


def test_check_through_controllers(smooth_plan: Path) -> None:
    for controller in ("intended", "jtc", "joint-position"):
        code = check_cmd.run(parse(check_cmd, [str(smooth_plan), "--controller", controller, "--no-png", "--no-jerk"]))
        assert code in (0, 1)
    # a plan with only positions is dropped by the seed's linear branch: fails
    names = [f"l_joint{i}" for i in range(1, 8)]
    data = json.loads(smooth_plan.read_text())
    lin = Trajectory(data["times"], data["positions"], joint_names=names).save(smooth_plan.with_name("lin.npz"))
    assert check_cmd.run(parse(check_cmd, [str(lin), "--controller", "seed", "--no-png"])) == 1


def test_planning_limits_are_stricter(smooth_plan: Path, tmp_path: Path, teleavatar) -> None:  # noqa: ANN001
    names = teleavatar.joint_names[:7]
    q0 = teleavatar.home[:7]
    v = 0.5 * teleavatar.limits.velocity[:7]  # above the planning limit (0.3 x), below hardware
    traj = Trajectory([0.0, 0.1], [q0, q0 + v * 0.1], joint_names=names).save(tmp_path / "fast.json")
    hw = check_cmd.run(parse(check_cmd, [str(traj), "--no-png", "--no-jerk", "--rate", "100"]))
    plan = check_cmd.run(
        parse(check_cmd, [str(traj), "--no-png", "--no-jerk", "--rate", "100", "--limits", "planning"])
    )
    assert plan == 1 and hw in (0, 1)


def test_replay_writes_streams(smooth_plan: Path, tmp_path: Path) -> None:
    for suffix in ("json", "npz", "csv"):
        out = tmp_path / f"replay.{suffix}"
        assert replay_cmd.run(parse(replay_cmd, [str(smooth_plan), "--controller", "seed", "-o", str(out)])) == 0
        assert out.exists()
    assert (tmp_path / "replay_joint_states.csv").exists()
    data = json.loads((tmp_path / "replay.json").read_text())
    assert data["controller"] == "industrial_simulator[seed]" and data["samples"]["rate"] == 10.0


def test_missing_file_is_a_taplan_error(tmp_path: Path) -> None:
    from taplan.errors import TaplanError

    with pytest.raises(TaplanError):
        check_cmd.run(parse(check_cmd, [str(tmp_path / "nope.json")]))


def test_cli_main_dispatches_check(smooth_plan: Path) -> None:
    from taplan.cli import main

    assert main(["check", str(smooth_plan), "--no-png"]) == 0
    assert main(["check", str(smooth_plan.with_name("missing.json"))]) == 2
