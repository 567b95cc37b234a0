"""Exit codes (0 pass, 1 failed check, 2 bad input) and one-line errors for every defect issue 18 lists."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from taplan.cli import main
from taplan.reference import IndustrialSimulator
from taplan.timing import jerk_limited
from taplan.trajectory import Trajectory, Waypoint


def run_cli(argv: list[str], capsys) -> tuple[int, str, str]:  # noqa: ANN001
    try:
        code = main(argv)
    except SystemExit as exc:
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(code: int, err: str, command: str, *fragments: str) -> None:
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"taplan {command}: error: "), lines[0]
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])


@pytest.fixture(scope="module")
def files(tmp_path_factory, teleavatar) -> dict[str, Path]:  # noqa: ANN001
    root = tmp_path_factory.mktemp("cli")
    q0 = teleavatar.home
    wp = np.array([q0, q0 + 0.1, q0 + 0.2])
    plan = jerk_limited(wp, teleavatar.planning_limits).trajectory
    bad = Trajectory([0.0, 0.05], [q0, q0 + 1.0], joint_names=teleavatar.joint_names)  # 20 rad/s
    (root / "wp.csv").write_text(",".join(teleavatar.joint_names[:2]) + "\n0,0.3\n0.2,0.5\n")
    return {
        "plan": plan.save(root / "plan.json"),
        "bad": bad.save(root / "bad.csv"),
        "wp": root / "wp.csv",
        "empty": root / "empty.csv",
        "list": root / "list.json",
        "root": root,
    }


@pytest.fixture(autouse=True)
def _empty_files(files) -> None:  # noqa: ANN001
    files["empty"].write_text("")
    files["list"].write_text("[]")


@pytest.mark.parametrize("command", ["check", "plan", "replay"])
@pytest.mark.parametrize("which", ["empty", "list"])
def test_empty_csv_and_list_json_are_one_line_errors(files, command: str, which: str, capsys) -> None:  # noqa: ANN001
    extra = ["--no-png"] if command == "check" else ["-o", str(files["root"] / "o" / "x.json")]
    code, out, err = run_cli([command, str(files[which]), *extra], capsys)
    expected = "an empty file" if which == "empty" else "top level: expected a JSON object"
    assert_one_line_error(code, err, command, str(files[which]), expected)


def test_output_in_a_missing_directory_is_created(files, capsys) -> None:  # noqa: ANN001
    root = files["root"]
    code, out, _ = run_cli(["check", str(files["plan"]), "--png", str(root / "new1" / "p.png")], capsys)
    assert code == 0 and (root / "new1" / "p.png").is_file()
    code, *_ = run_cli(["check", str(files["plan"]), "--no-png", "--json", str(root / "new2" / "r.json")], capsys)
    assert code == 0 and (root / "new2" / "r.json").is_file()
    code, *_ = run_cli(["replay", str(files["plan"]), "-o", str(root / "new3" / "a" / "r.json")], capsys)
    assert code == 0 and (root / "new3" / "a" / "r.json").is_file()
    code, *_ = run_cli(["plan", str(files["wp"]), "-o", str(root / "new4" / "t.json")], capsys)
    assert code == 0 and (root / "new4" / "t.json").is_file() and (root / "new4" / "t_100hz.csv").is_file()


def test_png_with_the_wrong_suffix_fails_before_the_verdict(files, capsys) -> None:  # noqa: ANN001
    code, out, err = run_cli(["check", str(files["plan"]), "--png", str(files["root"] / "out.txt")], capsys)
    assert_one_line_error(code, err, "check", "--png", "out.txt", ".png")
    assert "PASS" not in out and out == ""


def test_demo_into_an_existing_file_is_an_error(files, capsys) -> None:  # noqa: ANN001
    code, _, err = run_cli(["demo", "-o", str(files["plan"])], capsys)
    assert_one_line_error(code, err, "demo", "--out", "a directory")


@pytest.mark.parametrize(
    ("argv", "fragments"),
    [
        (["check", "{plan}", "--no-png", "--rate", "1e9"], ["--rate", "[1, 10000] Hz"]),
        (["plan", "{wp}", "-o", "{root}/r.json", "--rate", "1e9"], ["--rate", "[1, 10000] Hz"]),
        (["check", "{plan}", "--no-png", "--controller", "seed", "--update-rate", "0"], ["--update-rate"]),
        (["check", "{plan}", "--no-png", "--controller", "seed", "--jitter", "2"], ["--jitter", "[0, 1)"]),
        (["check", "{plan}", "--no-png", "--controller", "seed", "--jitter", "0.2"], ["--jitter", "joint-position"]),
        (["check", "{plan}", "--no-png", "--source", "samples"], ["--source", "--controller"]),
        (["check", "{wp}", "--no-png"], ["'time'", "waypoint CSV", "taplan plan"]),
        (["check", "{root}/missing.json", "--no-png"], ["not found", "missing.json"]),
        (["info", "--urdf", "{root}/missing.urdf"], ["URDF not found"]),
        (["check", "{plan}", "--bogus"], ["unrecognized arguments: --bogus"]),
        (["plan", "{wp}", "--method", "fast"], ["invalid choice: 'fast'"]),
    ],
)
def test_bad_options_are_one_line_errors(files, argv: list[str], fragments: list[str], capsys) -> None:  # noqa: ANN001
    argv = [a.format(**{k: str(v) for k, v in files.items()}) for a in argv]
    code, out, err = run_cli(argv, capsys)
    assert_one_line_error(code, err, argv[0], *fragments)
    assert "PASS" not in out


def test_urdfdom_noise_is_replaced_by_one_line(files) -> None:  # noqa: ANN001
    urdf = files["root"] / "bad.urdf"
    urdf.write_text(
        "<robot name='x'><link name='a'/><joint name='j' type='revolute'><parent link='a'/><child link='b'/>"
        "</joint><link name='b'/></robot>"
    )
    result = _taplan(["info", "--urdf", str(urdf)])
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("taplan info: error: pinocchio cannot load"), result.stderr
    assert "does not specify limits" in lines[0] and "joint.cpp" not in result.stderr


def _taplan(argv: list[str], **kwargs) -> subprocess.CompletedProcess:  # noqa: ANN003
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    return subprocess.run(
        [sys.executable, "-m", "taplan", *argv], capture_output=True, text=True, env=env, timeout=120, **kwargs
    )


@pytest.mark.parametrize(("which", "expected"), [("bad", 1), ("plan", 0)])
def test_exit_code_is_honest_when_stdout_is_closed(files, which: str, expected: int) -> None:  # noqa: ANN001
    """``taplan check ... | head -1``: the reader goes away after the first line; the code stays 0 / 1."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    argv = [sys.executable, "-m", "taplan", "check", str(files[which]), "--controller", "intended", "--no-png"]
    for read_first_line in (False, True):
        process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
        assert process.stdout is not None and process.stderr is not None
        if read_first_line:
            process.stdout.readline()
        process.stdout.close()  # like head -1, or a reader gone before the first write (every write fails)
        err = process.stderr.read().decode()
        assert process.wait(timeout=120) == expected, err
        assert "Traceback" not in err and "BrokenPipe" not in err


