"""Time-parameterise joint waypoints from a file and write the trajectory.

FILE holds joint waypoints: a trajectory file (CSV/JSON/NPZ, as written by taplan: its positions are used and its
times ignored), or a CSV whose header names the joints (``l_joint1,...``) with one waypoint per row. Joints are
matched to the bundled TeleAvatar by name. ``--method topp`` is time-optimal under velocity and acceleration
limits (TOPP-RA); ``jerk`` (default) also limits jerk and starts and ends with zero acceleration. ``--scene
scene.yaml`` plans collision-free legs between consecutive waypoints around the scene's obstacles
(:func:`taplan.planning.plan_motion`: certified path, jerk-limited timing, verified; joints missing from FILE hold the
home pose), stopping at each waypoint; a leg that cannot be planned is an error naming it.

``--scene-from-bag run.mcap`` plans around what the wrist depth cameras saw in a recorded run (the depth images
and camera infos fused at the recorded joint states, :func:`taplan.ros.bag_perception.perceive_bag`), alone or
with ``--scene``.

``--recorded`` (implied for a ``.mcap`` bag) reads FILE as a recorded demonstration: a CSV whose first column is
the time [s], or a rosbag2 bag's joint_states. It is made limit-respecting and jerk-limited within
``--max-deviation`` of the recording (:func:`taplan.timing.time_demonstration`), keeping its timing where the
limits allow (``--fastest``: as fast as they allow), and the deviation and slow-downs are reported.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from taplan.check import Thresholds, check
from taplan.errors import InvalidInputError
from taplan.io import bounded_rate, output_path, read_waypoints
from taplan.io.trajectory_file import SUFFIXES
from taplan.robot import Robot
from taplan.trajectory import Trajectory


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="waypoint or trajectory file (.csv, .json, .npz)")
    parser.add_argument(
        "--method", choices=("topp", "jerk"), default=None, help="timing method without --scene (default jerk)"
    )
    parser.add_argument(
        "--limits", choices=("planning", "hardware"), default="planning", help="limits to plan with (default planning)"
    )
    parser.add_argument(
        "-o", "--output", help="output trajectory file (default FILE stem + _timed.json; with --scene _planned.json)"
    )
    parser.add_argument("--rate", type=float, default=100.0, help="also write a CSV sampled at this rate [Hz]")
    parser.add_argument("--scene", default=None, help="plan collision-free legs around this scene (.yaml/.json)")
    parser.add_argument(
        "--scene-from-bag",
        default=None,
        help="plan around what the wrist depth cameras saw in this rosbag2 .mcap (with --scene: both)",
    )
    parser.add_argument(
        "--margin", type=float, default=None, help="with --scene: clearance of the planned path [m] (0.01)"
    )
    parser.add_argument(
        "--recorded", action="store_true", help="FILE is a recorded demonstration (time column; implied for .mcap)"
    )
    parser.add_argument(
        "--max-deviation", type=float, default=None, help="recorded: largest deviation from the recording [rad] (0.01)"
    )
    parser.add_argument("--fastest", action="store_true", help="recorded: as fast as the limits allow, not as recorded")
    parser.add_argument(
        "--stream",
        choices=("measured", "commanded"),
        default=None,
        help="recorded bag: which joint stream (default measured)",
    )


def _validate(args: argparse.Namespace, path: Path) -> None:
    """Every option checked before any work: an option the chosen mode would not use is refused, never ignored."""
    args.rate = bounded_rate(args.rate, "--rate")
    recorded = args.recorded or path.suffix.lower() == ".mcap"
    scene = args.scene is not None or args.scene_from_bag is not None
    mode = "a recorded demonstration" if recorded else ("--scene" if scene else "waypoints")
    if scene and recorded:
        raise InvalidInputError("--scene", args.scene, "waypoints, not a recorded demonstration (it is not planned)")
    if args.method is not None and (scene or recorded):
        timing = "--scene plans are jerk-limited" if scene else "a recording is timed as recorded"
        raise InvalidInputError("--method", args.method, f"no --method with {mode} ({timing})")
    if args.margin is not None:
        if not scene:
            raise InvalidInputError("--margin", args.margin, "no --margin without --scene (the path's clearance)")
        if not (0 <= args.margin < float("inf")):
            raise InvalidInputError("--margin", args.margin, "a clearance >= 0 [m]")
    if not recorded:
        for option, value in (
            ("--max-deviation", args.max_deviation),
            ("--fastest", args.fastest or None),
            ("--stream", args.stream),
        ):
            if value is not None:
                raise InvalidInputError(option, value, f"no {option} without --recorded or a .mcap bag")
    elif args.stream is not None and path.suffix.lower() != ".mcap":
        raise InvalidInputError("--stream", args.stream, "no --stream for a CSV recording (a bag has two streams)")
    if args.max_deviation is not None and not (0 < args.max_deviation < float("inf")):
        raise InvalidInputError("--max-deviation", args.max_deviation, "a positive deviation [rad]")
    args.method = args.method or "jerk"
    args.margin = 0.01 if args.margin is None else args.margin
    args.max_deviation = 0.01 if args.max_deviation is None else args.max_deviation
    args.stream = args.stream or "measured"


def load_waypoints(path: Path, joint_names: tuple[str, ...] | None = None) -> tuple[list[str], np.ndarray]:
    """Joint names and waypoints (N, n) from a trajectory file or a plain CSV with a joint-name header."""
    names, waypoints = read_waypoints(path, joint_names)
    return list(names), waypoints


def run(args: argparse.Namespace) -> int:
    from taplan.timing import jerk_limited, retime

    path = Path(args.file)
    _validate(args, path)
    in_scene = args.scene is not None or args.scene_from_bag is not None
    default = f"{path.stem}_planned.json" if in_scene else f"{path.stem}_timed.json"
    output = output_path(Path(args.output) if args.output else path.with_name(default), "--output", suffixes=SUFFIXES)
    if args.recorded or path.suffix.lower() == ".mcap":
        return _plan_recording(args, path, output)
    robot = Robot.teleavatar()
    names, waypoints = load_waypoints(path, robot.joint_names)
    if args.scene is not None or args.scene_from_bag is not None:
        return _plan_in_scene(args, path, output, names, waypoints, robot)
    limits = (robot.planning_limits if args.limits == "planning" else robot.limits).subset(names)
    if args.method == "topp":
        trajectory = retime(waypoints, limits)
    else:
        trajectory = jerk_limited(waypoints, limits).trajectory
    trajectory.save(output)
    sampled = trajectory.resample(args.rate).save(output.with_name(f"{output.stem}_{args.rate:g}hz.csv"))
    thresholds = Thresholds(check_jerk=args.method == "jerk")  # TOPP-RA limits velocity and acceleration only
    report = check(trajectory, limits, thresholds=thresholds, name=f"{path.name} ({args.method}, {args.limits} limits)")
    print(report.table())
    print(f"\n{len(waypoints)} waypoints, {len(names)} joints -> {trajectory.duration:.3f} s")
    print(f"wrote {output} (exact) and {sampled} ({args.rate:g} Hz samples)")
    return 0 if report.passed else 1


def _plan_recording(args: argparse.Namespace, path: Path, output: Path) -> int:
    from taplan.timing import load_recording, time_demonstration

    if path.suffix.lower() == ".mcap":
        from taplan.ros.bag import read_recording

        times, positions, names = read_recording(path, args.stream)
    else:
        times, positions, names = load_recording(str(path), args.stream)
    robot = Robot.teleavatar()
    limits = (robot.planning_limits if args.limits == "planning" else robot.limits).subset(names)
    result = time_demonstration(
        times, positions, limits, max_deviation=args.max_deviation, keep_timing=not args.fastest, robot=robot
    )
    trajectory = result.trajectory
    trajectory.save(output)
    sampled = trajectory.resample(args.rate).save(output.with_name(f"{output.stem}_{args.rate:g}hz.csv"))
    report = check(trajectory, limits, thresholds=Thresholds(check_jerk=True), name=f"{path.name} (recorded)")
    print(report.table())
    print(f"\n{len(times)} recorded samples, {len(names)} joints")
    print(result.summary())
    print(f"wrote {output} (exact) and {sampled} ({args.rate:g} Hz samples)")
    return 0 if report.passed else 1


def _plan_in_scene(
    args: argparse.Namespace, path: Path, output: Path, names: list[str], waypoints: np.ndarray, robot: Robot
) -> int:
    from taplan.errors import PlanningError
    from taplan.planning import plan_motion
    from taplan.scene import CollisionWorld, Scene, load_scene

    scene = load_scene(args.scene, robot) if args.scene is not None else Scene()
    if args.scene_from_bag is not None:
        from taplan.ros.bag_perception import perceive_bag

        seen = perceive_bag(robot, args.scene_from_bag)
        perceived = seen.perception.scene.obstacles["perceived"]
        scene.put("perceived", perceived.shape, perceived.pose)
        print(
            f"perceived {len(perceived.shape)} occupied voxels of {seen.perception.grid.resolution * 100:g} cm from "
            f"{seen.images} depth images and {seen.clouds} point clouds in {args.scene_from_bag}"
            + (f" (skipped {seen.skipped})" if seen.skipped else "")
        )
    world = CollisionWorld(robot, scene)
    configurations = np.repeat(robot.home[None, :], len(waypoints), axis=0)
    configurations[:, robot.indices(names)] = waypoints
    limits = robot.planning_limits if args.limits == "planning" else robot.limits
    times, pieces, offset = [0.0], [], 0.0
    for leg, (a, b) in enumerate(zip(configurations[:-1], configurations[1:], strict=True)):
        try:
            plan = plan_motion(robot, a, b, limits=limits, world=world, margin=args.margin, seed=leg)
        except PlanningError as exc:
            raise PlanningError(f"leg {leg} (waypoint {leg} -> {leg + 1}): {exc}") from exc
        r = plan.report
        print(
            f"leg {leg}: {r.stage}, {r.duration:.3f} s, path {r.path_length:.3f} rad, clearance "
            f"{r.min_clearance * 1e3:.1f} mm ({r.min_clearance_pair[0]} / {r.min_clearance_pair[1]}), planned in "
            f"{sum(r.stage_times.values()):.2f} s"
        )
        for note in r.notes:
            print(f"  note: {note}")
        trajectory = plan.trajectory
        times += list(offset + trajectory.times[1:])
        pieces.append(trajectory.coefficients)
        offset += trajectory.duration
    width = max(c.shape[1] for c in pieces)
    coefficients = np.concatenate([np.pad(c, ((0, 0), (0, width - c.shape[1]), (0, 0))) for c in pieces], axis=0)
    trajectory = Trajectory.from_polynomials(np.array(times), coefficients, robot.joint_names)
    trajectory.save(output)
    sampled = trajectory.resample(args.rate).save(output.with_name(f"{output.stem}_{args.rate:g}hz.csv"))
    where = " + ".join(str(s) for s in (args.scene, args.scene_from_bag) if s is not None)
    report = check(trajectory, limits, name=f"{path.name} in {where}")
    print(report.table())
    legs = len(waypoints) - 1
    plural = "" if legs == 1 else "s"
    print(f"\n{len(waypoints)} waypoints, {legs} leg{plural} -> {trajectory.duration:.3f} s, collision-free")
    print(f"wrote {output} (exact) and {sampled} ({args.rate:g} Hz samples)")
    return 0 if report.passed else 1
