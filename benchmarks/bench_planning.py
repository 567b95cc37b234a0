"""Motion planning in scenes: taplan.planning.plan_motion vs OMPL RRT-Connect + its simplifier + toppra.

The seeded suite of ``benchmarks/_scenes.py`` (thirteen scene families, joint and pose goals, one and both arms).
Both planners first plan problems of another seed untimed (one per family for taplan, one for OMPL): the first calls
of a process load compiled kernels (CasADi, numba) and fill caches, which no later call pays. Then for each problem,
in the same process:

* ``taplan``: ``plan_motion(robot, start, goal, scene)`` (goal IK for pose goals, certified path, jerk-limited
  timing, verified);
* ``ompl``: OMPL's RRT-Connect in the moving joints with a state validity check (signed distance >= 0 with the same
  collision world, OMPL's default motion-check resolution), ``simplifySolution``, then toppra with its defaults
  (velocity and acceleration limits, default gridpoints) on a spline through the simplified path. Pose goals get
  the problem's goal configuration (the peer is spared the IK).

Both are then checked by the same independent dense check: the timed trajectory sampled so that no link point moves
more than 1 mm between samples (bound ``Σ reach |Δq|``), counting samples in collision (signed distance < 0).

Run: ``python -m benchmarks.bench_planning [--problems 200] [--quick]``.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np

import taplan
from benchmarks import _harness
from benchmarks._peer import TRAVEL, CompiledScene, dense_check, motion_resolution
from benchmarks._scenes import FAMILIES, problems
from taplan.planning import plan_motion
from taplan.planning.motion import BUDGET_TOLERANCE
from taplan.scene import CollisionWorld

MAX_TIME = 5.0  # [s] per planner and problem
WARM_UP_SEED = 1000  # the warm-up's problems: this far from the suite's seed
BODIES_CODE = "taplan/scene/robot_bodies.py"  # with models/teleavatar: where the robot's bodies come from


def toppra_defaults(robot: taplan.Robot, waypoints: np.ndarray, active: np.ndarray) -> Any:
    """toppra with its defaults (:func:`benchmarks.bench_timing.toppra_defaults`) on a spline through the waypoints
    (K, len(active)) of the ``active`` joints; None when it fails."""
    from benchmarks.bench_timing import toppra_defaults as timed
    from taplan.timing import Path

    sub = robot.planning_limits.subset([robot.joint_names[j] for j in active])
    if len(waypoints) == 2:
        waypoints = np.array([waypoints[0], (waypoints[0] + waypoints[1]) / 2, waypoints[1]])
    return timed(Path(waypoints), sub)


def ompl_setup(
    world: CollisionWorld, compiled: CompiledScene, robot: taplan.Robot, start: np.ndarray, active: np.ndarray
) -> Any:
    """OMPL's SimpleSetup in the ``active`` joints (the others held at ``start``) as its users would set it up:
    the compiled validity check, a motion-check resolution that cannot step through the thinnest obstacle."""
    from ompl import base as ob
    from ompl import geometric as og

    n = len(active)
    limits = robot.planning_limits
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    for k, j in enumerate(active):
        bounds.setLow(k, float(limits.lower[j]))
        bounds.setHigh(k, float(limits.upper[j]))
    space.setBounds(bounds)
    setup = og.SimpleSetup(space)
    q = start.copy()

    class Validity(ob.StateValidityChecker):
        def isValid(self, state: Any) -> bool:  # noqa: N802 (OMPL's name)
            q[active] = [state[k] for k in range(n)]
            return compiled.valid(q)

    setup.setStateValidityChecker(Validity(setup.getSpaceInformation()))
    setup.getSpaceInformation().setStateValidityCheckingResolution(
        motion_resolution(world, active, space.getMaximumExtent())
    )
    setup.setPlanner(og.RRTConnect(setup.getSpaceInformation()))
    return setup


def ompl_pipeline(
    world: CollisionWorld, compiled: CompiledScene, robot: taplan.Robot, start: np.ndarray, goal: np.ndarray
) -> dict[str, Any]:
    begin, begin_cpu = time.perf_counter(), time.process_time()
    active = np.flatnonzero(np.abs(goal - start) > 1e-12)
    n = len(active)
    setup = ompl_setup(world, compiled, robot, start, active)
    space = setup.getStateSpace()
    s, g = space.allocState(), space.allocState()
    for k, j in enumerate(active):
        s[k] = float(start[j])
        g[k] = float(goal[j])
    setup.setStartAndGoalStates(s, g)
    solved = setup.solve(MAX_TIME)
    if not setup.haveExactSolutionPath():
        return {
            "success": False,
            "certified": False,
            "seconds": time.perf_counter() - begin,
            "cpu": time.process_time() - begin_cpu,
            "reason": str(solved),
        }
    setup.simplifySolution(max(MAX_TIME - (time.perf_counter() - begin), 1e-3))  # within the same budget
    path = setup.getSolutionPath()
    waypoints = np.array([[path.getState(i)[k] for k in range(n)] for i in range(path.getStateCount())])
    trajectory = toppra_defaults(robot, waypoints, active)
    seconds, cpu = time.perf_counter() - begin, time.process_time() - begin_cpu
    if trajectory is None:
        return {"success": False, "certified": False, "seconds": seconds, "cpu": cpu, "reason": "toppra failed"}
    full = np.repeat(start[None, :], len(waypoints), axis=0)
    full[:, active] = waypoints
    collisions, clearance = dense_check(compiled, world, trajectory, trajectory.duration, start, active)
    return {
        "success": True,
        "certified": collisions == 0,
        "seconds": seconds,
        "cpu": cpu,
        "path_length": float(np.linalg.norm(np.diff(full, axis=0), axis=1).sum()),
        "duration": float(trajectory.duration),
        "path_topp_duration": float(trajectory.duration),
        "collisions": collisions,
        "clearance": clearance,
    }


def taplan_pipeline(
    world: CollisionWorld, compiled: CompiledScene, robot: taplan.Robot, problem: Any
) -> dict[str, Any]:
    begin, begin_cpu = time.perf_counter(), time.process_time()
    try:
        plan = plan_motion(robot, problem.start, problem.goal, world=world, max_time=MAX_TIME, seed=problem.index)
    except taplan.TaplanError as exc:
        return {
            "success": False,
            "certified": False,
            "seconds": time.perf_counter() - begin,
            "cpu": time.process_time() - begin_cpu,
            "reason": str(exc)[:200],
        }
    seconds, cpu = time.perf_counter() - begin, time.process_time() - begin_cpu
    index = np.arange(robot.nq)
    collisions, clearance = dense_check(
        compiled, world, plan.trajectory, plan.trajectory.duration, problem.start, index
    )
    active = np.flatnonzero(np.ptp(plan.path, axis=0) > 1e-12)
    unsmoothed = toppra_defaults(robot, plan.path[:, active], active)  # the path's quality, timed like the peer's
    return {
        "path_topp_duration": float("nan") if unsmoothed is None else float(unsmoothed.duration),
        "success": True,
        "certified": collisions == 0,
        "seconds": seconds,
        "cpu": cpu,
        "stage": plan.report.stage,
        "notes": list(plan.report.notes),
        "approaches": [(a.end, a.clearance) for a in plan.report.approaches],
        "smoothed": plan.report.smoothed,
        "stage_times": plan.report.stage_times,
        "path_length": plan.report.path_length,
        "duration": plan.report.duration,
        "collisions": collisions,
        "clearance": clearance,
    }


def run(count: int, seed: int, families: tuple[str, ...] = FAMILIES) -> dict[str, Any]:
    logging.getLogger("toppra").setLevel(logging.ERROR)
    from ompl import util as ou

    ou.setLogLevel(ou.LOG_WARN)
    robot = taplan.Robot.teleavatar()
    _warm_up(robot, seed, families)
    suite = problems(count, seed, families)
    rows = []
    for problem in suite:
        world = CollisionWorld(robot, problem.scene)
        compiled = CompiledScene(world)
        row = {"family": problem.family, "kind": problem.kind, "arms": list(problem.arms), "index": problem.index}
        row["taplan"] = taplan_pipeline(world, compiled, robot, problem)
        row["ompl"] = ompl_pipeline(world, compiled, robot, problem.start, problem.goal_q)
        rows.append(row)
    bodies = [b.name for b in CollisionWorld(robot, None).bodies]
    return {
        "rows": rows,
        "count": count,
        "seed": seed,
        "bodies": bodies,
        "models_commit": _models_commit(),
        "load": os.getloadavg()[1],  # [processes] 5-minute load average at the end (2-core machine: shared)
        "families": list(families),
        "max_time": MAX_TIME,
        "tolerance": BUDGET_TOLERANCE,
        "travel": TRAVEL,
    }


def _warm_up(robot: taplan.Robot, seed: int, families: tuple[str, ...]) -> None:
    """Both pipelines on problems of another seed, untimed and unrecorded: one per family for taplan (its straight,
    optimised and sampled routes, joint and pose goals), the first for OMPL."""
    warm = problems(len(families), seed + WARM_UP_SEED, families)
    for problem in warm:
        world = CollisionWorld(robot, problem.scene)
        with contextlib.suppress(taplan.TaplanError):  # a problem without a plan still warmed what it ran
            plan_motion(robot, problem.start, problem.goal, world=world, max_time=MAX_TIME, seed=problem.index)
    first = warm[0]
    world = CollisionWorld(robot, first.scene)
    ompl_pipeline(world, CompiledScene(world), robot, first.start, first.goal_q)


def _models_commit() -> str:
    """The last commit that changed the robot's bodies (``models/teleavatar``, ``taplan/scene/robot_bodies.py``), or ""
    outside git."""
    root = Path(__file__).resolve().parent.parent
    try:
        out = subprocess.run(
            ["git", "-C", str(root), "log", "-1", "--format=%h", "--", "models/teleavatar", BODIES_CODE],
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.SubprocessError):
        return ""
    return out.stdout.strip()


def _solvable(row: dict[str, Any]) -> bool:
    """A certified path is known: either pipeline returned one that passed the dense check."""
    return any(row[key]["success"] and row[key]["certified"] for key in ("taplan", "ompl"))


def _stats(records: list[dict[str, Any]], solvable: list[bool], budget: float) -> list[Any]:
    good = [r for r in records if r["success"]]
    certified = [r for r in good if r["certified"]]
    solved = sum(r["success"] and r["certified"] for r, ok in zip(records, solvable, strict=True) if ok)
    seconds = [r["seconds"] for r in records]
    cpu = [r.get("cpu", np.nan) for r in records]  # results saved before CPU times were recorded have none
    return [
        f"{len(good)}/{len(records)}",
        f"{len(certified)}/{len(records)}",
        f"{solved}/{sum(solvable)}",
        sum(r["collisions"] > 0 for r in good),
        float(np.median(seconds)),
        float(np.percentile(seconds, 95)),
        float(max(seconds)),
        float(np.median(cpu)),
        float(np.percentile(cpu, 95)),
        f"{sum(t <= budget for t in seconds)}/{len(seconds)}",
        float(np.median([r["path_length"] for r in good])) if good else float("nan"),
        float(np.median([r["duration"] for r in good])) if good else float("nan"),
        float(min((r["clearance"] for r in good), default=np.nan)) * 1e3,
    ]


def _failures(rows: list[dict[str, Any]], family: str) -> str:
    """taplan's failures in a family: how many of each reason (its first words)."""
    reasons: dict[str, int] = {}
    for r in rows:
        if r["family"] == family and not r["taplan"]["success"]:
            key = r["taplan"]["reason"].split(" (")[0][:70]
            reasons[key] = reasons.get(key, 0) + 1
        elif r["family"] == family and not r["taplan"]["certified"]:
            reasons["collision in the dense check"] = reasons.get("collision in the dense check", 0) + 1
    return "; ".join(f"{count}× {why}" for why, count in sorted(reasons.items(), key=lambda x: -x[1])) or "none"


