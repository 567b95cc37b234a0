"""The defects the fuzz suite found, one test each (each failed before its fix)."""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np
import pytest

from taplan import api
from taplan.cli import main
from taplan.io import load_trajectory
from taplan.timing import jerk_limited


def run_cli(argv: list[str], capsys) -> tuple[int, str, str]:  # noqa: ANN001
    try:
        code = main(argv)
    except SystemExit as exc:
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def one_error_line(err: str, command: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"taplan {command}: error: "), err
    assert "internal error" not in lines[0]
    return lines[0]


def test_a_jerk_plan_with_degree_11_pieces_round_trips_and_checks(teleavatar, tmp_path: Path, capsys) -> None:  # noqa: ANN001
    """plan --method jerk wrote 12-term pieces that the loader refused (it allowed degree 9)."""
    lim = teleavatar.planning_limits
    rng = np.random.default_rng(4)
    span = lim.upper - lim.lower
    wp = lim.lower + span * (0.05 + 0.9 * rng.random((3, 14)))
    plan = jerk_limited(wp, lim).trajectory
    assert plan.coefficients.shape[1] > 10  # the case that failed
    for fmt in ("json", "csv", "npz"):
        back = load_trajectory(plan.save(tmp_path / f"p.{fmt}"))
        t = np.linspace(0.0, plan.duration, 2001)
        assert np.max(np.abs(back(t) - plan(t))) <= 1e-9  # [rad]
        code, out, err = run_cli(["check", str(tmp_path / f"p.{fmt}"), "--no-png"], capsys)
        assert code == 0, out + err


def test_replay_of_an_empty_file_name_is_a_usage_error(capsys) -> None:  # noqa: ANN001
    code, _, err = run_cli(["replay", ""], capsys)  # was an internal ValueError (Path('.').with_name)
    assert code == 2 and "file not found" in one_error_line(err, "replay")


def test_bench_only_with_an_unknown_name_is_one_line(capsys) -> None:  # noqa: ANN001
    code, _, err = run_cli(["bench", "--only", "no_such_benchmark"], capsys)  # was argparse's usage + error
    assert code == 2 and "--only" in one_error_line(err, "bench")


def test_a_bag_with_huge_positions_fails_instead_of_crashing(tmp_path: Path, capsys) -> None:  # noqa: ANN001
    from taplan.ros.bag import BagWriter

    path = tmp_path / "run.mcap"
    with BagWriter(path) as writer:
        for k in range(40):
            for side in api.SIDES:
                q = np.full(7, 0.01 * k) * (1 if side == "left" else -1)
                if k == 20:
                    q[2] = 1e308  # finite, so the reader keeps it; its speed overflows
                fields = {"name": list(api.ARM_JOINT_NAMES[side]), "position": list(q), "velocity": [], "effort": []}
                writer.record(api.Topics.joint_cmd(side), api.JOINT_STATE, fields, 10**18 + k * 13_000_000)
    code, out, err = run_cli(["check", str(path)], capsys)  # was IndexError in SPARC
    assert code == 1 and "FAIL" in out, err


def test_a_scene_file_that_is_not_utf8_is_a_usage_error(tmp_path: Path, capsys) -> None:  # noqa: ANN001
    wp = tmp_path / "wp.csv"
    wp.write_text("l_joint1\n0.1\n0.2\n")
    scene = tmp_path / "scene.yaml"
    scene.write_bytes(b"\x93\xffobstacles: []")
    code, _, err = run_cli(["plan", str(wp), "--scene", str(scene)], capsys)  # was UnicodeDecodeError
    assert code == 2 and "UTF-8" in one_error_line(err, "plan")


def test_a_trajectory_lasting_ages_is_refused_not_sampled(tmp_path: Path, capsys) -> None:  # noqa: ANN001
    path = tmp_path / "long.json"
    path.write_text('{"joint_names": ["l_joint1"], "times": [0, 1e300], "positions": [[0.1], [0.2]]}')
    code, _, err = run_cli(["check", str(path), "--no-png"], capsys)  # was OverflowError (or memory exhausted)
    assert code == 2 and "samples" in one_error_line(err, "check")


