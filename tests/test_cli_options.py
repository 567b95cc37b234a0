"""Every option is honoured or refused, never ignored (issue 23): an option the chosen mode would not use, or a value
outside its range, is one line ``taplan CMD: error: --option: ...``, exit 2, before any work or output."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import taplan
from taplan.cli import main
from taplan.errors import InvalidInputError

SCENE = str(Path(__file__).resolve().parents[1] / "models" / "teleavatar" / "scenes" / "table.yaml")


@pytest.fixture
def files(tmp_path: Path) -> dict[str, str]:
    robot = taplan.Robot.teleavatar()
    waypoints = tmp_path / "waypoints.csv"
    rows = np.array([robot.home[:7], robot.home[:7] + 0.1])
    np.savetxt(waypoints, rows, delimiter=",", header=",".join(robot.joint_names[:7]), comments="")
    plan = tmp_path / "plan.json"
    taplan.Trajectory(np.array([0.0, 1.0]), rows, joint_names=robot.joint_names[:7]).save(plan)
    bag = tmp_path / "run.mcap"
    bag.write_bytes(b"")  # refused on its options before it is read
    return {"waypoints": str(waypoints), "plan": str(plan), "bag": str(bag), "dir": str(tmp_path)}


CASES = [
    (["plan", "{waypoints}", "--scene", SCENE, "--method", "topp"], "--method: expected no --method with --scene"),
    (["plan", "{waypoints}", "--margin", "0.02"], "--margin: expected no --margin without --scene"),
    (["plan", "{waypoints}", "--scene", SCENE, "--margin", "-1"], "--margin: expected a clearance >= 0"),
    (["plan", "{waypoints}", "--fastest"], "--fastest: expected no --fastest without --recorded"),
    (["plan", "{waypoints}", "--max-deviation", "0.1"], "--max-deviation: expected no --max-deviation without"),
    (["plan", "{waypoints}", "--stream", "commanded"], "--stream: expected no --stream without --recorded"),
    (["plan", "{waypoints}", "--rate", "1e6"], "--rate: expected a rate in [1, 10000] Hz"),
    (["check", "{bag}", "--controller", "seed"], "--controller: expected no --controller with a bag"),
    (["check", "{bag}", "--png", "{dir}/x.png"], "--png: expected no --png with a bag"),
    (["check", "{plan}", "--margin", "0.01"], "--margin: expected no --margin without --scene"),
    (["run", "{plan}", "--state-timeout", "0"], "--state-timeout: expected a positive number"),
    (["run", "{plan}", "--tracking-error", "-1"], "--tracking-error: expected a positive number"),
    (["run", "{plan}", "--wait", "0"], "--wait: expected a positive number"),
    (["run", "{plan}", "--duration", "3"], "--duration: expected no --duration without --targets"),
    (["sim", "--duration", "-1"], "--duration: expected a time > 0 s"),
    (["sim", "--stall-after", "-1"], "--stall-after: expected a time > 0 s"),
    (["run", "{plan}", "--record", "{dir}/run.csv"], "--record: expected a file name ending in .npz"),
]


@pytest.mark.parametrize(("argv", "message"), CASES, ids=[" ".join(a[:1] + a[2:4]) for a, _ in CASES])
def test_option_is_refused_in_one_line(files, capsys, argv, message) -> None:
    before = set(Path(files["dir"]).iterdir())
    assert main([a.format(**files) for a in argv]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"taplan {argv[0]}: error: ") and message in lines[0], lines
    assert captured.out == ""  # nothing was computed or printed first
    assert set(Path(files["dir"]).iterdir()) == before  # and nothing written


def test_library_refuses_negative_margins_and_timeouts() -> None:
    from taplan.planning import check_segment
    from taplan.ros.runner import RunnerConfig
    from taplan.scene import CollisionWorld

    robot = taplan.Robot.teleavatar()
    world = CollisionWorld(robot)
    with pytest.raises(InvalidInputError, match="margin"):
        check_segment(world, robot.home, robot.home, margin=-1.0)
    with pytest.raises(InvalidInputError, match="state_timeout"):
        RunnerConfig(state_timeout=0.0)
    with pytest.raises(InvalidInputError, match="tracking_error"):
        RunnerConfig(tracking_error=-1.0)


def test_every_output_path_creates_its_directories(files, capsys) -> None:
    """One rule (taplan.io.output_path): missing parent directories are created, for every command's outputs."""
    out = Path(files["dir"]) / "new"
    assert main(["plan", files["waypoints"], "-o", str(out / "a" / "p.json")]) == 0
    assert main(["replay", files["plan"], "-o", str(out / "b" / "r.json")]) == 0
    assert main(["check", files["plan"], "--png", str(out / "c" / "x.png"), "--json", str(out / "d" / "x.json")]) == 0
    for written in ("a/p.json", "a/p_100hz.csv", "b/r.json", "c/x.png", "d/x.json"):
        assert (out / written).is_file(), written