def _bodies_line(results: dict[str, Any]) -> str:
    """Which robot bodies the three checks (taplan, the peer, the dense check) used, and the machine's load."""
    bodies = results.get("bodies")
    if not bodies:
        return "Robot bodies: not recorded."
    fingers = [b for b in bodies if "finger" in b]
    commit = results.get("models_commit") or "?"
    load = results.get("load")
    return (
        f"Robot bodies (taplan, the peer's validity check and the dense check alike): the {len(bodies)} capsules of "
        f"`CollisionWorld` at commit {commit} ({', '.join(bodies)}; fingers: {len(fingers)}), with the SRDF's "
        "allowed pairs."
        + ("" if load is None else f" Machine load (5-minute average, 2 cores, shared) at the end: {load:.1f}.")
    )


STAGES = ("validate", "goal_ik", "straight", "optimize", "sample", "smooth", "timing", "verify")


def _stage_table(rows: list[dict[str, Any]], families: list[str]) -> str:
    """Median seconds per stage and family (successful plans), with the problems' indices (their seeds)."""
    header = ["scenes", "problems (seeds)", *STAGES, "total median [s]", "CPU median [s]", "OMPL median [s]"]
    table = []
    for family in (*families, "all"):
        subset = [r for r in rows if family in ("all", r["family"])]
        timed = [r["taplan"]["stage_times"] for r in subset if r["taplan"]["success"]]
        seeds = "all" if family == "all" else ", ".join(str(r["index"]) for r in subset)
        medians = [float(np.median([t[k] for t in timed])) if timed else float("nan") for k in STAGES]
        total = float(np.median([r["taplan"]["seconds"] for r in subset]))
        cpu = float(np.median([r["taplan"].get("cpu", np.nan) for r in subset]))
        peer = float(np.median([r["ompl"]["seconds"] for r in subset]))
        table.append([family, seeds, *medians, total, cpu, peer])
    return _harness.markdown_table(header, table)


