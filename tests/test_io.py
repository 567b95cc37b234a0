"""The trajectory-file contract (taplan.io): validation, exact round trips, one loader for every command."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from taplan.cli import main
from taplan.errors import ConfigError, InvalidInputError
from taplan.io import (
    ACCELERATION_TOL,
    POSITION_TOL,
    VELOCITY_TOL,
    bounded_rate,
    load_trajectory,
    output_path,
    read_waypoints,
)
from taplan.planning import cartesian_offset
from taplan.timing import jerk_limited, optimize, retime, straight_line, synchronise, time_demonstration
from taplan.trajectory import Trajectory

FORMATS = ("json", "csv", "npz")


def run_cli(argv: list[str], capsys) -> tuple[int, str, str]:  # noqa: ANN001
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse usage errors
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def plans(teleavatar) -> dict[str, Trajectory]:  # noqa: ANN001
    """One trajectory per timing method (and per interpolation a file without coefficients defines)."""
    lim = teleavatar.planning_limits
    q0 = teleavatar.home
    wp = np.array([q0, q0 + 0.2, q0 + np.r_[[0.3, 0.1, -0.2, 0.2, 0.0, 0.1, 0.0] * 2]])
    arm = lim.subset(teleavatar.joint_names[:7])
    right = lim.subset(teleavatar.joint_names[7:])
    t_rec = np.linspace(0.0, 2.0, 101)  # a recording at 50 Hz [s]
    t = np.linspace(0.0, 1.0, 5)
    q = q0[None, :] + 0.1 * np.sin(t)[:, None]
    return {
        "topp": retime(wp, lim),
        "jerk": jerk_limited(wp, lim).trajectory,
        "straight": straight_line(q0[:7], q0[:7] + 0.3, arm).shifted(0.0),
        "optimize": optimize(wp[:2, :7], arm, intervals=12, max_iterations=200).trajectory,
        "linear": Trajectory(t, q, joint_names=teleavatar.joint_names),
        "cubic": Trajectory(t, q, 0.1 * np.cos(t)[:, None] * np.ones(14), joint_names=teleavatar.joint_names),
        "quintic": jerk_limited(wp, lim).trajectory.resample(100.0),
        "cartesian": cartesian_offset(teleavatar, q0, {"right_ee": [0.0, 0.0, -0.05]}).trajectory,
        "demonstration": time_demonstration(t_rec, q0[:7] + 0.2 * np.sin(t_rec)[:, None], arm).trajectory,
        "synchronised": synchronise({"left": wp[:, :7], "right": wp[:, 7:]}, {"left": arm, "right": right})["right"],
        "random_jerk": jerk_limited(lim.lower + (lim.upper - lim.lower) * _fractions(3), lim).trajectory,
    }


def _fractions(rows: int) -> np.ndarray:
    """Waypoints spread over the limits (their jerk-limited pieces reach degree 11: the file format must carry it)."""
    return 0.05 + 0.9 * np.random.default_rng(4).random((rows, 14))


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize(
    "method",
    ["topp", "jerk", "straight", "optimize", "linear", "cubic", "quintic", "cartesian", "demonstration", "synchronised",
     "random_jerk"],
)  # fmt: skip
def test_every_method_round_trips_exactly_in_every_format(plans, method: str, fmt: str, tmp_path: Path) -> None:  # noqa: ANN001
    plan = plans[method]
    back = load_trajectory(plan.save(tmp_path / f"p.{fmt}"))
    assert back.joint_names == plan.joint_names
    assert back.interpolation == plan.interpolation
    t = np.union1d(np.linspace(plan.times[0], plan.times[-1], 3001), plan.times)
    for order, tol in enumerate((POSITION_TOL, VELOCITY_TOL, ACCELERATION_TOL, 1e-3)):  # rad, rad/s, rad/s², rad/s³
        assert np.max(np.abs(back(t, order) - plan(t, order))) <= tol, (method, fmt, order)


def test_topp_csv_passes_the_limits_its_json_passes(plans, teleavatar, tmp_path: Path) -> None:  # noqa: ANN001
    from taplan.check import Thresholds, check

    lim = teleavatar.planning_limits
    reports = [
        check(load_trajectory(plans["topp"].save(tmp_path / f"t.{fmt}")), lim, thresholds=Thresholds(check_jerk=False))
        for fmt in FORMATS
    ]
    assert all(r.passed for r in reports)
    peaks = [[j.peak_acceleration for j in r.joints] for r in reports]
    np.testing.assert_allclose(peaks[1], peaks[0], atol=1e-9)


def _saved_json(plans, tmp_path: Path) -> dict:  # noqa: ANN001
    return json.loads(plans["jerk"].save(tmp_path / "jerk.json").read_text())


def test_positions_edited_past_the_limit_disagree_with_coefficients(plans, teleavatar, tmp_path: Path) -> None:  # noqa: ANN001
    data = _saved_json(plans, tmp_path)
    k = data["joint_names"].index("l_joint2")
    for row in data["positions"][5:]:
        row[k] += 1.5
    bad = tmp_path / "edited.json"
    bad.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=r"positions disagree with coefficients at l_joint2, t=.* \(sample 5\)"):
        load_trajectory(bad)
    with pytest.raises(ConfigError, match="l_joint2"):
        Trajectory.load(bad)


@pytest.mark.parametrize("command", ["check", "plan", "replay"])
def test_every_command_rejects_the_three_files_of_the_issue(plans, command: str, tmp_path: Path, capsys) -> None:  # noqa: ANN001
    data = _saved_json(plans, tmp_path)
    k = data["joint_names"].index("l_joint2")
    edited = json.loads(json.dumps(data))
    for row in edited["positions"]:
        row[k] += 1.5
    with_nan = json.loads(json.dumps(data))
    with_nan["positions"][3][2] = float("nan")
    short = json.loads(json.dumps(data))
    short["positions"] = [row[:13] for row in short["positions"]]
    for name, content, reason in (
        ("edited", edited, "disagree with coefficients at l_joint2"),
        ("nan", with_nan, "finite numbers"),
        ("short", short, r"shape \(\d+, 14\)"),
    ):
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps(content))
        extra = ["--no-png"] if command == "check" else ["-o", str(tmp_path / "out" / "x.json")]
        code, out, err = run_cli([command, str(path), *extra], capsys)
        assert code == 2, (name, out, err)
        assert "PASS" not in out
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"taplan {command}: error: ")
        assert re.search(reason, lines[0]), lines[0]


def test_samples_within_the_stated_tolerance_are_accepted(plans, tmp_path: Path) -> None:  # noqa: ANN001
    data = _saved_json(plans, tmp_path)
    data["positions"][4][0] += 0.5 * POSITION_TOL
    data["velocities"][4][0] += 0.5 * VELOCITY_TOL
    data["accelerations"][4][0] += 0.5 * ACCELERATION_TOL
    path = tmp_path / "near.json"
    path.write_text(json.dumps(data))
    load_trajectory(path)
    data["accelerations"][4][0] += ACCELERATION_TOL
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match="accelerations disagree .* at l_joint1, .*tolerance 0.001 rad/s²"):
        load_trajectory(path)


def test_replay_and_check_reject_an_unknown_joint_alike(teleavatar, tmp_path: Path, capsys) -> None:  # noqa: ANN001
    names = ["bogus", *teleavatar.joint_names[1:7]]
    path = Trajectory([0.0, 1.0], np.zeros((2, 7)), joint_names=names).save(tmp_path / "bogus.csv")
    for command in (["check", str(path), "--no-png"], ["replay", str(path), "-o", str(tmp_path / "r.json")]):
        code, _, err = run_cli(command, capsys)
        assert code == 2 and "unknown joint 'bogus'" in err and len(err.strip().splitlines()) == 1
    with pytest.raises(ConfigError, match="unknown joint 'bogus'"):
        Trajectory.load(path, teleavatar.joint_names)


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("name", "text", "message"),
    [
        ("empty.csv", "", "header: expected a header .* found an empty file"),
        ("header_only.csv", "time,l_joint1.pos\n", "rows: expected at least 2 samples, found 0"),
        ("misspelled.csv", "time,l_joint1.pos,l_joint1.vell\n0,0,0\n1,0,0\n", "column 'l_joint1.vell'"),
        ("stray.csv", "time,l_joint1.pos,l_jiont1.vel\n0,0,0\n1,0,0\n", "'l_jiont1.vel' for a joint with no '.pos'"),
        ("dup.csv", "time,l_joint1.pos,l_joint1.pos\n0,0,0\n1,0,0\n", "column 'l_joint1.pos' twice"),
        ("text.csv", "time,l_joint1.pos\n0,0\n1,abc\n", "line 3, column 'l_joint1.pos': expected a number"),
        ("ragged.csv", "time,l_joint1.pos\n0,0\n1\n", "line 3: expected 2 cells"),
        ("back.csv", "time,l_joint1.pos\n0,0\n0,1\n", "strictly increasing"),
        ("waypoints.csv", "l_joint1,l_joint2\n0,0\n1,1\n", "'time' \\(a waypoint CSV"),
        ("list.json", "[1, 2]", "top level: expected a JSON object"),
        ("broken.json", "{", "not valid JSON"),
        ("dupname.json", '{"joint_names":["a","a"],"times":[0,1],"positions":[[0,0],[1,1]]}', "'a' twice"),
        ("strings.json", '{"joint_names":["a"],"times":["0","1"],"positions":[[0],[1]]}', "times: expected numbers"),
        ("ragged.json", '{"joint_names":["a"],"times":[0,1],"positions":[[0],[1, 2]]}', "positions: expected a rect"),
        ("acc.json", '{"joint_names":["a"],"times":[0,1],"positions":[[0],[1]],"accelerations":[[0],[0]]}', "vel"),
        ("inf.json", '{"joint_names":["a"],"times":[0,Infinity],"positions":[[0],[1]]}', "times: expected finite"),
        ("nan.npz", None, "not a readable NPZ"),
        ("plan.txt", "x", "a trajectory file ending in .json, .csv or .npz"),
    ],
)
def test_malformed_files_are_one_clear_config_error(tmp_path: Path, name: str, text: str | None, message: str) -> None:
    path = _write(tmp_path, name, "not a zip archive" if text is None else text)
    with pytest.raises(ConfigError, match=message) as info:
        load_trajectory(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_positions_only_file_is_linear_as_documented(tmp_path: Path) -> None:
    path = _write(tmp_path, "lin.csv", "time,a.pos\n0,0\n1,1\n3,0\n")
    traj = load_trajectory(path)
    assert traj.interpolation == "linear"
    np.testing.assert_allclose(traj([0.5, 2.0]), [[0.5], [0.5]], atol=1e-15)


def test_waypoint_csv_and_trajectory_file_give_waypoints(teleavatar, tmp_path: Path) -> None:  # noqa: ANN001
    names, table = read_waypoints(_write(tmp_path, "wp.csv", "l_joint1,l_joint2\n0,0.1\n0.2,0.3\n"))
    assert names == ("l_joint1", "l_joint2") and table.shape == (2, 2)
    with pytest.raises(ConfigError, match="unknown joint 'l_jiont2'"):
        read_waypoints(_write(tmp_path, "bad.csv", "l_joint1,l_jiont2\n0,0\n1,1\n"), teleavatar.joint_names)
    with pytest.raises(ConfigError, match="at least 2 waypoints"):
        read_waypoints(_write(tmp_path, "one.csv", "l_joint1\n0\n"))


def test_output_path_creates_parents_and_checks_suffix(tmp_path: Path) -> None:
    out = output_path(tmp_path / "a" / "b" / "plot.png", "--png", suffixes=(".png",))
    assert out.parent.is_dir()
    with pytest.raises(InvalidInputError, match="--png: expected a file name ending in .png"):
        output_path(tmp_path / "out.txt", "--png", suffixes=(".png",))
    existing = _write(tmp_path, "file", "x")
    with pytest.raises(InvalidInputError, match="a directory"):
        output_path(existing, "--out", directory=True)
    with pytest.raises(ConfigError, match="cannot create directory"):
        output_path(existing / "sub" / "x.json", "-o")


@pytest.mark.parametrize("value", [0.0, -1.0, 1e9, float("nan"), float("inf"), "x"])
def test_rates_are_bounded(value) -> None:  # noqa: ANN001
    with pytest.raises(InvalidInputError, match=r"--rate: expected a rate in \[1, 10000\] Hz"):
        bounded_rate(value, "--rate")
    assert bounded_rate(250.0, "--rate") == 250.0
