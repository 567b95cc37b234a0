"""Where plan_motion's time goes: cProfile over problems of ``benchmarks/_scenes.py``, with the per-stage sums of
``PlanReport.stage_times`` (wall) beside the CPU time of each stage's functions (the profiler runs on
``time.process_time``: the machine is shared, CPU time is what the planner itself spent) and the functions with the
most cumulative and own CPU time.

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
# the functions whose cumulative CPU time is a stage's (wall: PlanReport.stage_times)
STAGE_FUNCTIONS = {
    "goal_ik": ("motion.py", "_goal_ik"),
    "straight": ("verify.py", "check_segment"),
    "optimize+smooth": ("optimize.py", "optimize_path"),
    # inside the optimiser: its batched distance evaluations (with Jacobian rows), the QPs' rows, the QP solves
    # (calls = SCP iterations), its final certificate
    "  evaluations": ("optimize.py", "_evaluate"),
    "  QP rows": ("optimize.py", "_linearised"),
    "  QP solves": ("solve_qp.py", "solve_qp", "optimize.py", "_sequential_convex"),
    "  certificate": ("verify.py", "check_segments", "optimize.py", "optimize_path"),
    "sample": ("rrt.py", "rrt_connect_shrinking"),
    "timing (jerk_limited)": ("jerk_limited.py", "jerk_limited"),
    "timing (straight_line)": ("straight.py", "straight_line"),
    "verify": ("verify.py", "verify_trajectory"),
    "time_and_verify": ("motion.py", "_time_and_verify"),
}


def _stage_cpu(stats: pstats.Stats) -> dict[str, tuple[int, float]]:
    """Calls and cumulative CPU seconds of each stage's function (recursion counted once); with a caller
    ``(module, name, caller module, caller name)``: only the calls from that caller."""
    out = {}
    for stage, (module, name, *caller) in STAGE_FUNCTIONS.items():
        calls, seconds = 0, 0.0
        for (path, _line, function), (_cc, nc, _tt, ct, callers) in stats.stats.items():  # type: ignore[attr-defined]
            if function != name or not path.endswith(module):
                continue
            if not caller:
                calls, seconds = calls + nc, seconds + ct
                continue
            for (caller_path, _, caller_name), (_ccc, c_nc, _c_tt, c_ct) in callers.items():
                if caller_name == caller[1] and caller_path.endswith(caller[0]):
                    calls, seconds = calls + c_nc, seconds + c_ct
        out[stage] = (calls, seconds)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problems", type=int, default=26)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--top", type=int, default=30)
    args = parser.parse_args(argv)
    logging.getLogger("toppra").setLevel(logging.ERROR)
    robot = taplan.Robot.teleavatar()
    suite = problems(args.problems, args.seed)
    profile = cProfile.Profile(time.process_time)
    seconds, cpu, totals = [], [], {}
    for problem in suite:
        world = CollisionWorld(robot, problem.scene)
        begin, begin_cpu = time.perf_counter(), time.process_time()
        profile.enable()
        try:
            plan = plan_motion(robot, problem.start, problem.goal, world=world, max_time=MAX_TIME, seed=problem.index)
            stage, stage_times = plan.report.stage, plan.report.stage_times
        except taplan.TaplanError as exc:
            stage, stage_times = f"failed ({str(exc)[:60]})", {}
        profile.disable()
        seconds.append(time.perf_counter() - begin)
        cpu.append(time.process_time() - begin_cpu)
        for key, value in stage_times.items():
            totals[key] = totals.get(key, 0.0) + value
        spent = " ".join(f"{k}={v * 1e3:.0f}" for k, v in stage_times.items() if v > 5e-4)
        ms = seconds[-1] * 1e3
        cpu_ms = cpu[-1] * 1e3
        head = f"{problem.index:3d} {problem.family:10s} {problem.kind:5s}"
        print(f"{head} {ms:8.1f} ms ({cpu_ms:6.1f} CPU) {stage}  {spent}")
    for what, values in (("wall", seconds), ("CPU", cpu)):
        median, p95 = np.median(values) * 1e3, np.percentile(values, 95) * 1e3
        print(f"{what}: median {median:.1f} ms, p95 {p95:.1f} ms, sum {sum(values):.3f} s")
    print("stage sums, wall [s]:", {k: round(v, 3) for k, v in totals.items()})
    stats = pstats.Stats(profile)
    print("stage CPU [s] (calls):")
    for stage, (calls, spent_cpu) in _stage_cpu(stats).items():
        print(f"  {stage:24s} {spent_cpu:8.3f} ({calls})")
    stats.sort_stats("cumulative").print_stats(args.top)
    stats.sort_stats("tottime").print_stats(args.top)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