def test_replay_state_with_every_waypoint_dropped_holds_the_initial_state() -> None:
    names = ("l_joint1", "l_joint2")
    points = [Waypoint(0.0, [0.0, 0.5]), Waypoint(0.5, [0.2, 0.6]), Waypoint(1.0, [0.4, 0.7])]
    replay = IndustrialSimulator(mode="seed").replay(points, joint_names=names, initial_positions=[0.1, 0.2])
    assert replay.dropped == (1, 2)
    q, _ = replay.state(0.7)
    np.testing.assert_array_equal(q, [0.0, 0.5])  # never moved past the first point
    q_many, _ = replay.state(np.array([0.0, 2.0]))
    assert q_many.shape == (2, 2)


def test_replay_state_of_an_empty_replay_does_not_index_error() -> None:
    from taplan.reference.replay import Replay

    replay = Replay(
        controller="x",
        joint_names=("a",),
        times=np.zeros(0),
        positions=np.zeros((0, 1)),
        velocities=np.zeros((0, 1)),
        accelerations=None,
        rate=100.0,
        initial_positions=np.array([0.3]),
        initial_velocities=np.zeros(1),
        waypoint_indices=np.zeros(0, dtype=int),
        waypoint_times=np.zeros(0),
        dropped=(0, 1),
    )
    q, v = replay.state(1.0)
    assert q.tolist() == [0.3] and v.tolist() == [0.0]
    assert replay.state(np.array([0.0, 1.0]))[0].shape == (2, 1)


