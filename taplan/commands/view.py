"""See a plan in the browser: robot, scene, hand paths, closest pair and limits, on a time slider.

``taplan view plan.json --scene scene.yaml`` serves the viewer on 127.0.0.1 (``--port``, default 8080) and prints
its URL; ``taplan view run.mcap`` replays a recorded bag (commanded and measured robots side by side);
``taplan view --live --loopback`` follows the joint states of a running ``taplan sim`` over DDS.
``--html page.html`` writes a self-contained page that opens without a server, and exits. Ctrl-C stops the server.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import signal
from pathlib import Path
from typing import Any

from taplan.errors import InvalidInputError

TRAJECTORY_SUFFIXES = (".json", ".csv", ".npz")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", nargs="?", type=Path, help="trajectory (.json, .csv, .npz) or recorded bag (.mcap)")
    parser.add_argument("--scene", type=Path, default=None, help="scene file (.yaml/.json) to show around the robot")
    parser.add_argument("--live", action="store_true", help="follow /{left,right}_arm/joint_states over DDS")
    parser.add_argument("--loopback", action="store_true", help="with --live: DDS on 127.0.0.1 (a local taplan sim)")
    parser.add_argument("--domain-id", type=int, default=None, help="with --live: ROS_DOMAIN_ID (default: env, else 0)")
    parser.add_argument("--host", default="127.0.0.1", help="interface to serve on (127.0.0.1: this machine only)")
    parser.add_argument("--port", type=int, default=8080, help="TCP port (8080; 0: any free port)")
    parser.add_argument("--play", action="store_true", help="start playing at once")
    parser.add_argument("--html", type=Path, default=None, help="write a self-contained HTML page and exit")
    parser.add_argument("--duration", type=float, default=None, help="stop the server after this many seconds")
    parser.add_argument("--urdf", type=Path, default=None, help="robot URDF (default: the bundled TeleAvatar)")


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def _motions(args: argparse.Namespace, robot: Any) -> list[Any]:
    from taplan.trajectory import Trajectory
    from taplan.viz import Motion
    from taplan.viz.sources import motions_from_bag

    if args.file is None:
        return []
    path: Path = args.file
    if not path.is_file():
        raise InvalidInputError("file", str(path), "an existing trajectory (.json, .csv, .npz) or bag (.mcap) file")
    if path.suffix.lower() == ".mcap":
        return motions_from_bag(robot, path)
    if path.suffix.lower() not in TRAJECTORY_SUFFIXES:
        raise InvalidInputError("file", str(path), "a .json, .csv, .npz trajectory or a .mcap bag")
    return [Motion.from_trajectory(robot, Trajectory.load(path, robot.joint_names), "plan")]


def run(args: argparse.Namespace) -> int:
    from taplan.robot import Robot
    from taplan.viz import Viewer

    if args.file is None and not args.live:
        raise InvalidInputError("file", None, "a trajectory or bag file, or --live")
    if args.live and args.html is not None:
        raise InvalidInputError("--html", str(args.html), "a file source (a live view has nothing to record)")
    if args.duration is not None and not args.duration > 0:
        raise InvalidInputError("--duration", args.duration, "a positive time [s]")
    robot = Robot.from_urdf(args.urdf) if args.urdf is not None else Robot.teleavatar()
    motions = _motions(args, robot)
    scene = None
    if args.scene is not None:
        from taplan.scene import load_scene

        scene = load_scene(args.scene, robot)
    if args.html is not None:
        from taplan.viz import write_html

        with contextlib.redirect_stdout(io.StringIO()):  # viser's own banner
            written = write_html(args.html, *motions, scene=scene, robot=robot)
        print(f"wrote {written} (open it in a browser: no server needed)")
        return 0
    signal.signal(signal.SIGTERM, _interrupt)
    logging.getLogger("websockets").setLevel(logging.CRITICAL)  # a port scan's broken handshakes are not errors
    live = ("live",) if args.live else ()
    with contextlib.redirect_stdout(io.StringIO()):
        viewer = Viewer(robot, scene, motions, host=args.host, port=args.port, live=live)
    follower = None
    try:
        if args.live:
            follower = _start_live(args, viewer)
        if args.play:
            viewer.play()
        if viewer.skipped_visuals:
            print(
                f"taplan view: {len(viewer.skipped_visuals)} visual mesh file(s) missing or unreadable (first: "
                f"{viewer.skipped_visuals[0]}); drawing the collision bodies"
            )
        what = ", ".join(f"{m.name} {m.duration:.2f} s" for m in motions) or "live joint states"
        print(f"taplan view: {what} at {viewer.url} (Ctrl-C to stop)", flush=True)
        _wait(args.duration)
    except KeyboardInterrupt:
        pass
    finally:
        if follower is not None:
            follower.stop()
            follower.interface.close()
        with contextlib.redirect_stdout(io.StringIO()):
            viewer.close()
    print("taplan view: stopped", flush=True)
    return 0


def _start_live(args: argparse.Namespace, viewer: Any) -> Any:
    from taplan.ros.dds import DdsInterface, loopback_config
    from taplan.viz.sources import LiveFollower

    interface = DdsInterface(args.domain_id, config=loopback_config() if args.loopback else None)
    follower = LiveFollower(viewer, interface)
    follower.start()
    return follower


def _wait(duration: float | None) -> None:
    import time

    start = time.monotonic()
    while duration is None or time.monotonic() - start < duration:
        time.sleep(0.1)