def test_a_csv_field_of_megabytes_is_a_usage_error(tmp_path: Path, capsys) -> None:  # noqa: ANN001
    path = tmp_path / "big.csv"
    path.write_text('time,l_joint1.pos\n"' + "1" * 200_000 + '",0\n')
    code, _, err = run_cli(["check", str(path)], capsys)  # was csv.Error: field larger than field limit
    assert code == 2 and "CSV" in one_error_line(err, "check")


def test_an_npz_with_an_unknown_compression_method_is_a_usage_error(tmp_path: Path, capsys) -> None:  # noqa: ANN001
    buffer = io.BytesIO()
    np.savez(buffer, times=np.array([0.0, 1.0]), positions=np.zeros((2, 1)))
    raw = bytearray(buffer.getvalue())
    with zipfile.ZipFile(io.BytesIO(bytes(raw))) as archive:
        header = archive.infolist()[0].header_offset
    raw[header + 8] = 99  # the local header's compression method
    central = raw.rfind(b"PK\x01\x02")
    raw[central + 10] = 99
    path = tmp_path / "p.npz"
    path.write_bytes(bytes(raw))
    code, _, err = run_cli(["check", str(path)], capsys)  # was NotImplementedError
    assert code == 2 and "NPZ" in one_error_line(err, "check")


@pytest.mark.parametrize("controller", ["seed", "jtc", "joint-position"])
def test_a_spike_between_controller_samples_still_fails(teleavatar, tmp_path: Path, controller: str, capsys) -> None:  # noqa: ANN001
    """A 0.4 ms spike (3 mrad, far above the acceleration limit) between 100 Hz samples: the controller's stream
    never sees it, so before the plan itself was checked too, ``check --controller`` passed the file."""
    from taplan.trajectory import Trajectory

    q0 = teleavatar.home
    plan = jerk_limited(np.array([q0, q0 + 0.2]), teleavatar.planning_limits).trajectory
    t = plan.sample_times(2000.0)
    q, v, a = (plan(t, k).copy() for k in range(3))
    tc, w, amp = 0.5053, 4e-4, 3e-3  # [s], [s], [rad]
    g = amp * np.exp(-(((t - tc) / w) ** 2))
    q[:, 3] += g
    v[:, 3] += g * (-2 * (t - tc) / w**2)
    a[:, 3] += g * ((2 * (t - tc) / w**2) ** 2 - 2 / w**2)
    path = Trajectory(t, q, v, a, plan.joint_names).save(tmp_path / "spike.json")
    code, out, _ = run_cli(["check", str(path), "--no-png"], capsys)
    assert code == 1  # the plan alone fails
    code, out, _ = run_cli(["check", str(path), "--no-png", "--controller", controller], capsys)
    assert code == 1 and "the plan itself: FAIL" in out and "l_joint4: acceleration" in out


def test_a_peak_between_grid_samples_fails(teleavatar, tmp_path: Path, capsys) -> None:  # noqa: ANN001
    """A parabola whose vertex (1e-6 rad past l_joint2's limit) lies between two 1 kHz samples, which both sit about
    9e-6 rad inside it: the check evaluated only its grid and passed it; now the peaks between samples are refined."""
    from taplan.check import check
    from taplan.trajectory import Trajectory

    lim = teleavatar.limits
    j, tp, curvature, excess = 1, 0.0505, 40.0, 1e-6  # joint, vertex [s], [rad/s²] / 2, [rad]
    peak = lim.upper[j] + excess
    c = np.zeros((1, 3, 14))
    c[0, 0] = teleavatar.home
    c[0, 0, j] = peak - curvature * tp**2
    c[0, 1, j] = 2 * curvature * tp
    c[0, 2, j] = -curvature
    plan = Trajectory.from_polynomials([0.0, 2 * tp], c, teleavatar.joint_names)
    grid = plan(plan.sample_times(1000.0))[:, j]
    assert grid.max() < lim.upper[j] - 8e-6  # every sample is inside the limit
    report = check(plan, lim)
    assert not report.passed
    assert report.joint("l_joint2").position_violation == pytest.approx(excess, abs=1e-9)  # [rad]
    code, out, _ = run_cli(["check", str(plan.save(tmp_path / "p.json")), "--no-png"], capsys)
    assert code == 1 and "position limit exceeded" in out
