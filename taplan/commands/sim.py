"""Play the TeleAvatar over ROS 2 (DDS): the /api topics in, joint states, end-effector poses and FSM out.

Runs the joint-mode model with the FSM rules of the developer guide (no motion without a heartbeat, force pause
after 1 s without ``/api/fsm/enable`` 1.0, commands validated and clipped, gripper range [0, 1]) until Ctrl-C or
``--duration``. With ``--scene table.yaml --depth`` it also publishes the wrist depth cameras' images of that scene
(``/{left,right}/depth/image_raw`` 16UC1 and ``camera_info``, rendered through the camera model at
``--depth-rate``), so perception runs end to end without the robot. Rehearse a program end to end with ``taplan sim
--loopback`` in one terminal and ``taplan run --loopback plan.json`` (or your own ROS 2 code on the same
ROS_DOMAIN_ID) in another.
"""

from __future__ import annotations

import argparse
import math
import time
from typing import Any

from taplan.commands._ros_args import add_transport_arguments, open_transport
from taplan.errors import InvalidInputError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_transport_arguments(parser)
    parser.add_argument("--duration", type=float, default=None, help="stop after this many seconds (default: never)")
    parser.add_argument("--rate", type=float, default=100.0, help="joint_states / current_ee_pose rate [Hz] (100)")
    parser.add_argument("--motion-rate", type=float, default=100.0, help="motion model rate [Hz] (100, the robot's)")
    parser.add_argument(
        "--motion",
        choices=("joint", "interpolate"),
        default="joint",
        help="motion model: joint (move to the latest command at the velocity ceiling, the robot's joint mode) or "
        "interpolate (the seed simulator's linear interpolation between streamed commands)",
    )
    parser.add_argument(
        "--refuse-out-of-range",
        action="store_true",
        help="refuse commands outside the hardware limits (default: clip them; either way they are logged and counted)",
    )
    parser.add_argument(
        "--stall-after", type=float, default=None, help="fault injection: stop joint_states after this many seconds"
    )
    parser.add_argument("--scene", default=None, help="what the simulated depth cameras see (.yaml/.json)")
    parser.add_argument("--depth", action="store_true", help="publish wrist depth images of --scene")
    parser.add_argument("--depth-rate", type=float, default=5.0, help="depth images per camera per second (5)")
    parser.add_argument(
        "--depth-size", choices=("quarter", "full"), default="quarter", help="depth image 160x120 (quarter) or 640x480"
    )


MAX_SIM_RATE = 1000.0  # [Hz]


def run(args: argparse.Namespace) -> int:
    from taplan.io import bounded_rate
    from taplan.robot import Robot
    from taplan.ros.sim import SimConfig, SimulatedRobot

    for name in ("duration", "stall_after"):
        value = getattr(args, name)
        if value is not None and not (math.isfinite(value) and value > 0):
            raise InvalidInputError(f"--{name.replace('_', '-')}", value, "a time > 0 s")
    config = SimConfig(
        # the loop below polls every 0.5 ms: faster streams than 1 kHz could not be kept
        state_rate=bounded_rate(args.rate, "--rate", high=MAX_SIM_RATE),
        motion_rate=bounded_rate(args.motion_rate, "--motion-rate", high=MAX_SIM_RATE),
        stall_after=args.stall_after,
        motion=args.motion,
        refuse_out_of_range=args.refuse_out_of_range,
    )
    if args.depth and args.scene is None:
        raise InvalidInputError("--depth", "no --scene", "a scene file for the cameras to see (--scene FILE)")
    interface, bag = open_transport(args)
    robot = Robot.teleavatar()
    sim = SimulatedRobot(interface, robot, config)
    cameras = _depth_cameras(args, interface, sim)
    print(f"taplan sim: TeleAvatar on ROS_DOMAIN_ID {interface.domain_id}; Ctrl-C to stop", flush=True)
    start = time.monotonic()
    try:
        while args.duration is None or time.monotonic() - start < args.duration:
            interface.spin_once()
            sim.step()
            if cameras is not None:
                cameras.step()
            time.sleep(0.0005)
    except KeyboardInterrupt:
        pass
    finally:
        interface.close()
        if bag is not None:
            bag.close()
            print(f"wrote {bag.path} ({bag.count} messages)")
    print(f"taplan sim: stopped in {sim.fsm.name}; rejected {sim.rejected or 'nothing'}", flush=True)
    return 0


def _depth_cameras(args: argparse.Namespace, interface: Any, sim: Any) -> Any:
    """The simulated wrist depth cameras of ``--scene`` (None without ``--depth``)."""
    if not args.depth:
        return None
    from taplan.ros.sim_depth import SIM_DEPTH_CAMERA, DepthCameraSim
    from taplan.scene import load_scene
    from taplan.scene.camera import WRIST_DEPTH_CAMERA

    camera = WRIST_DEPTH_CAMERA if args.depth_size == "full" else SIM_DEPTH_CAMERA
    return DepthCameraSim(interface, sim, load_scene(args.scene), camera=camera, rate=args.depth_rate)
