"""Check a trajectory file against the joint limits and for smoothness; exit 1 when it fails.

``taplan check plan.json`` evaluates the plan itself; ``taplan check run.mcap`` (or a rosbag2 directory ``run/``)
checks a recorded run (from ``taplan run --bag`` or ``ros2 bag record -s mcap``): the commanded joint streams,
their timing, the heartbeat gaps and the measured positions; ``--controller seed|intended|jtc|jtc-none|
joint-position|joint-velocity`` checks what that controller would do with it instead (and the plan itself must
still hold the position, velocity and acceleration limits: a sampled stream can hide an excess between its
samples). Joints are matched by name to the robot (default the bundled TeleAvatar); ``--limits planning`` uses the
planner's scaled limits instead of the hardware ceilings. Prints the report, writes a PNG of q, q̇, q̈ and jerk, and
optionally the report as JSON. ``--scene scene.yaml`` also checks the plan's clearance to the scene (and
the robot's own bodies) along the whole timed trajectory (:func:`taplan.planning.scene_clearance`): the closest pair
and when, FAIL when anything is closer than ``--margin`` (default 0: contact) at any instant. No PNG for a bag.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from taplan.check import Thresholds, check
from taplan.commands.replay import add_controller_arguments, replay_with, validate_controller_arguments
from taplan.errors import ConfigError, InvalidInputError
from taplan.io import bounded_rate, load_trajectory, output_path

if TYPE_CHECKING:
    from taplan.planning.clearance import SceneClearance
    from taplan.robot import Robot
    from taplan.trajectory import Trajectory


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "file", type=Path, help="trajectory file (.csv with a time column, .json, .npz) or a recorded run (.mcap bag)"
    )
    add_controller_arguments(parser, "trajectory")
    parser.add_argument("--limits", choices=("hardware", "planning"), default="hardware", help="limit set (hardware)")
    parser.add_argument(
        "--source",
        choices=("updates", "samples"),
        default=None,
        help="replay stream to check with a --controller: its updates (default) or its joint_states samples",
    )
    parser.add_argument("--rate", type=float, default=None, help="evaluation rate of a trajectory [Hz] (1000)")
    parser.add_argument("--no-jerk", action="store_true", help="report jerk without failing on it")
    parser.add_argument("--png", type=Path, default=None, help="plot file of a plan (default <file>_check.png)")
    parser.add_argument("--no-png", action="store_true", help="do not write a plot")
    parser.add_argument("--json", type=Path, default=None, help="also write the report as JSON")
    parser.add_argument(
        "--scene", type=Path, default=None, help="also check the plan's clearance to this scene (.yaml/.json)"
    )
    parser.add_argument(
        "--margin",
        type=float,
        default=None,
        help="with --scene: clearance [m] required at every instant (default 0: no contact)",
    )


def _validate(args: argparse.Namespace) -> None:
    """Every option checked before any work, so no error can follow a printed verdict."""
    validate_controller_arguments(args)
    bag = args.file.suffix.lower() == ".mcap" or _is_bag_directory(args.file)
    if args.controller == "trajectory":
        for option, default in (("update_rate", 100.0), ("pub_rate", 10.0), ("command_rate", 100.0)):
            if getattr(args, option) != default:
                flag = "--" + option.replace("_", "-")
                raise InvalidInputError(flag, getattr(args, option), "no controller rate without a --controller")
    elif bag:
        raise InvalidInputError(
            "--controller", args.controller, "no --controller with a bag (a recorded run is checked as it ran)"
        )
    if bag and args.png is not None:
        raise InvalidInputError("--png", str(args.png), "no --png with a bag (a plot is drawn for a plan file)")
    if args.margin is not None:
        if args.scene is None:
            raise InvalidInputError("--margin", args.margin, "no --margin without --scene (it is the scene clearance)")
        if not (args.margin >= 0 and args.margin < float("inf")):
            raise InvalidInputError("--margin", args.margin, "a clearance >= 0 [m]")
    args.margin = 0.0 if args.margin is None else args.margin
    if args.scene is not None:
        if bag:
            raise InvalidInputError("--scene", str(args.scene), "a plan file to check against a scene, not a bag")
        if not args.scene.is_file():
            raise ConfigError(f"--scene: file not found: {str(args.scene)!r}")
    if args.rate is not None:
        if args.controller != "trajectory" or args.file.suffix.lower() == ".mcap" or _is_bag_directory(args.file):
            raise InvalidInputError("--rate", args.rate, "no --rate with a --controller or a bag (they set the rate)")
        args.rate = bounded_rate(args.rate, "--rate")
    if args.source is not None and args.controller == "trajectory":
        raise InvalidInputError("--source", args.source, "no --source without a --controller (a plan has no streams)")
    args.source = args.source or "updates"
    if args.png is not None and args.no_png:
        raise InvalidInputError("--png", str(args.png), "either --png or --no-png, not both")
    if args.png is not None:
        output_path(args.png, "--png", suffixes=(".png",))
    if args.json is not None:
        output_path(args.json, "--json", suffixes=(".json",))
    if not (args.file.is_file() or _is_bag_directory(args.file)):
        raise ConfigError(f"file not found: {str(args.file)!r} (a trajectory file, a .mcap bag or a rosbag2 directory)")


def _is_bag_directory(path: Path) -> bool:
    return path.is_dir() and (path / "metadata.yaml").is_file()


def run(args: argparse.Namespace) -> int:
    from taplan.robot import Robot

    _validate(args)
    if args.file.suffix.lower() == ".mcap" or _is_bag_directory(args.file):
        return _check_bag(args)
    robot = Robot.teleavatar()
    trajectory = load_trajectory(args.file, robot.joint_names)
    all_limits = robot.limits if args.limits == "hardware" else robot.planning_limits
    limits = all_limits.subset(trajectory.joint_names)
    thresholds = Thresholds(check_jerk=not args.no_jerk)
    plan_failures: list[str] = []
    if args.controller == "trajectory":
        subject = trajectory
        report = check(trajectory, limits, rate=args.rate, thresholds=thresholds, name=str(args.file))
    else:
        subject = replay_with(trajectory, args, all_limits)
        report = check(
            subject, limits, thresholds=thresholds, source=args.source, name=f"{args.file} via {subject.controller}"
        )
        # a controller's sampled stream can hide an excess of the plan between its samples: the plan itself must
        # hold its position, velocity and acceleration limits too (its jerk is the controller stream's business)
        plan_report = check(trajectory, limits, thresholds=Thresholds(check_jerk=False), name=str(args.file))
        plan_failures = [f for f in plan_report.failures if "velocity step" not in f]
    print(report.table())
    if plan_failures:
        print(f"the plan itself: FAIL: {'; '.join(plan_failures)}")
    clearance = None
    if args.scene is not None:
        clearance = check_scene(trajectory, robot, args.scene, args.margin)
        print(clearance.summary())
    if not args.no_png:
        from taplan.plots import save_profiles

        png = args.png or output_path(args.file.with_name(f"{args.file.stem}_check.png"), "--png")
        how = "the plan" if args.controller == "trajectory" else f"through {subject.controller}"
        save_profiles(subject, png, limits, title=f"{args.file.name}: {how} ({args.limits} limits)")
        print(f"wrote {png}")
    if args.json is not None:
        if clearance is None:
            args.json.write_text(report.to_json())
        else:
            import json

            data = {**report.to_dict(), "scene": {"file": str(args.scene), **clearance.to_dict()}}
            args.json.write_text(json.dumps(data, indent=2, default=float))
        print(f"wrote {args.json}")
    return 0 if report.passed and not plan_failures and (clearance is None or clearance.passed) else 1


def check_scene(trajectory: Trajectory, robot: Robot, scene: Path, margin: float = 0.0) -> SceneClearance:
    """The plan's clearance to ``scene`` (and the robot's own bodies) along the whole timed trajectory; the joints
    the plan does not drive hold the home pose (where ``taplan sim`` starts; ``taplan run --scene`` holds them where
    the robot is)."""
    from taplan.planning.clearance import scene_clearance
    from taplan.scene import CollisionWorld, load_scene

    return scene_clearance(CollisionWorld(robot, load_scene(scene, robot)), trajectory, margin)


def _check_bag(args: argparse.Namespace) -> int:
    """A recorded run: commands (limits, steps, smoothness, timing), heartbeat gaps and measured positions."""
    from taplan.robot import Robot
    from taplan.ros.bag import read_run
    from taplan.ros.run_check import check_run

    robot = Robot.teleavatar()
    limits = robot.limits if args.limits == "hardware" else robot.planning_limits
    report = check_run(read_run(args.file), limits, Thresholds(check_jerk=not args.no_jerk), name=str(args.file))
    print(report.table())
    if args.json is not None:
        import json

        args.json.write_text(json.dumps(report.to_dict(), indent=2, default=float))
        print(f"wrote {args.json}")
    return 0 if report.passed else 1
