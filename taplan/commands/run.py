"""Drive the arms over ROS 2 (DDS): execute a saved plan, with the heartbeat, the rate and a safe stop handled.

Waits for ``/{left,right}_arm/joint_states``, enables the robot (``/api/fsm/enable`` at 20 Hz, holding the measured
position until ``/fsm_state`` is READY), then publishes the plan on ``/api/{side}_arm/joint_cmd`` at ``--rate``
(50-77 Hz). Before the first command it applies everything ``taplan check`` applies to FILE (the limits of every
derivative, velocity steps, at 1 kHz and at the command rate; the clearance of the robot's own bodies and of
``--scene``'s obstacles) and sends nothing when that fails (exit 1, the failing line, "nothing was sent"). It stops
smoothly (jerk-limited, inside the limits) on Ctrl-C, on an error, when joint states stop for ``--state-timeout``
and when the arm lags a command by more than ``--tracking-error``. Another node's disable (``/api/fsm/enable`` <= 0,
or ``/fsm_state`` PAUSE after READY) ends the run at once, exit 1 "disabled by another node": no heartbeat
re-enables the robot. A robot without ``/fsm_state`` is not driven unless ``--no-fsm``. FILE is any trajectory
``taplan plan`` writes (it must start at the robot's current position). ``--targets FILE|-`` instead streams live
targets for ``--duration`` seconds (JSON lines of joint or pose targets, see :mod:`taplan.ros.targets`) through the
jerk-limited joint or pose streamer; ``--hold SECONDS`` holds the current position (a heartbeat test). Writes what
it sent and measured (``--record``, .npz) and the bag (``--bag``). ``--scene scene.yaml`` certifies the plan's
clearance to the scene along its whole timed trajectory (the joints it does not drive where the robot is) and sends
nothing when anything would touch (exit 1), like ``taplan check PLAN --scene``.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Any

from taplan.commands._ros_args import add_transport_arguments, open_transport

if TYPE_CHECKING:
    from taplan.ros.runner import RunnerConfig


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", nargs="?", type=Path, help="trajectory file (.json, .csv, .npz) from taplan plan")
    add_transport_arguments(parser)
    parser.add_argument("--hold", type=float, default=None, help="hold the measured position this long [s]")
    parser.add_argument("--targets", default=None, help="stream JSON-line targets from this file ('-': stdin)")
    parser.add_argument("--duration", type=float, default=None, help="how long to stream --targets [s]")
    parser.add_argument("--rate", type=float, default=77.0, help="joint_cmd rate [Hz], 50-77 (77)")
    parser.add_argument(
        "--state-timeout", type=float, default=0.2, help="stop after this long without joint states [s] (0.2)"
    )
    parser.add_argument("--tracking-error", type=float, default=0.15, help="abort above this error [rad] (0.15)")
    parser.add_argument("--wait", type=float, default=5.0, help="wait this long for the first joint states [s] (5)")
    parser.add_argument("--disable", action="store_true", help="send /api/fsm/enable -1 at the end (robot pauses)")
    parser.add_argument("--record", type=Path, default=None, help="write sent and measured streams (.npz)")
    parser.add_argument(
        "--cameras",
        action="store_true",
        help="fuse the wrist depth cameras (recorded with --bag); stop smoothly when their images stop",
    )
    parser.add_argument("--camera-timeout", type=float, default=1.0, help="--cameras: stale after this long [s]")
    parser.add_argument(
        "--no-fsm", action="store_true", help="drive a robot without /fsm_state, unconfirmed (default: refuse)"
    )
    parser.add_argument(
        "--command-velocity",
        choices=("zero", "feedforward", "feedback"),
        default="zero",
        help="JointState.velocity of each command: zero (default: the v2 robot reads positions only), the plan's "
        "(feedforward) or the guide's P form (feedback)",
    )
    parser.add_argument("--scene", default=None, help="also check clearance to this scene's obstacles (.yaml/.json)")


def runner_config(args: argparse.Namespace) -> RunnerConfig:
    """The runner's configuration from the options; ``--state-timeout`` is the stall time itself, not a ceiling
    over 5 of the robot's measured publishing periods."""
    from taplan.ros.runner import RunnerConfig

    return RunnerConfig(
        rate=args.rate,
        state_timeout=args.state_timeout,
        stale_periods=float("inf"),
        tracking_error=args.tracking_error,
        wait_timeout=args.wait,
        disable=args.disable,
        require_fsm=not args.no_fsm,
        command_velocity=args.command_velocity,
    )


