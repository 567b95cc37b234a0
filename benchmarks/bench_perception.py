"""Perception: depth-image fusion, distances against occupied voxels (taplan's voxel grid vs coal's octree), and
plan_motion in scenes perceived through the wrist cameras next to the same problems planned with the true primitives.

1. **Integration**: one 640x480 depth image (the table_box family seen by a wrist camera, 2 mm noise, 2 % missing
   pixels) fused by :meth:`taplan.scene.Perception.integrate_depth` (decoding, clearing what it sees through, the
   self-filter of the robot's bodies at that configuration, insertion) at 2 cm; peer: ``coal.makeOctree`` on the
   image's points (an octree built from that image alone; coal's octrees are not updated incrementally, so a fused
   map is a rebuild from every point kept).
2. **Distance**: ``CollisionWorld.distances(q)`` (every body pair, Jacobians) against a 10-primitive scene (a table
   and nine boxes) and against its volume as >= 50,000 occupied 1 cm voxels (:class:`~taplan.scene.Occupancy`);
   peer: coal's capsule-octree distance (``coal.distance`` with an ``OcTree`` of the same voxels) for the same
   bodies, one query per body.
3. **Planning**: the seeded problems of ``benchmarks/_scenes.py``; each scene is perceived from the wrist cameras
   (:func:`taplan.scene.scan.perceive`: 8 next-best-view scan poses per wrist camera chosen among 150 seeded arm
   poses for seeing the workspace and, 10x weighted, the space the arm will fill at the goal; 160x120 depth images
   with noise and missing pixels; 1 cm voxels; unknown space that seen surfaces hide or no image viewed counts as
   occupied, ``unknown="occluded"``; the robot's space at the start is known free) and planned with
   ``plan_motion`` in the perceived scene (plus the objects the hands carry, which are known) and in the true scene.
   Both plans are checked by the same independent dense check against the **true** primitives
   (``benchmarks/_peer.dense_check``).

Run: ``python -m benchmarks.bench_perception [--problems 100] [--quick]``.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import time
from typing import Any

import numpy as np

import taplan
from benchmarks import _harness
from benchmarks._peer import CompiledScene, dense_check
from benchmarks._scenes import make_scene, problems
from taplan.errors import TaplanError
from taplan.planning import plan_motion, plan_seen
from taplan.scene import Box, CollisionWorld, OccupancyGrid, Perception, Scene
from taplan.scene.camera import TELEAVATAR_CAMERAS, WRIST_DEPTH_CAMERA, PinholeCamera, look_at
from taplan.scene.raycast import render_depth
from taplan.scene.scan import RenderedViews, perceive, scan_configurations

MAX_TIME = 10.0  # [s] per plan: plan_motion's default budget (wall clock)
SCAN_CAMERA = PinholeCamera(160, 120, 84.25, 84.25, 80.0, 60.0)  # the wrist camera's field of view, 1/4 size
RESOLUTION = 0.01  # [m] voxel edge: a voxel overstates a surface by up to its edge, starts keep 1.5 cm
SCAN_VIEWS, SCAN_SAMPLES = 8, 150  # views per wrist camera, chosen among this many seeded arm poses
FOCUS_WEIGHT = 10.0  # the task's space weighs this much more than the rest of the workspace in the view choice
FOCUS_STEPS = (1.0,)  # the task's space: the arm's at these fractions of the straight joint segment to the goal


def _cpu_calls(func: Any, repeats: int, warmup: int) -> dict[str, float]:
    """Like :func:`_harness.time_calls`, in CPU time of this process (``time.process_time``) [µs]: on a machine
    shared by other jobs the wall clock measures the queue as much as the work."""
    for _ in range(warmup):
        func()
    samples = np.empty(repeats)
    for i in range(repeats):
        start = time.process_time()
        func()
        samples[i] = time.process_time() - start
    return _harness.summarize(samples * 1e6)


# ------------------------------------------------------------------------------------------------ integration
def bench_integration(robot: taplan.Robot, repeats: int) -> dict[str, Any]:
    import coal

    scene = make_scene("table_box", np.random.default_rng(0))
    perception = Perception(robot)
    T = look_at([0.25, 0.2, 0.15], [0.55, 0.0, -0.45])
    depth = render_depth(WRIST_DEPTH_CAMERA, T, scene, noise=0.002, missing=0.02, rng=1)
    valid = int(np.count_nonzero(np.isfinite(depth)))

    def integrate() -> None:
        perception.integrate_depth(depth, WRIST_DEPTH_CAMERA, T_root_camera=T, q=robot.home)

    ours = _harness.time_calls(integrate, repeats, warmup=3)
    ours_cpu = _cpu_calls(integrate, repeats, warmup=1)
    plain = Perception(robot, unknown="free")  # without the workspace's unknown-space tracking

    def integrate_plain() -> None:
        plain.integrate_depth(depth, WRIST_DEPTH_CAMERA, T_root_camera=T, q=robot.home)

    plain_cpu = _cpu_calls(integrate_plain, repeats, warmup=1)
    points = WRIST_DEPTH_CAMERA.points(depth) @ T[:3, :3].T + T[:3, 3]
    octree = _harness.time_calls(lambda: coal.makeOctree(points, 0.02), max(5, repeats // 3), warmup=2)
    octree_cpu = _cpu_calls(lambda: coal.makeOctree(points, 0.02), max(5, repeats // 3), warmup=1)
    return {
        "pixels": valid,
        "voxels": len(perception.grid),
        "taplan": ours,
        "taplan_cpu": ours_cpu,
        "taplan_no_unknown_cpu": plain_cpu,
        "coal_octree_build": octree,
        "coal_octree_build_cpu": octree_cpu,
    }


# ---------------------------------------------------------------------------------------------------- distance
def _ten_primitives() -> Scene:
    scene = Scene()
    scene.add("table", Box((0.7, 1.3, 0.06)), ([0.55, 0.0, -0.45], [0, 0, 0, 1]))
    rng = np.random.default_rng(3)
    for k in range(9):
        size = rng.uniform(0.08, 0.16, 3)
        xy = rng.uniform([0.3, -0.55], [0.8, 0.55])
        scene.add(f"box{k}", Box(tuple(size)), ([xy[0], xy[1], -0.42 + size[2] / 2], [0, 0, 0, 1]))
    return scene


def _voxelised(scene: Scene, resolution: float) -> Any:
    grid = OccupancyGrid(resolution)
    for obstacle in scene.obstacles.values():
        half = np.asarray(obstacle.shape.size) / 2
        axes = [np.arange(-h, h + 1e-9, resolution / 2) for h in half]
        local = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        grid.insert(local @ obstacle.pose[:3, :3].T + obstacle.pose[:3, 3])
    return grid.snapshot()


def bench_distance(robot: taplan.Robot, repeats: int) -> dict[str, Any]:
    import coal
    import pinocchio as pin

    primitives = _ten_primitives()
    occupancy = _voxelised(primitives, 0.01)
    voxel_scene = Scene()
    voxel_scene.add("perceived", occupancy)
    rng = np.random.default_rng(0)
    limits = robot.planning_limits
    configurations = [limits.lower + rng.uniform(0.1, 0.9, robot.nq) * (limits.upper - limits.lower) for _ in range(50)]
    out: dict[str, Any] = {"voxel_count": len(occupancy), "primitive_count": len(primitives.obstacles)}
    for name, scene in (("primitives", primitives), ("voxels", voxel_scene)):
        world = CollisionWorld(robot, scene)
        counter = iter(range(10**9))

        def query(world: CollisionWorld = world, counter: Any = counter) -> None:
            world.distances(configurations[next(counter) % len(configurations)])

        out[name] = _harness.time_calls(query, repeats, warmup=20)
        out[name + "_cpu"] = _cpu_calls(query, repeats, warmup=5)
    # coal's octree: one capsule-octree distance per moving body (what the occupancy obstacle answers)
    world = CollisionWorld(robot, voxel_scene)
    tree = coal.makeOctree(occupancy.centers(), occupancy.resolution)
    bodies = [b for b in world.bodies if b.joint != 0]
    data = robot.model.createData()
    request = coal.DistanceRequest()
    result = coal.DistanceResult()
    identity = coal.Transform3s()
    shapes = [coal.Capsule(b.radius, float(np.linalg.norm(b.end - b.start))) for b in bodies]
    counter = iter(range(10**9))

    def coal_query() -> None:
        q = configurations[next(counter) % len(configurations)]
        pin.forwardKinematics(robot.model, data, q)
        for body, shape in zip(bodies, shapes, strict=True):
            a, b = data.oMi[body.joint].act(body.start), data.oMi[body.joint].act(body.end)
            axis = b - a
            length = np.linalg.norm(axis)
            z = axis / length if length > 1e-9 else np.array([0.0, 0.0, 1.0])
            x = np.cross([1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0], z)
            x /= np.linalg.norm(x)
            R = np.column_stack([x, np.cross(z, x), z])
            result.clear()
            coal.distance(tree, identity, shape, coal.Transform3s(R, (a + b) / 2), request, result)

    out["coal_octree"] = _harness.time_calls(coal_query, max(10, repeats // 4), warmup=3)
    out["coal_octree_cpu"] = _cpu_calls(coal_query, max(10, repeats // 4), warmup=1)
    out["coal_bodies"] = len(bodies)
    out["ratio"] = out["voxels"]["median_us"] / out["primitives"]["median_us"]
    out["ratio_cpu"] = out["voxels_cpu"]["median_us"] / out["primitives_cpu"]["median_us"]
    return out


# ---------------------------------------------------------------------------------------------------- planning
def _perceived(robot: taplan.Robot, problem: Any) -> tuple[Perception, float]:
    """The scan before planning: next-best views of the workspace (the goal's space weighted), fused."""
    start = time.perf_counter()
    probe = Perception(robot, cameras=dict(TELEAVATAR_CAMERAS), unknown="free", resolution=RESOLUTION)
    views = scan_configurations(
        probe,
        problem.scene,
        count=SCAN_VIEWS,
        samples=SCAN_SAMPLES,
        seed=problem.index,
        focus=[problem.start + a * (problem.goal_q - problem.start) for a in FOCUS_STEPS],
        focus_weight=FOCUS_WEIGHT,
    )
    perception = perceive(robot, problem.scene, views, camera=SCAN_CAMERA, seed=problem.index, resolution=RESOLUTION)
    for name, item in problem.scene.attached.items():  # what the hands carry is known, not seen
        perception.scene.attach(name, item.shape, item.frame, item.pose)
    return perception, time.perf_counter() - start


def _checked(robot: taplan.Robot, plan: Any, truth: tuple[CollisionWorld, Any], problem: Any) -> dict[str, Any]:
    trajectory = plan.trajectory
    index = np.arange(robot.nq)
    collisions, clearance = dense_check(truth[1], truth[0], trajectory, trajectory.duration, problem.start, index)
    return {"collisions": collisions, "true_clearance": clearance}


def _plan(robot: taplan.Robot, world: CollisionWorld, truth: tuple[CollisionWorld, Any], problem: Any) -> dict:
    start, cpu = time.perf_counter(), time.process_time()
    try:
        plan = plan_motion(robot, problem.start, problem.goal, world=world, max_time=MAX_TIME, seed=problem.index)
    except TaplanError as exc:
        return {
            "success": False,
            "time": time.perf_counter() - start,
            "cpu": time.process_time() - cpu,
            "error": type(exc).__name__ + ": " + str(exc),
        }
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    return {"success": True, "time": elapsed, "cpu": cpu, **_checked(robot, plan, truth, problem)}


def _plan_seen(robot: taplan.Robot, perception: Perception, truth: tuple[CollisionWorld, Any], problem: Any) -> dict:
    """The look-where-you-go loop (:func:`taplan.planning.plan_seen`): its final plan's time (``time``, ``cpu``) and
    the loop's total with the views' rendering and fusion (``total``, ``total_cpu``)."""
    capture = RenderedViews(perception, problem.scene, camera=SCAN_CAMERA, seed=problem.index)
    start, cpu = time.perf_counter(), time.process_time()
    try:
        seen = plan_seen(
            robot,
            perception,
            problem.start,
            problem.goal,
            capture,
            camera=SCAN_CAMERA,
            max_time=MAX_TIME,
            seed=problem.index,
            nothing_unshadows=True,  # rendered images: no return means nothing within range
        )
    except TaplanError as exc:
        return {
            "success": False,
            "time": float("nan"),
            "total": time.perf_counter() - start,
            "total_cpu": time.process_time() - cpu,
            "views": capture.count,
            "error": type(exc).__name__ + ": " + str(exc),
        }
    total, total_cpu = time.perf_counter() - start, time.process_time() - cpu
    return {
        "success": True,
        "time": seen.plan_time,
        "cpu": seen.plan_cpu,
        "total": total,
        "total_cpu": total_cpu,
        "views": capture.count,
        "rounds": len(seen.rounds),
        "optimistic": seen.optimistic,
        "certified_clearance": seen.clearance,
        **_checked(robot, seen.plan, truth, problem),
    }


def bench_planning(
    robot: taplan.Robot,
    count: int,
    partial: Any = None,
    shard: tuple[int, int] = (0, 1),
    done: list[dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """Plan every problem in both scenes; ``partial(rows)`` is called after each problem (results so far).
    ``shard`` ``(k, n)``: only the problems whose index is ``k`` modulo ``n`` (runs split over processes);
    ``done``: rows of an earlier, interrupted run (their problems are skipped)."""
    rows: list[dict[str, Any]] = list(done or [])
    skip = {r["index"] for r in rows}
    for problem in problems(count, seed=7)[shard[0] :: shard[1]]:
        if problem.index in skip:
            continue
        truth_world = CollisionWorld(robot, problem.scene)
        truth = (truth_world, CompiledScene(truth_world))
        perception, perceive_time = _perceived(robot, problem)
        scene = perception.scene
        perceived = _plan_seen(robot, perception, truth, problem)
        primitive = _plan(robot, truth_world, truth, problem)
        voxels = len(scene.obstacles["perceived"].shape) if "perceived" in scene.obstacles else 0
        unknown = len(scene.obstacles["perceived_unknown"].shape) if "perceived_unknown" in scene.obstacles else 0
        rows.append(
            {
                "family": problem.family,
                "index": problem.index,
                "kind": problem.kind,
                "voxels": voxels,
                "unknown_voxels": unknown,
                "perceive_time": perceive_time,
                "perceived": perceived,
                "true": primitive,
            }
        )
        logging.info("%d %s: perceived %s, true %s", problem.index, problem.family, perceived, primitive)
        if partial is not None:
            partial(rows)
    return {"problems": rows, "summary": _summary(rows)}


def _summary(rows: list[dict]) -> dict[str, Any]:
    out: dict[str, Any] = {"count": len(rows)}
    for key in ("perceived", "true"):
        ok = [r[key] for r in rows if r[key]["success"]]
        out[key] = {
            "success": len(ok) / len(rows),
            "collisions": sum(int(r["collisions"] > 0) for r in ok),
            "median_time": float(np.median([r["time"] for r in ok])) if ok else float("nan"),
            "p95_time": float(np.percentile([r["time"] for r in ok], 95)) if ok else float("nan"),
        }
    both = [r for r in rows if r["perceived"]["success"] and r["true"]["success"]]
    if both:
        for key, suffix in (("time", ""), ("cpu", "_cpu")):
            out["median_time_ratio_same_problems" + suffix] = float(
                np.median([r["perceived"][key] for r in both]) / np.median([r["true"][key] for r in both])
            )
        if all("total" in r["perceived"] for r in both):  # the look-where-you-go loop: views and fusion included
            for key, suffix in (("total", ""), ("total_cpu", "_cpu")):
                true_key = "time" if key == "total" else "cpu"
                out["median_loop_ratio_same_problems" + suffix] = float(
                    np.median([r["perceived"][key] for r in both]) / np.median([r["true"][true_key] for r in both])
                )
        out["p95_time_same_problems"] = {
            key: float(np.percentile([r[key]["time"] for r in both], 95)) for key in ("perceived", "true")
        }
    families: dict[str, Any] = {}
    for family in dict.fromkeys(r["family"] for r in rows):
        mine = [r for r in rows if r["family"] == family]
        pair = [r for r in mine if r["perceived"]["success"] and r["true"]["success"]]
        families[family] = {
            "count": len(mine),
            **{f"{key}_success": sum(r[key]["success"] for r in mine) for key in ("perceived", "true")},
            **{
                f"{key}_collisions": sum(r[key]["success"] and r[key]["collisions"] > 0 for r in mine)
                for key in ("perceived", "true")
            },
            "median_time_ratio": float(
                np.median([r["perceived"]["time"] for r in pair]) / np.median([r["true"]["time"] for r in pair])
            )
            if pair
            else float("nan"),
        }
    out["families"] = families
    loop = [r["perceived"] for r in rows if "total" in r["perceived"]]
    if loop:
        solved = [p for p in loop if p["success"]]
        out["loop"] = {
            "median_total": float(np.median([p["total"] for p in solved])) if solved else float("nan"),
            "p95_total": float(np.percentile([p["total"] for p in solved], 95)) if solved else float("nan"),
            "median_total_cpu": float(np.median([p["total_cpu"] for p in solved])) if solved else float("nan"),
            "median_views": float(np.median([p["views"] for p in loop])),
            "max_views": int(max(p["views"] for p in loop)),
            "optimistic": sum(bool(p.get("optimistic")) for p in solved),
            "failures": {
                kind: sum(p.get("error", "").startswith(kind) for p in loop if not p["success"])
                for kind in ("UnseenSpaceError", "PlanningError", "CollisionError", "InvalidInputError")
            },
        }
    out["median_perceive_time"] = float(np.median([r["perceive_time"] for r in rows]))
    out["median_voxels"] = float(np.median([r["voxels"] for r in rows]))
    out["median_unknown_voxels"] = float(np.median([r.get("unknown_voxels", 0) for r in rows]))
    return out


# ------------------------------------------------------------------------------------------------------ report
def _ms(stats: dict[str, float], key: str = "median_us") -> str:
    return f"{stats[key] / 1e3:.2f} ms"


def markdown(results: dict[str, Any], note: str) -> str:
    integ, dist = results["integration"], results["distance"]
    lines = [
        "## Perception (depth images, occupied voxels, planning in perceived scenes)",
        "",
        note,
        "",
        "| measurement | wall median | wall p95 | CPU median | target |",
        "|---|---|---|---|---|",
        f"| fuse one 640x480 depth image ({integ['pixels']} valid pixels, 2 cm; decode, clear, self-filter, insert, "
        "known-free/shadowed update of the workspace) "
        f"| {_ms(integ['taplan'])} | {_ms(integ['taplan'], 'p95_us')} | **{_ms(integ['taplan_cpu'])}** | <= 10 ms |",
        f'| the same without unknown-space tracking (`unknown="free"`) | | | {_ms(integ["taplan_no_unknown_cpu"])} | |',
        f"| peer: coal.makeOctree of that image's points | {_ms(integ['coal_octree_build'])} "
        f"| {_ms(integ['coal_octree_build'], 'p95_us')} | {_ms(integ['coal_octree_build_cpu'])} | |",
        f"| CollisionWorld.distances, {dist['primitive_count']} primitives | {_ms(dist['primitives'])} "
        f"| {_ms(dist['primitives'], 'p95_us')} | {_ms(dist['primitives_cpu'])} | |",
        f"| CollisionWorld.distances, {dist['voxel_count']} voxels (the same volume at 1 cm) "
        f"| {_ms(dist['voxels'])} | {_ms(dist['voxels'], 'p95_us')} | {_ms(dist['voxels_cpu'])} "
        f"| <= 3x primitives: **{dist['ratio']:.2f}x** wall, **{dist['ratio_cpu']:.2f}x** CPU |",
        f"| peer: coal capsule-octree distance, {dist['coal_bodies']} moving bodies, same voxels "
        f"| {_ms(dist['coal_octree'])} | {_ms(dist['coal_octree'], 'p95_us')} | {_ms(dist['coal_octree_cpu'])} | |",
    ]
    if "planning" in results:
        s = results["planning"]["summary"]
        p, t = s["perceived"], s["true"]
        lines += [
            "",
            f"plan_motion on {s['count']} seeded problems of `benchmarks/_scenes.py` (budget {MAX_TIME:g} s), each "
            f"scene perceived from the wrist cameras (median {s['median_voxels']:.0f} voxels, perceived in "
            f"{s['median_perceive_time']:.2f} s); every plan checked densely against the **true** primitives:",
            "",
            "| scene planned in | success | plans colliding with the true scene | median time | p95 time |",
            "|---|---|---|---|---|",
            f"| {'perceived voxels' + (', looking where it goes (final plan)' if 'loop' in s else '')} "
            f"| {p['success'] * 100:.1f} % | {p['collisions']} | {p['median_time']:.3f} s "
            f"| {p['p95_time']:.3f} s |",
            f"| true primitives | {t['success'] * 100:.1f} % | {t['collisions']} | {t['median_time']:.3f} s "
            f"| {t['p95_time']:.3f} s |",
            "",
            f"Median time ratio on the problems both solved: "
            f"**{s.get('median_time_ratio_same_problems', float('nan')):.2f}x** wall, "
            f"{s.get('median_time_ratio_same_problems_cpu', float('nan')):.2f}x CPU (target <= 2x).",
        ]
        if "loop" in s:
            loop = s["loop"]
            lines[-3] = lines[-3].replace(
                "| perceived voxels |", "| perceived voxels, look-where-you-go loop (final plan) |"
            )
            lines += [
                "",
                "Look where you go (`taplan.planning.plan_seen`): plan with unseen space free, look (wrist-camera "
                "views chosen from the map, rendered, fused) at the unseen voxels the plan sweeps, re-plan when "
                "something was seen in the way; every returned plan certified against occupied + counted unknown "
                "voxels. "
                f"Whole loop per solved problem (plans, view choice, rendering, fusion, certificate): median "
                f"{loop['median_total']:.2f} s wall ({loop['median_total_cpu']:.2f} s CPU), p95 "
                f"{loop['p95_total']:.2f} s; its ratio to the true-primitive plan on the problems both solved: "
                f"**{s.get('median_loop_ratio_same_problems', float('nan')):.2f}x** wall, "
                f"{s.get('median_loop_ratio_same_problems_cpu', float('nan')):.2f}x CPU (the scan before planning, "
                f"median {s['median_perceive_time']:.2f} s, not included). Views per problem: median "
                f"{loop['median_views']:.0f}, max {loop['max_views']}; {loop['optimistic']} plans were the optimistic "
                f"plan with its swept space seen, the others the conservative fallback. Failures by kind: "
                + ", ".join(f"{k} {v}" for k, v in loop["failures"].items())
                + ".",
            ]
    return "\n".join(lines)


SHARDS = _harness.RESULTS_DIR / "shards"


def _shard(text: str) -> tuple[int, int]:
    k, _, n = text.partition("/")
    if not (k.isdigit() and n.isdigit() and 0 <= int(k) < int(n)):
        raise argparse.ArgumentTypeError(f"expected K/N with 0 <= K < N, received {text!r}")
    return int(k), int(n)


def _shard_path(k: int, n: int) -> Any:
    return SHARDS / f"perception-planning-{k}-of-{n}.json"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--problems", type=int, default=100, help="planning problems (default 100)")
    parser.add_argument("--quick", action="store_true", help="10 problems, fewer repeats")
    parser.add_argument("--skip-planning", action="store_true")
    parser.add_argument(
        "--shard", type=_shard, help="K/N: plan only problems K, K+N, ... (saved to results/shards/ after each)"
    )
    parser.add_argument("--merge", type=int, metavar="N", help="merge the N planning shards into the report")
    parser.add_argument(
        "--keep-measurements",
        action="store_true",
        help="with --merge: take the fusion and distance rows from the saved results (a --skip-planning run)",
    )
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    robot = taplan.Robot.teleavatar()
    if args.shard is not None:  # planning only, one part of the problems
        k, n = args.shard
        SHARDS.mkdir(parents=True, exist_ok=True)

        def save_shard(rows: list[dict[str, Any]]) -> None:
            payload = {"shard": [k, n], "problems": args.problems, "load_average_now": os.getloadavg()[0]}
            _shard_path(k, n).write_text(json.dumps({**payload, "rows": rows}, indent=1, default=float))

        path = _shard_path(k, n)
        done = json.loads(path.read_text())["rows"] if path.is_file() else []  # resume an interrupted run
        bench_planning(robot, args.problems, save_shard, (k, n), done)
        return
    repeats = 10 if args.quick else 40
    results: dict[str, Any] = {"load_average": os.getloadavg()[0], "quick": args.quick}
    if args.merge and args.keep_measurements:
        saved = json.loads((_harness.RESULTS_DIR / "perception.json").read_text())["results"]
        results.update({key: saved[key] for key in ("load_average", "quick", "integration", "distance")})
    else:
        results["integration"] = bench_integration(robot, repeats)
        results["distance"] = bench_distance(robot, repeats * 5)
    note = f"Load average {results['load_average']:.1f} on {os.cpu_count()} cores at the start."

    def partial(rows: list[dict[str, Any]]) -> None:  # results so far, saved after every problem
        results["planning"] = {"problems": rows, "summary": _summary(rows)}
        results["load_average_now"] = os.getloadavg()[0]
        _harness.save("perception", results, markdown(results, note))

    if args.merge:
        rows = []
        for k in range(args.merge):
            rows += json.loads(_shard_path(k, args.merge).read_text())["rows"]
        rows.sort(key=lambda r: r["index"])
        partial(rows)
        note += f" Planning run in {args.merge} processes (`--shard K/{args.merge}`), merged: {len(rows)} problems."
    elif not args.skip_planning:
        results["planning"] = bench_planning(robot, 10 if args.quick else args.problems, partial)
    text = markdown(results, note)
    _harness.save("perception", results, text)
    print(text)


if __name__ == "__main__":
    main()