def test_intended_velocity_at_a_point_reached_within_one_update_is_the_segment_slope() -> None:
    """docs/reference.md: a waypoint without velocities reports the slope of the segment that reached it."""
    points = [Waypoint(0.0, [0.0]), Waypoint(0.004, [0.01]), Waypoint(0.5, [0.2]), Waypoint(0.503, [0.2])]
    replay = IndustrialSimulator(mode="intended").replay(points, joint_names=("l_joint1",))
    at = {round(float(t), 6): float(v) for t, v in zip(replay.times, replay.velocities[:, 0], strict=True)}
    assert at[0.004] == pytest.approx(0.01 / 0.004, rel=1e-9)  # 2.5 rad/s, a move shorter than 10 ms
    assert at[0.503] == 0.0  # a zero-length move


def test_unbounded_jerk_is_shown_as_not_bounded(files, teleavatar, capsys) -> None:  # noqa: ANN001
    from taplan.check import Thresholds, check
    from taplan.timing import retime

    q0 = teleavatar.home
    plan = retime(np.array([q0, q0 + 0.2, q0 + 0.3]), teleavatar.planning_limits)
    report = check(plan, teleavatar.planning_limits, thresholds=Thresholds(check_jerk=False))
    rows = [line for line in report.table().splitlines() if line.startswith(("l_joint", "r_joint"))]
    assert rows and all(" n/b " in row for row in rows)
    assert "jerk: n/b = not bounded" in report.table()
    assert all(j["jerk_bounded"] is False for j in report.to_dict()["joints"])


@pytest.mark.parametrize("controller", ["seed", "intended", "jtc"])
def test_a_plan_file_checked_through_a_controller_is_sampled_at_its_rate(files, controller: str, capsys) -> None:  # noqa: ANN001
    """The exact plan and its 100 Hz samples give the same verdict through a controller model."""
    plan = Trajectory.load(files["plan"])
    sampled = plan.resample(100.0).save(files["root"] / "plan_100hz.csv")
    verdicts = []
    for path in (files["plan"], sampled):
        code, out, _ = run_cli(["check", str(path), "--controller", controller, "--no-png"], capsys)
        verdicts.append((code, out.splitlines()[0].rsplit(" ", 1)[-1]))
    assert verdicts == [(0, "PASS"), (0, "PASS")]


def test_bench_report_only_keeps_the_measured_machine_line(tmp_path: Path, monkeypatch) -> None:  # noqa: ANN001
    import benchmarks.__main__ as runner

    monkeypatch.setattr(runner, "HERE", tmp_path)
    (tmp_path / "RESULTS.md").write_text("# x\n\n- Machine: the measuring box, 2 CPUs\n- Run time: ik 3 s\n")
    runner.write_report(None, measured=False)
    text = (tmp_path / "RESULTS.md").read_text()
    assert "- Machine: the measuring box, 2 CPUs" in text and "- Run time: ik 3 s" in text


def test_help_has_no_rst_markup(capsys) -> None:  # noqa: ANN001
    """``taplan -h`` and every ``taplan CMD -h`` read as plain text: no ``literals``, :roles:, `quotes` or **bold**."""
    import re

    from taplan.cli import COMMANDS

    for argv in [[]] + [[name] for name in COMMANDS]:
        try:
            main([*argv, "-h"])
        except SystemExit as exc:
            assert exc.code == 0
        text = capsys.readouterr().out
        assert text.startswith("usage: taplan"), argv
        assert not re.search(r"``|`|:[a-z]+:|\*\*", text.replace("::", "")), (argv, text)
