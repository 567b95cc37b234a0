"""Replay a trajectory file through a controller model and write the replayed streams.

``taplan replay plan.json --controller seed -o replay.json`` runs the plan through the seed's industrial simulator
(``seed``/``intended``), ros2_control's trajectory controller (``jtc``/``jtc-none``) or the TeleAvatar joint mode
(``joint-position``/``joint-velocity``) and writes the update stream (and ``joint_states`` samples) as JSON, NPZ or
CSV.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from taplan.errors import ConfigError, InvalidInputError
from taplan.io import bounded_rate, load_trajectory, output_path
from taplan.reference import IndustrialSimulator, JointModeRobot, JointTrajectoryController, Replay
from taplan.trajectory import Trajectory

CONTROLLERS = ("seed", "intended", "jtc", "jtc-none", "joint-position", "joint-velocity")


def add_controller_arguments(parser: argparse.ArgumentParser, default: str) -> None:
    """Options shared by ``taplan replay`` and ``taplan check``."""
    parser.add_argument(
        "--controller",
        default=default,
        choices=CONTROLLERS if default != "trajectory" else ("trajectory", *CONTROLLERS),
        help=f"controller model (default {default})",
    )
    parser.add_argument("--update-rate", type=float, default=100.0, help="controller update rate [Hz] (100)")
    parser.add_argument("--pub-rate", type=float, default=10.0, help="joint_states publish rate [Hz] (10)")
    parser.add_argument(
        "--command-rate", type=float, default=100.0, help="joint_cmd rate for joint mode [Hz] (100, the arm loop rate)"
    )
    parser.add_argument(
        "--jitter", type=float, default=0.0, help="joint_cmd period jitter, a fraction in [0, 1), joint mode only (0)"
    )


def validate_controller_arguments(args: argparse.Namespace) -> None:
    """Rates within range; ``--jitter`` only where it acts (the joint-mode command stream)."""
    for option in ("update_rate", "pub_rate", "command_rate"):
        setattr(args, option, bounded_rate(getattr(args, option), "--" + option.replace("_", "-")))
    jitter = args.jitter
    if not (0.0 <= jitter < 1.0):
        raise InvalidInputError("--jitter", jitter, "a fraction in [0, 1)")
    if jitter and not args.controller.startswith("joint-"):
        raise InvalidInputError(
            "--jitter",
            f"{jitter:g} with --controller {args.controller}",
            "0 unless --controller is joint-position or joint-velocity",
        )


def replay_with(trajectory: Trajectory, args: argparse.Namespace, limits=None) -> Replay:  # noqa: ANN001
    """Run ``trajectory`` through the controller named by ``args.controller``.

    The simulators and the trajectory controller receive the trajectory sampled at their update rate (its
    positions, velocities and accelerations every period, as a planner streams a plan), not its knots: a plan's
    knots are where its polynomial pieces meet, irregular and often microseconds apart, not points meant to be sent.
    The joint mode samples at ``--command-rate`` itself.
    """
    name = args.controller
    if name in ("seed", "intended", "jtc", "jtc-none"):
        trajectory = trajectory.resample(args.update_rate)
    if name in ("seed", "intended"):
        return IndustrialSimulator(args.update_rate, args.pub_rate, mode=name).replay(trajectory)
    if name in ("jtc", "jtc-none"):
        return JointTrajectoryController(args.update_rate, "none" if name == "jtc-none" else "splines").replay(
            trajectory
        )
    convention = "position" if name == "joint-position" else "velocity"
    robot = JointModeRobot(limits, convention=convention, rate=args.update_rate)
    return robot.replay_trajectory(trajectory, args.command_rate, jitter=args.jitter)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", type=Path, help="trajectory file (.csv with a time column, .json, .npz)")
    add_controller_arguments(parser, "seed")
    parser.add_argument("-o", "--output", type=Path, default=None, help="output file (.json, .npz, .csv)")


def run(args: argparse.Namespace) -> int:
    from taplan.robot import Robot

    validate_controller_arguments(args)
    if not args.file.is_file():  # before its name is used for the default output
        raise ConfigError(f"file not found: {str(args.file)!r}")
    output = args.output or args.file.with_name(f"{args.file.stem}_{args.controller}_replay.json")
    output = output_path(output, "--output", suffixes=(".json", ".npz", ".csv"))
    robot = Robot.teleavatar()
    trajectory = load_trajectory(args.file, robot.joint_names)
    replay = replay_with(trajectory, args)
    written = replay.save(output)
    samples = len(replay.samples) if replay.samples is not None else 0
    print(
        f"{replay.controller}: {len(replay)} updates over {replay.duration:.3f} s, {samples} joint_states samples, "
        f"dropped waypoints {list(replay.dropped)}"
    )
    for note in replay.events[:10]:
        print(f"  {note}")
    for path in written:
        print(f"wrote {path}")
    return 0
