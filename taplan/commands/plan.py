"""Time-parameterise joint waypoints from a file and write the trajectory.

FILE holds joint waypoints: a trajectory file (CSV/JSON/NPZ, as written by taplan: its positions are used and its
times ignored), or a CSV whose header names the joints (``l_joint1,...``) with one waypoint per row. Joints are
matched to the bundled TeleAvatar by name. ``--method topp`` is time-optimal under velocity and acceleration
limits (TOPP-RA); ``jerk`` (default) also limits jerk and starts and ends with zero acceleration.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from taplan.check import Thresholds, check
from taplan.errors import ConfigError
from taplan.robot import Robot
from taplan.trajectory import Trajectory


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="waypoint or trajectory file (.csv, .json, .npz)")
    parser.add_argument("--method", choices=("topp", "jerk"), default="jerk", help="timing method (default jerk)")
    parser.add_argument(
        "--limits", choices=("planning", "hardware"), default="planning", help="limits to plan with (default planning)"
    )
    parser.add_argument("-o", "--output", help="output trajectory file (default FILE stem + _timed.json)")
    parser.add_argument("--rate", type=float, default=100.0, help="also write a CSV sampled at this rate [Hz]")


def load_waypoints(path: Path) -> tuple[list[str], np.ndarray]:
    """Joint names and waypoints (N, n) from a trajectory file or a plain CSV with a joint-name header."""
    if path.suffix.lower() == ".csv":
        header = path.read_text().splitlines()[0].split(",") if path.is_file() else []
        if header and header[0] != "time":
            try:
                table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
            except ValueError as exc:
                raise ConfigError(f"cannot parse {str(path)!r}: {exc}") from exc
            return [h.strip() for h in header], table
    trajectory = Trajectory.load(path)
    return list(trajectory.joint_names), np.array(trajectory.positions)


def run(args: argparse.Namespace) -> int:
    from taplan.timing import jerk_limited, retime

    path = Path(args.file)
    names, waypoints = load_waypoints(path)
    robot = Robot.teleavatar()
    limits = (robot.planning_limits if args.limits == "planning" else robot.limits).subset(names)
    if args.method == "topp":
        trajectory = retime(waypoints, limits)
    else:
        trajectory = jerk_limited(waypoints, limits).trajectory
    output = Path(args.output) if args.output else path.with_name(f"{path.stem}_timed.json")
    trajectory.save(output)
    sampled = trajectory.resample(args.rate).save(output.with_name(f"{output.stem}_{args.rate:g}hz.csv"))
    thresholds = Thresholds(check_jerk=args.method == "jerk")  # TOPP-RA limits velocity and acceleration only
    report = check(trajectory, limits, thresholds=thresholds, name=f"{path.name} ({args.method}, {args.limits} limits)")
    print(report.table())
    print(f"\n{len(waypoints)} waypoints, {len(names)} joints -> {trajectory.duration:.3f} s")
    print(f"wrote {output} (exact) and {sampled} ({args.rate:g} Hz samples)")
    return 0 if report.passed else 1