def run(args: argparse.Namespace) -> int:
    from taplan.errors import InvalidInputError
    from taplan.robot import Robot
    from taplan.ros.runner import CheckFailedError, Runner
    from taplan.trajectory import Trajectory

    for option, value in (
        ("--state-timeout", args.state_timeout),
        ("--tracking-error", args.tracking_error),
        ("--wait", args.wait),
        ("--hold", args.hold),
        ("--duration", args.duration),
    ):
        if value is not None and not (0 < value < float("inf")):
            raise InvalidInputError(option, value, "a positive number (seconds; radians for --tracking-error)")
    if args.record is not None:
        from taplan.io.paths import output_path

        output_path(args.record, "--record", suffixes=(".npz",))
    if args.duration is not None and args.targets is None:
        raise InvalidInputError("--duration", args.duration, "no --duration without --targets (a plan sets its own)")
    modes = [x is not None for x in (args.file, args.hold, args.targets)]
    if sum(modes) != 1:
        raise InvalidInputError(
            "FILE / --hold / --targets", (args.file, args.hold, args.targets), "exactly one of the three"
        )
    if args.targets is not None and args.duration is None:
        raise InvalidInputError("--duration", None, "a streaming time [s] with --targets")
    trajectory = Trajectory.load(args.file, Robot.teleavatar().joint_names) if args.file is not None else None
    config = runner_config(args)
    robot = Robot.teleavatar()
    world = None
    if args.scene is not None:
        from taplan.scene import CollisionWorld, load_scene

        world = CollisionWorld(robot, load_scene(args.scene))
    interface, bag = open_transport(args)

    def progress(t: float, _: float | None) -> None:
        print(f"  t = {t:6.1f} s", flush=True)

    try:
        runner = Runner(
            interface,
            robot,
            config=config,
            on_progress=progress,
            monitors=_camera_monitors(args, interface, robot),
            world=world,
        )
        print(f"taplan run: waiting for joint states on ROS_DOMAIN_ID {interface.domain_id}", flush=True)
        if trajectory is not None:
            print(f"taplan run: checking {args.file} ({trajectory.duration:.2f} s) before sending", flush=True)
            try:
                result = runner.execute(trajectory)
            except CheckFailedError as exc:
                print(exc.report)
                print(f"taplan run: FAIL: {exc.line}: nothing was sent", flush=True)
                return 1
        elif args.targets is not None:
            result = _stream_targets(runner, robot, args)
        else:
            runner.wait_for_state()
            print(f"taplan run: holding the measured position for {args.hold:g} s", flush=True)
            result = runner.stream(lambda t: None, args.hold)
            if result.status == "completed":
                result = dataclasses.replace(result, reason=f"held the position for {args.hold:g} s")
    finally:
        interface.close()
        if bag is not None:
            bag.close()
            print(f"wrote {bag.path} ({bag.count} messages)")
    if runner.presend is not None:
        print(f"taplan run: pre-send check PASS ({runner.presend.clearance.line()})", flush=True)
    print(
        f"taplan run: {result.status}: {result.reason}; {len(result.sent)} commands, {result.heartbeats} heartbeats, "
        f"max tracking error {result.max_tracking_error:.4f} rad, final error {result.final_error:.4f} rad",
        flush=True,
    )
    if args.record is not None:
        result.save(args.record)
        print(f"wrote {args.record}")
    return 0 if result.status == "completed" else 1


def _stream_targets(runner, robot, args: argparse.Namespace):  # noqa: ANN001, ANN202 (CLI glue)
    import sys

    from taplan.ros.targets import TargetFeed, TargetStreamer

    lines = sys.stdin if args.targets == "-" else open(args.targets)  # noqa: SIM115 (read by the feed thread)
    start = runner.wait_for_state()
    feed = TargetFeed(lines, robot, start)
    # joint or pose: its first accepted target decides (every command is still guarded by the runner's world)
    streamer = TargetStreamer(robot, runner.limits, runner.period)
    print(f"taplan run: streaming targets from {args.targets} for {args.duration:g} s at {args.rate:g} Hz", flush=True)
    result = runner.stream(feed, args.duration, streamer=streamer)
    print(f"taplan run: {streamer.summary(feed.skipped)}", flush=True)
    if result.status == "completed" and streamer.accepted == 0:
        rejected = feed.skipped + streamer.rejected
        reason = f"all {rejected} targets were rejected" if rejected else "no target arrived"
        result = dataclasses.replace(result, status="no targets", reason=f"{reason}: the arm only held its position")
    return result


def _camera_monitors(args: argparse.Namespace, interface: Any, robot: Any) -> tuple:
    """With ``--cameras``: a PerceptionLink on the interface (its images are recorded with ``--bag``) whose stale
    stream stops the run."""
    if not args.cameras:
        return ()
    from taplan.ros.perception_link import PerceptionLink
    from taplan.scene import Perception

    # the run plans nothing in this scene (it records the images and watches the stream): no unknown-space
    # tracking, whose projections and snapshots would cost the control loop tens of milliseconds per image
    link = PerceptionLink(interface, Perception(robot, unknown="free"), stale_after=args.camera_timeout)
    return (link.monitor,)
