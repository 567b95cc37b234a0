"""Replay and check time of the reference controller models.

Scenario: a smooth random plan (cubic Hermite waypoints every 0.2 s, seeded) of 10 s and 60 s for 7 and 14 joints,
replayed through IndustrialSimulator (seed and intended, 100 Hz updates + 10 Hz joint_states), the
JointTrajectoryController model (100 Hz) and the joint-mode robot (60 Hz commands, 100 Hz loop), then checked.
Goal: replay of a 10 s, 14-joint plan at 100 Hz in <= 1 ms median (>= 10,000x real time).

Usage: ``python -m benchmarks.bench_reference [--quick] [--repeats N] [--no-save]``.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import numpy as np

from benchmarks import _harness
from taplan.check import check
from taplan.reference import IndustrialSimulator, JointModeRobot, JointTrajectoryController
from taplan.robot import Robot
from taplan.trajectory import Trajectory


def plan(robot: Robot, joints: int, duration: float, spacing: float = 0.2) -> Trajectory:
    rng = np.random.default_rng(7)
    names = robot.joint_names[:joints]
    t = np.arange(0.0, duration + 1e-9, spacing)
    lim = robot.planning_limits.subset(names)
    centre = robot.home[:joints]
    q = centre + 0.3 * np.cumsum(rng.uniform(-0.05, 0.05, (t.size, joints)), axis=0)
    q = np.clip(q, lim.lower, lim.upper)
    v = np.gradient(q, t, axis=0)
    v[0] = v[-1] = 0.0
    return Trajectory(t, q, v, joint_names=names)


def main(argv: Sequence[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats and only the 10 s plans")
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument("--no-save", action="store_true")
    args = parser.parse_args(argv)
    repeats = args.repeats or (30 if args.quick else 200)
    robot = Robot.teleavatar()
    durations = (10.0,) if args.quick else (10.0, 60.0)
    results: dict[str, dict] = {}
    rows = []
    for duration in durations:
        for joints in (7, 14):
            traj = plan(robot, joints, duration)
            lim = robot.limits.subset(traj.joint_names)
            cases = {
                "seed": lambda traj=traj: IndustrialSimulator(mode="seed").replay(traj),
                "intended": lambda traj=traj: IndustrialSimulator(mode="intended").replay(traj),
                "jtc": lambda traj=traj: JointTrajectoryController().replay(traj),
                "joint-position": lambda traj=traj, lim=lim: JointModeRobot(lim).replay_trajectory(traj, 60.0),
            }
            for model, call in cases.items():
                reps = repeats if model != "joint-position" else max(5, repeats // 10)
                replay = call()
                stats = _harness.time_calls(call, reps, warmup=min(10, reps))
                check_stats = _harness.time_calls(
                    lambda replay=replay, lim=lim: check(replay, lim), max(5, reps // 4), 3
                )
                key = f"{model}/{joints}j/{duration:g}s"
                speed = duration / (stats["median_us"] * 1e-6)
                results[key] = {
                    "replay": stats,
                    "check": check_stats,
                    "updates": len(replay),
                    "real_time_factor": speed,
                }
                rows.append(
                    [
                        model,
                        joints,
                        f"{duration:g}",
                        len(replay),
                        stats["median_us"] / 1e3,
                        stats["p95_us"] / 1e3,
                        check_stats["median_us"] / 1e3,
                        f"{speed:,.0f}x",
                    ]
                )
    goal = results["seed/14j/10s"]["replay"]["median_us"] <= 1000.0
    goal_i = results["intended/14j/10s"]["replay"]["median_us"] <= 1000.0
    md = "\n".join(
        [
            "## Reference controllers: replay and check",
            "",
            "A smooth plan (cubic Hermite waypoints every 0.2 s) replayed through each controller model in model time "
            "(100 Hz updates; joint_states at 10 Hz for the simulator; joint mode: 60 Hz commands into a 100 Hz loop), "
            "then `taplan.check` on the update stream. Times in ms (median, p95).",
            "",
            _harness.markdown_table(
                ["model", "joints", "plan [s]", "updates", "replay median", "replay p95", "check median", "real time"],
                rows,
            ),
            "",
            f"Goal (10 s, 14-joint plan replayed in <= 1 ms median, >= 10,000x real time): seed "
            f"{'met' if goal else 'NOT met'} ({results['seed/14j/10s']['replay']['median_us'] / 1e3:.3f} ms), "
            f"intended {'met' if goal_i else 'NOT met'} "
            f"({results['intended/14j/10s']['replay']['median_us'] / 1e3:.3f} ms).",
        ]
    )
    if not args.no_save:
        _harness.save("reference", results, md)
    print(md)
    return results


if __name__ == "__main__":
    main()
