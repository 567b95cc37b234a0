"""What the robot's collision bodies cost: distance queries, and an IK step with collision avoidance.

Measured on the bundled TeleAvatar and table scene (``models/teleavatar/scenes/table.yaml``), seeded:

* ``distances``: ``CollisionWorld.distances(q)`` with Jacobians (every pair: self and scene) at 200 random clear
  configurations; queries per second = 1 / median;
* ``min_distance``: ``CollisionWorld.min_distance(q)`` (no Jacobians), same configurations;
* ``planning``: ``plan_motion`` (5 s budget) on the seeded problems of ``benchmarks/_scenes.py`` (every family in
  turn; the problems are drawn clear for the bodies under test, so each version plans its own set): success and
  time per family;
* ``ik step``: ``DifferentialIK.step`` with the scene (``SceneLimit``) and the arm-arm ``CollisionLimit``, both
  hands moving to targets 10 cm below their home poses: 3 x 300 consecutive steps (dt 0.01 s) from home.

The same file runs against another checkout for a before/after figure (its taplan on ``PYTHONPATH``):
``PYTHONPATH=<checkout> python benchmarks/bench_bodies.py --no-save``.

Run: ``python -m benchmarks.bench_bodies [--no-save]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import taplan
from taplan.ik import DifferentialIK
from taplan.scene import CollisionWorld
from taplan.scene.io import load_scene

SCENE = Path(taplan.__file__).parent / "models" / "teleavatar" / "scenes" / "table.yaml"


def _times(func, calls: list, warmup: int = 20) -> np.ndarray:
    for args in calls[:warmup]:
        func(*args)
    out = []
    for args in calls:
        t0 = time.perf_counter()
        func(*args)
        out.append(time.perf_counter() - t0)
    return np.array(out) * 1e6


def _stats(us: np.ndarray) -> dict[str, float]:
    return {"median_us": float(np.median(us)), "p95_us": float(np.percentile(us, 95))}


def measure() -> dict[str, dict[str, float]]:
    robot = taplan.Robot.teleavatar()
    world = CollisionWorld(robot, load_scene(SCENE))
    rng = np.random.default_rng(25)
    lim = robot.planning_limits
    clear = []
    while len(clear) < 200:
        q = robot.home + rng.uniform(-0.5, 0.5, robot.nq)
        q = np.clip(q, lim.lower, lim.upper)
        if world.min_distance(q)[0] > 0.0:
            clear.append((q,))
    out = {
        "bodies": {"count": float(len(world.bodies)), "self_pairs": float(len(world.self_pairs))},
        "distances": _stats(_times(lambda q: world.distances(q), clear)),
        "min_distance": _stats(_times(lambda q: world.min_distance(q), clear)),
    }
    ik = DifferentialIK(robot, dt=0.01, scene=world)
    targets = {}
    for frame in ("left_ee", "right_ee"):
        T = robot.frame_pose(robot.home, frame)
        T[:3, 3] += [0.0, 0.0, -0.10]
        targets[frame] = T
    steps = []
    for _ in range(4):  # consecutive steps as in a control loop, each run from home (the first run warms up)
        ik.reset(robot.home)
        run = []
        for _ in range(300):
            t0 = time.perf_counter()
            ik.step(targets)
            run.append(time.perf_counter() - t0)
        steps.append(run)
    out["ik_step"] = _stats(np.array(steps[1:]).ravel() * 1e6)
    return out


def planning(count: int) -> dict[str, dict[str, float]]:
    from benchmarks._scenes import problems
    from taplan.planning import plan_motion

    robot = taplan.Robot.teleavatar()
    out: dict[str, dict[str, float]] = {}
    for problem in problems(count, seed=0):
        row = out.setdefault(problem.family, {"problems": 0.0, "solved": 0.0, "seconds": 0.0})
        t0 = time.perf_counter()
        try:
            plan_motion(robot, problem.start, problem.goal, problem.scene, max_time=5.0)
            row["solved"] += 1
        except taplan.errors.TaplanError:
            pass
        row["seconds"] += time.perf_counter() - t0
        row["problems"] += 1
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-save", action="store_true")
    parser.add_argument("--quick", action="store_true", help="10 planning problems")
    parser.add_argument("--planning", type=int, default=20, help="planning problems (0: none)")
    args = parser.parse_args(argv)
    if args.quick:
        args.planning = min(args.planning, 10)
    results = measure()
    if args.planning:
        results["planning"] = planning(args.planning)
        for family, row in results["planning"].items():
            print(
                f"planning {family:10s} {int(row['solved'])}/{int(row['problems'])} solved, "
                f"mean {row['seconds'] / row['problems']:.2f} s"
            )
    rows = [
        ("distances (with Jacobians)", results["distances"], 1e6 / results["distances"]["median_us"]),
        ("min_distance", results["min_distance"], 1e6 / results["min_distance"]["median_us"]),
        ("IK step, scene + arm-arm avoidance", results["ik_step"], 1e6 / results["ik_step"]["median_us"]),
    ]
    b = results["bodies"]
    print(f"bodies {int(b['count'])}, self pairs checked {int(b['self_pairs'])}")
    for name, s, rate in rows:
        print(f"{name:38s} median {s['median_us']:8.1f} us  p95 {s['p95_us']:8.1f} us  ({rate:8.0f} /s)")
    if not args.no_save:
        from benchmarks import _harness

        table = _harness.markdown_table(
            ["query", "median [µs]", "p95 [µs]", "per second"],
            [[n, f"{s['median_us']:.1f}", f"{s['p95_us']:.1f}", f"{r:.0f}"] for n, s, r in rows],
        )
        text = (
            "## Collision bodies: distance queries and IK step (taplan.scene, table scene)\n\n"
            f"{int(b['count'])} bodies, {int(b['self_pairs'])} self pairs checked. `python -m benchmarks.bench_bodies`"
            "\n\n" + table
        )
        if "planning" in results:
            text += "\n\n" + _harness.markdown_table(
                ["family", "solved", "mean time [s]"],
                [
                    [f, f"{int(r['solved'])}/{int(r['problems'])}", f"{r['seconds'] / r['problems']:.2f}"]
                    for f, r in results["planning"].items()
                ],
            )
        _harness.save("bodies", results, text)


if __name__ == "__main__":
    main()
