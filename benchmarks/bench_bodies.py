"""What the robot's collision bodies cost: distance queries, and an IK step with collision avoidance.

Measured on the bundled TeleAvatar and table scene (``models/teleavatar/scenes/table.yaml``), seeded:

* ``distances``: ``CollisionWorld.distances(q)`` with Jacobians (every pair: self and scene) at 200 random clear
  configurations; queries per second = 1 / median;
* ``distances, cutoff``: the same within 0.15 m (what the IK's scene limit asks for: influence plus a band);
* ``min_distance``: ``CollisionWorld.min_distance(q)`` (no Jacobians), same configurations;
* ``ik step``: ``DifferentialIK.step`` with the scene (``SceneLimit``) and the arm-arm ``CollisionLimit``, both
  hands moving to targets 10 cm below their home poses: 3 x 300 consecutive steps (dt 0.01 s) from home;
* ``planning``: ``plan_motion`` (5 s budget) on the seeded problems of ``benchmarks/_scenes.py`` (every family in
  turn; the problems are drawn clear for the bodies under test, so each version plans its own set): success and
  time per family.

Each query is timed per call after a warm-up, wall clock and CPU time (``time.process_time``: the machine is shared,
CPU time is the steadier figure); median and p95. Side by side in the same run:

* ``coal``: the same world with ``engine=False`` (every robot-obstacle pair a coal query, the joint Jacobians from
  pinocchio): the per-pair path the closed forms replace;
* ``--baseline CHECKOUT``: another checkout's taplan (e.g. the commit before the real body) in a subprocess with
  the same script, e.g. ``git worktree add /tmp/before 3769945`` then ``--baseline /tmp/before``.

Run: ``python -m benchmarks.bench_bodies [--no-save] [--planning N] [--baseline CHECKOUT]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import taplan
from taplan.ik import DifferentialIK
from taplan.scene import CollisionWorld
from taplan.scene.io import load_scene

SCENE = Path(taplan.__file__).parent / "models" / "teleavatar" / "scenes" / "table.yaml"
CUTOFF = 0.15  # [m] the IK scene limit's band (influence 0.05 m + 0.1 m)
QUERIES = ("distances", "distances_cutoff", "min_distance", "ik_step")
LABELS = {
    "distances": "distances, all pairs, with Jacobians",
    "distances_cutoff": f"distances within {CUTOFF} m, with Jacobians",
    "min_distance": "min_distance",
    "ik_step": "IK step, scene + arm-arm avoidance",
}


def _times(func, calls: list, warmup: int = 20) -> dict[str, float]:
    for args in calls[:warmup]:
        func(*args)
    wall, cpu = [], []
    for args in calls:
        c0, t0 = time.process_time(), time.perf_counter()
        func(*args)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return _stats(np.array(wall) * 1e6, np.array(cpu) * 1e6)


def _stats(wall_us: np.ndarray, cpu_us: np.ndarray) -> dict[str, float]:
    return {
        "median_us": float(np.median(wall_us)),
        "p95_us": float(np.percentile(wall_us, 95)),
        "cpu_median_us": float(np.median(cpu_us)),
        "cpu_p95_us": float(np.percentile(cpu_us, 95)),
        "per_second": float(1e6 / np.median(wall_us)),
    }


def _world(robot: taplan.Robot, engine: bool) -> CollisionWorld:
    scene = load_scene(SCENE)
    if engine:
        return CollisionWorld(robot, scene)
    try:
        return CollisionWorld(robot, scene, engine=False)
    except TypeError:  # a checkout from before the engine: coal is its only path
        return CollisionWorld(robot, scene)


def measure(engine: bool = True) -> dict[str, Any]:
    robot = taplan.Robot.teleavatar()
    world = _world(robot, engine)
    rng = np.random.default_rng(25)
    lim = robot.planning_limits
    clear = []
    while len(clear) < 200:
        q = robot.home + rng.uniform(-0.5, 0.5, robot.nq)
        q = np.clip(q, lim.lower, lim.upper)
        if world.min_distance(q)[0] > 0.0:
            clear.append((q,))
    out: dict[str, Any] = {
        "bodies": {"count": float(len(world.bodies)), "self_pairs": float(len(world.self_pairs))},
        "distances": _times(lambda q: world.distances(q), clear),
        "distances_cutoff": _times(lambda q: world.distances(q, cutoff=CUTOFF), clear),
        "min_distance": _times(lambda q: world.min_distance(q), clear),
    }
    ik = DifferentialIK(robot, dt=0.01, scene=world)
    targets = {}
    for frame in ("left_ee", "right_ee"):
        T = robot.frame_pose(robot.home, frame)
        T[:3, 3] += [0.0, 0.0, -0.10]
        targets[frame] = T
    wall, cpu = [], []
    for run in range(4):  # consecutive steps as in a control loop, each run from home (the first run warms up)
        ik.reset(robot.home)
        for _ in range(300):
            c0, t0 = time.process_time(), time.perf_counter()
            ik.step(targets)
            if run:
                wall.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
    out["ik_step"] = _stats(np.array(wall) * 1e6, np.array(cpu) * 1e6)
    return out


def baseline(checkout: str) -> dict[str, Any]:
    """:func:`measure` of another checkout's taplan (this script in a subprocess with it on ``PYTHONPATH``)."""
    env = dict(os.environ, PYTHONPATH=str(Path(checkout).resolve()))
    done = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), "--measure-only"],
        env=env,
        capture_output=True,
        text=True,
        check=True,
        cwd=str(Path(checkout).resolve()),
    )
    commit = subprocess.run(
        ["git", "-C", checkout, "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
    ).stdout.strip()
    result = json.loads(done.stdout.strip().splitlines()[-1])
    result["commit"] = commit
    return result


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


def _merged(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Several rounds of :func:`measure` as one: per query and statistic the median over the rounds."""
    out: dict[str, Any] = {"bodies": runs[0]["bodies"]}
    for query in QUERIES:
        out[query] = {key: float(np.median([run[query][key] for run in runs])) for key in runs[0][query]}
    return out


def _versions(results: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    versions = [("taplan", results["taplan"]), ("coal per pair (engine=False)", results["coal"])]
    if "baseline" in results:
        versions.append((f"baseline {results['baseline'].get('commit', '')}", results["baseline"]))
    return versions


def _rows(versions: list[tuple[str, dict[str, Any]]]) -> list[list[str]]:
    """One row per query and version: wall median / p95, CPU median / p95, queries per second."""
    rows = []
    for query in QUERIES:
        for name, res in versions:
            s = res[query]
            rows.append(
                [
                    LABELS[query],
                    name,
                    f"{int(res['bodies']['count'])} / {int(res['bodies']['self_pairs'])}",
                    f"{s['median_us']:.0f}",
                    f"{s['p95_us']:.0f}",
                    f"{s['cpu_median_us']:.0f}",
                    f"{s['cpu_p95_us']:.0f}",
                    f"{s['per_second']:.0f}",
                ]
            )
    return rows


HEADER = ["query", "version", "bodies / self pairs", "median [µs]", "p95 [µs]", "CPU median [µs]", "CPU p95 [µs]"]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-save", action="store_true")
    parser.add_argument("--quick", action="store_true", help="10 planning problems")
    parser.add_argument("--planning", type=int, default=20, help="planning problems (0: none)")
    parser.add_argument("--baseline", metavar="CHECKOUT", help="also measure this checkout's taplan (subprocess)")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds with --baseline")
    parser.add_argument("--measure-only", action="store_true", help=argparse.SUPPRESS)  # the baseline's side
    args = parser.parse_args(argv)
    if args.measure_only:
        print(json.dumps(measure()))
        return
    if args.quick:
        args.planning = min(args.planning, 10)
    results: dict[str, Any] = {"coal": measure(engine=False)}
    if args.baseline:  # alternate rounds: the load of a shared machine drifts between them
        ours, theirs = [], []
        for _ in range(args.rounds):
            theirs.append(baseline(args.baseline))
            ours.append(measure())
        results["taplan"], results["baseline"] = _merged(ours), _merged(theirs)
        results["baseline"]["commit"] = theirs[0]["commit"]
        results["ratio"] = {
            query: {
                clock: float(np.median([o[query][clock] / t[query][clock] for o, t in zip(ours, theirs, strict=True)]))
                for clock in ("median_us", "cpu_median_us")
            }
            for query in QUERIES
        }
        results["rounds"] = args.rounds
    else:
        results["taplan"] = measure()
    results["quick"] = bool(args.quick)
    if args.planning:
        results["planning"] = planning(args.planning)
        for family, row in results["planning"].items():
            print(
                f"planning {family:10s} {int(row['solved'])}/{int(row['problems'])} solved, "
                f"mean {row['seconds'] / row['problems']:.2f} s"
            )
    rows = _rows(_versions(results))
    for row in rows:
        print(
            f"{row[0]:40s} {row[1]:32s} {row[2]:>8s}  median {row[3]:>6s} us  p95 {row[4]:>6s}  "
            f"CPU {row[5]:>6s} / {row[6]:>6s}  ({row[7]:>6s} /s)"
        )
    ratio_rows = [
        [LABELS[q], f"{r['median_us']:.2f}", f"{r['cpu_median_us']:.2f}"] for q, r in results.get("ratio", {}).items()
    ]
    for row in ratio_rows:
        print(f"taplan / baseline  {row[0]:40s} wall {row[1]}x  CPU {row[2]}x")
    if not args.no_save:
        from benchmarks import _harness

        text = (
            "## Collision bodies: distance queries and IK step (taplan.scene, table scene)\n\n"
            "`python -m benchmarks.bench_bodies"
            + (" --baseline <checkout of " + results["baseline"].get("commit", "") + ">" if args.baseline else "")
            + "`: per call after a warm-up, 200 seeded clear configurations (IK: 900 consecutive steps); wall "
            "clock and CPU time (shared, loaded machine: CPU time is the steadier figure).\n\n"
            + _harness.markdown_table(HEADER + ["per second"], rows)
        )
        if ratio_rows:
            text += (
                f"\n\ntaplan / baseline {results['baseline']['commit']}, median over {results['rounds']} alternating "
                "rounds of the per-round ratio of medians:\n\n"
                + _harness.markdown_table(["query", "wall", "CPU"], ratio_rows)
            )
        if "planning" in results:
            total = int(sum(r["problems"] for r in results["planning"].values()))
            text += f"\n\n`plan_motion` (5 s budget) on {total} seeded problems of `benchmarks/_scenes.py`:"
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
