"""Where plan_motion's time goes: cProfile over problems of ``benchmarks/_scenes.py``, with the per-stage sums of
``PlanReport.stage_times`` and the functions with the most cumulative and own time.

Run: ``python -m benchmarks.profile_planning [--problems 26] [--seed 0] [--top 30]``.
"""

from __future__ import annotations

import argparse
import cProfile
import logging
import pstats
import time

import numpy as np

import taplan
from benchmarks._scenes import problems
from taplan.planning import plan_motion
from taplan.scene import CollisionWorld

MAX_TIME = 5.0  # [s] the benchmark's budget


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problems", type=int, default=26)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--top", type=int, default=30)
    args = parser.parse_args(argv)
    logging.getLogger("toppra").setLevel(logging.ERROR)
    robot = taplan.Robot.teleavatar()
    suite = problems(args.problems, args.seed)
    profile = cProfile.Profile()
    seconds, totals = [], {}
    for problem in suite:
        world = CollisionWorld(robot, problem.scene)
        begin = time.perf_counter()
        profile.enable()
        try:
            plan = plan_motion(robot, problem.start, problem.goal, world=world, max_time=MAX_TIME, seed=problem.index)
            stage, stage_times = plan.report.stage, plan.report.stage_times
        except taplan.TaplanError as exc:
            stage, stage_times = f"failed ({str(exc)[:60]})", {}
        profile.disable()
        seconds.append(time.perf_counter() - begin)
        for key, value in stage_times.items():
            totals[key] = totals.get(key, 0.0) + value
        spent = " ".join(f"{k}={v * 1e3:.0f}" for k, v in stage_times.items() if v > 5e-4)
        ms = seconds[-1] * 1e3
        print(f"{problem.index:3d} {problem.family:10s} {problem.kind:5s} {ms:8.1f} ms  {stage}  {spent}")
    print(f"median {np.median(seconds) * 1e3:.1f} ms, p95 {np.percentile(seconds, 95) * 1e3:.1f} ms")
    print("stage sums [s]:", {k: round(v, 3) for k, v in totals.items()}, "calls:", round(sum(seconds), 3))
    stats = pstats.Stats(profile)
    stats.sort_stats("cumulative").print_stats(args.top)
    stats.sort_stats("tottime").print_stats(args.top)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
