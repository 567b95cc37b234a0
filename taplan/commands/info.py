"""Print the robot model: joints, limits, home pose and end-effector poses at home.

By default the bundled TeleAvatar; ``--urdf`` loads any URDF (its own limits, home at the limits' midpoint).
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import numpy as np
import pinocchio as pin

import taplan


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--urdf", help="a URDF to load instead of the bundled TeleAvatar")
    parser.add_argument("--json", action="store_true", help="print JSON instead of tables")


def run(args: argparse.Namespace) -> int:
    robot = taplan.Robot.from_urdf(args.urdf) if args.urdf else taplan.Robot.teleavatar()
    frames = {g.ee_frame: g.base_frame for g in robot.groups.values()}
    poses = robot.frame_poses(robot.home, frames) if frames else {}
    if args.json:
        payload = {
            "model": robot.urdf_path.name,
            "joint_names": list(robot.joint_names),
            "limits": robot.limits.to_dict(),
            "planning_limits": robot.planning_limits.to_dict(),
            "limit_differences": [dataclasses.asdict(d) for d in robot.limits.differences],
            "home": robot.home.tolist(),
            "ee_poses_at_home": {f: T.tolist() for f, T in poses.items()},
        }
        print(json.dumps(payload, indent=2))
        return 0
    print(f"taplan {taplan.__version__}  model {robot.urdf_path}")
    print(f"{robot.nq} joints (model order): {', '.join(robot.joint_names)}")
    for group in robot.groups.values():
        print(f"  group {group.name!r}: {', '.join(group.joint_names)}; ee {group.ee_frame}, base {group.base_frame}")
    print(f"collision capsules: {len(robot.capsules)} ({', '.join(c.link for c in robot.capsules)})")
    print("\nHardware limits [rad, rad/s, rad/s^2, rad/s^3]:")
    print(robot.limits)
    print("\nWhere the limit sources disagree (rule: the more restrictive wins unless overridden, reason given):")
    print(limit_sources(robot.limits))
    scale = taplan.DEFAULT_PLANNING_SCALING
    print(
        f"\nPlanning limits = hardware x {scale.velocity} (velocity), x {scale.acceleration} (acceleration), "
        f"x {scale.jerk} (jerk), {scale.position_margin} rad inside each bound."
    )
    print("\nHome pose [rad]:")
    for name, value in zip(robot.joint_names, robot.home, strict=True):
        print(f"  {name:<9} {value:+.4f}")
    for frame, T in poses.items():
        base = frames[frame]
        T_base = robot.relative_pose(robot.home, frame, base)
        quat = pin.Quaternion(T[:3, :3]).coeffs()  # xyzw
        print(f"\n{frame} at home, in the root frame {robot.model.frames[1].name!r}:")
        print(f"  position [m] {np.array2string(T[:3, 3], precision=4, suppress_small=True)}")
        print(f"  quaternion xyzw {np.array2string(quat, precision=4, suppress_small=True)}")
        print(f"  in {base}: position [m] {np.array2string(T_base[:3, 3], precision=4, suppress_small=True)}")
        print(np.array2string(T, precision=4, suppress_small=True, prefix="  "))
    return 0


def limit_sources(limits: taplan.JointLimits) -> str:
    """Every disagreement per quantity (position, velocity, acceleration, jerk), or why there can be none."""
    lines = []
    groups = {"position": ("lower", "upper"), "velocity": ("velocity",), "acceleration": ("acceleration",)}
    groups["jerk"] = ("jerk",)
    for quantity, bounds in groups.items():
        rows = [d for d in limits.differences if d.bound in bounds]
        if not rows:
            single = {
                "acceleration": "only arm_config gives one (a URDF has no acceleration limit)",
                "jerk": "no source gives one; taplan uses 10 x the acceleration limit",
            }
            lines.append(f"  {quantity}: no disagreement" + (f" ({single[quantity]})" if quantity in single else ""))
            continue
        lines.append(f"  {quantity}: {len(rows)} disagreement(s)")
        reasons = {d.reason for d in rows if d.reason}
        for d in rows:
            note = "  (overridden)" if d.reason else ""
            lines.append(
                f"    {d.joint:<9} {d.bound:<8} arm_config {d.config:+.3f}, URDF {d.model:+.3f} -> {d.used:+.3f}{note}"
            )
        lines += [f"    overridden because {reason}" for reason in sorted(reasons)]
    return "\n".join(lines)