def markdown(results: dict[str, Any]) -> str:
    rows = results["rows"]
    budget = results["max_time"] + results["tolerance"]
    header = [
        "scenes",
        "pipeline",
        "success",
        "certified success",
        "solved of solvable",
        "collisions (dense check)",
        "time median [s]",
        "p95 [s]",
        "max [s]",
        "CPU median [s]",
        "CPU p95 [s]",
        f"within {budget:g} s",
        "path length median [rad]",
        "duration median [s]",
        "min clearance [mm]",
    ]
    families = [f for f in FAMILIES if any(r["family"] == f for r in rows)]
    table = []
    for family in (*families, "all"):
        subset = rows if family == "all" else [r for r in rows if r["family"] == family]
        solvable = [_solvable(r) for r in subset]
        for key, label in (("taplan", "taplan plan_motion"), ("ompl", "OMPL RRT-Connect (compiled check)")):
            table.append([family, label, *_stats([r[key] for r in subset], solvable, budget)])
    ours = [r["taplan"] for r in rows]
    peer = [r["ompl"] for r in rows]
    solvable = [_solvable(r) for r in rows]
    solved = sum(r["success"] and r["certified"] for r, ok in zip(ours, solvable, strict=True) if ok)
    rate = solved / max(sum(solvable), 1)
    collisions = sum(r["collisions"] > 0 for r in ours if r["success"])
    late = sum(r["seconds"] > budget for r in ours)
    t_ours = float(np.median([r["seconds"] for r in ours]))
    t_peer = float(np.median([r["seconds"] for r in peer]))
    both = [(a, b) for a, b in zip(ours, peer, strict=True) if a["certified"] and b["certified"]] if rows else []
    d_ours = float(np.median([a["duration"] for a, _ in both])) if both else float("nan")
    d_peer = float(np.median([b["duration"] for _, b in both])) if both else float("nan")
    stages = [r["taplan"].get("stage", "failed") for r in rows]
    smoothed = sum(bool(r["taplan"].get("smoothed")) for r in rows)
    bent = sum(bool(r["taplan"].get("approaches")) for r in rows)
    stage_line = ", ".join(f"{s} {stages.count(s)}" for s in ("straight", "optimization", "rrt-connect", "failed"))
    p95_ours = float(np.percentile([r["seconds"] for r in ours], 95))
    c_ours = float(np.median([r.get("cpu", np.nan) for r in ours]))
    c_p95 = float(np.percentile([r.get("cpu", np.nan) for r in ours], 95))
    c_peer = float(np.median([r.get("cpu", np.nan) for r in peer]))
    goals = [
        f"solved >= 99.5 % of the solvable problems: {solved}/{sum(solvable)} = {100 * rate:.1f} % "
        f"({'met' if rate >= 0.995 else 'NOT met'})",
        f"median planning time <= 30 ms: {t_ours * 1e3:.0f} ms ({'met' if t_ours <= 0.03 else 'NOT met'}); "
        f"p95 <= 150 ms: {p95_ours * 1e3:.0f} ms ({'met' if p95_ours <= 0.15 else 'NOT met'}); "
        f"<= 1/10 of OMPL's median: {t_ours / t_peer:.2f}x ({'met' if t_ours <= t_peer / 10 else 'NOT met'})",
        f"0 collisions in the independent dense check: {collisions} ({'met' if collisions == 0 else 'NOT met'})",
        f"every call within max_time + {results['tolerance']:g} s: {len(ours) - late}/{len(ours)} "
        f"({'met' if late == 0 else 'NOT met'})",
        f"median planning time vs the fair OMPL peer's: {t_ours:.3f} s vs {t_peer:.3f} s = {t_ours / t_peer:.2f}x",
        f"in CPU time (the machine is shared): taplan median {c_ours * 1e3:.0f} ms, p95 {c_p95 * 1e3:.0f} ms; OMPL "
        f"median {c_peer * 1e3:.0f} ms; ratio {c_ours / c_peer:.2f}x",
        f"median duration (problems both solved, certified): {d_ours:.2f} s vs {d_peer:.2f} s",
    ]
    return "\n".join(
        [
            "## Motion planning in scenes (taplan.planning vs a fair OMPL peer)",
            "",
            f"{len(rows)} seeded problems (`benchmarks/_scenes.py`, seed {results['seed']}): families "
            f"{', '.join(families)}; joint and pose goals, one and both arms, half of them with the straight "
            f"joint-space segment blocked. {results['max_time']:g} s budget per planner. taplan: `plan_motion` "
            "(goal IK, certified path, jerk-limited timing, verification). OMPL: RRT-Connect with a compiled "
            "validity check (pinocchio + coal on the same bodies and pairs, `benchmarks/_peer.py`), a motion-check "
            "resolution that moves no robot point more than 1 cm between checked states (half the thinnest "
            "obstacle), `simplifySolution`, toppra with default gridpoints; pose goals get the goal configuration "
            "(the peer is spared the IK). Times are per call after an untimed warm-up on problems of another seed "
            "(one per family for taplan, one for OMPL). Both certified by the same independent dense check "
            f"(pinocchio + coal distances, {results['travel'] * 1e3:g} mm of link-point travel between samples). "
            "Solvable: a certified trajectory was found by either.",
            "",
            _bodies_line(results),
            "",
            _harness.markdown_table(header, table),
            "",
            f"taplan's paths came from: {stage_line} (rrt-connect paths smoothed: {smoothed}; plans with a bent "
            f"end, start or goal inside the margin: {bent}).",
            "",
            "taplan's failures per family: " + "; ".join(f"**{f}**: {_failures(rows, f)}" for f in families),
            "",
            "Where taplan's time goes, per family (median seconds of each stage of `plan_motion` over the family's "
            "problems, `PlanReport.stage_times`; problem k is planned with `seed=k`, the suite's seed is above):",
            "",
            _stage_table(rows, families),
            "",
            "Goals:",
            "",
            *[f"- {g}" for g in goals],
        ]
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problems", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true", help="20 problems")
    parser.add_argument("--families", default=",".join(FAMILIES), help="comma-separated, of " + ",".join(FAMILIES))
    parser.add_argument("--no-save", action="store_true")
    args = parser.parse_args(argv)
    families = tuple(f for f in args.families.split(",") if f)
    unknown = sorted(set(families) - set(FAMILIES))
    if unknown or not families:
        parser.error(f"--families: unknown {unknown or 'empty'}; valid: {', '.join(FAMILIES)}")
    results = run(20 if args.quick else args.problems, args.seed, families)
    results["quick"] = args.quick
    text = markdown(results)
    print(text)
    if not args.no_save:
        _harness.save("planning", results, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
