"""taplan.planning.kernels_ready: the compiled kernels' first calls happen before a plan's budget starts, with the
argument types the plans use (a plan afterwards compiles nothing more)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# in a fresh process: the kernels' compiled signatures after load_compiled_kernels, then after planning an optimised,
# a sampled and a pose-goal problem of the benchmark
_SCRIPT = """
import json, numba, numpy as np, taplan
from benchmarks._scenes import problems
from taplan.planning import plan_motion
from taplan.planning import clearance_kernel
from taplan.planning.kernels_ready import load_compiled_kernels
from taplan.scene import CollisionWorld, engine_kernels

def signatures():
    out = {}
    for module in (engine_kernels, clearance_kernel):
        for name, value in vars(module).items():
            if isinstance(value, numba.core.registry.CPUDispatcher) and value.__module__ == module.__name__:
                out[module.__name__ + "." + name] = len(value.signatures)
    return out

robot = taplan.Robot.teleavatar()
before = signatures()
load_compiled_kernels(robot)
loaded = signatures()
stages = []
for problem in problems(13, 0):
    if problem.index in (0, 3, 4, 5, 11):  # sampled, pose, optimised, two arms, attached
        plan = plan_motion(robot, problem.start, problem.goal, world=CollisionWorld(robot, problem.scene), seed=0)
        stages.append(plan.report.stage)
print(json.dumps({"before": before, "loaded": loaded, "after": signatures(), "stages": stages}))
"""


def test_a_plan_after_loading_the_kernels_compiles_nothing_more() -> None:
    run = subprocess.run(
        [sys.executable, "-c", _SCRIPT], capture_output=True, text=True, cwd=ROOT, timeout=600, check=True
    )
    found = json.loads(run.stdout.strip().splitlines()[-1])
    assert found["before"] and not any(found["before"].values())  # a fresh process: nothing compiled yet
    entries = ("self_pairs", "obstacle_pairs", "self_distances", "solid_distances", "first_blocked_along")
    for entry, count in found["loaded"].items():
        if entry.rsplit(".", 1)[-1] in entries:
            assert count >= 1, entry  # the engine's and the sampler's entry points
    assert found["after"] == found["loaded"]  # every type a plan used was loaded beforehand
    assert {"straight", "optimization", "rrt-connect"} & set(found["stages"])
