"""Look where you go: plans in a perceived scene that stay in space the cameras have seen free.

A :class:`~taplan.scene.Perception` that counts unseen space as an obstacle (``unknown="occluded"`` or
``"occupied"``) refuses every motion through space no image has seen into; with only wrist cameras most goals and
detours lie there. :func:`plan_seen` closes the loop the way a person does, by looking where the arm will go:

1. plan optimistically: :func:`~taplan.planning.plan_motion` against the occupied voxels only (unseen space free);
2. the plan's swept space: the robot's moving bodies along the timed trajectory, widened by the plan's margin and
   one voxel; the counted unknown voxels in it are what must be seen before the plan may run;
3. none: certify the plan (:func:`~taplan.planning.verify_trajectory`) against the occupied AND the counted unknown
   voxels and return it; some: choose wrist-camera views that see them (:func:`~taplan.scene.scan.views_seeing`,
   from the map only, configurations clear of the occupied voxels), ``capture`` each, fuse; when something
   was seen where the plan goes, go to 1, else to 2 with the same plan (a joint goal inside unseen space is looked
   at before the first plan);
4. when two rounds of views in a row resolve nothing or the rounds run out: plan conservatively (unknown counted as
   occupied); when that fails too, :class:`~taplan.errors.UnseenSpaceError` names the unseen space the motion needs.

Every returned plan is certified against the occupied and the counted unknown voxels, so it runs in space the
images saw free (or the robot's own bodies filled at the start and at earlier captures). The view configurations are
chosen clear of the occupied voxels, not of unseen space (a wrist camera that must look at unseen space near the
body often stands in some), so the loop does not mark the robot's space at a view known free: only the images do.

What is simulated: ``capture(frame, q)`` returns the image the camera takes with the arm at ``q``;
:class:`~taplan.scene.scan.RenderedViews` renders it without moving anything, so the motions to the views are
neither planned nor timed, and a view may stand where the robot could not safely go. On the robot, ``capture``
plans the motion to ``q`` in the seen space (``plan_motion`` with ``perception.scene``, which counts unseen space),
executes it, waits for the next depth image of that camera and returns it; when there is no such motion it returns
None and the view is skipped (two rounds without anything resolved end the looking).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from taplan.errors import CollisionError, InvalidInputError, PlanningError, UnseenSpaceError
from taplan.ik import solve_pose
from taplan.planning.ends import DEFAULT_FLOOR, approach_segment
from taplan.planning.motion import DEFAULT_MARGIN, MotionPlan, plan_motion
from taplan.planning.verify import verify_trajectory
from taplan.scene.camera import WRIST_DEPTH_CAMERA, PinholeCamera
from taplan.scene.perception import Perception
from taplan.scene.scan import views_seeing
from taplan.scene.scene import Scene
from taplan.scene.world import CollisionWorld

__all__ = ["plan_seen", "SeenPlan", "LookRound"]

log = logging.getLogger(__name__)

SWEEP_STEP = 0.04  # [rad] largest joint change between the configurations whose bodies make the swept space
MAX_SWEEP = 150  # configurations sampled along a trajectory at most
STALLS = 2  # rounds in a row whose views resolve nothing before the loop stops looking
AIM_DISTANCE = (0.25, 0.6)  # [m] from an aimed view's camera to the unseen point it looks at


@dataclass(frozen=True)
class LookRound:
    """One round of the loop: how many counted unknown voxels the motion needed (``unseen``), the views taken
    (``(camera frame, configuration)``), how many of those voxels the images resolved, the time of the round's
    optimistic plan (0: none was made, e.g. a goal in unseen space looked at first) and of looking (view choice,
    capture, fusion) [s]."""

    unseen: int
    views: tuple[tuple[str, np.ndarray], ...]
    resolved: int
    plan_time: float
    look_time: float


@dataclass(frozen=True)
class SeenPlan:
    """The outcome of :func:`plan_seen`.

    Attributes:
        plan: The plan, certified against the occupied and the counted unknown voxels.
        optimistic: True when it is an optimistic plan whose swept space was seen (False: the conservative fallback,
            planned with unknown space as an obstacle).
        rounds: The rounds of looking, in order.
        plan_time, plan_cpu: The final plan's ``plan_motion`` time [s], wall and CPU of this process.
        total_time: The whole loop: every plan, view choice, capture and fusion, the certificate [s] (wall).
        clearance: The final plan's certified clearance to the occupied and unknown voxels [m].
        margin: The margin the plans kept [m]: ``margin``, or less when the robot stood closer than that to seen
            voxels with no short way out (see :func:`plan_seen`).
    """

    plan: MotionPlan
    optimistic: bool
    rounds: tuple[LookRound, ...] = field(default_factory=tuple)
    plan_time: float = 0.0
    plan_cpu: float = 0.0
    total_time: float = 0.0
    clearance: float = 0.0
    margin: float = DEFAULT_MARGIN

    @property
    def views(self) -> list[tuple[str, np.ndarray]]:
        """Every view taken, in order."""
        return [v for r in self.rounds for v in r.views]


def _optimistic_scene(perception: Perception, out: Scene | None) -> Scene:
    """The perception's scene without its unknown-space obstacle (same shapes, no copy of the voxels)."""
    scene = out if out is not None else Scene(perception.robot)
    source = perception.scene
    for name in [n for n in scene.obstacles if n not in source.obstacles or n == perception.unknown_name]:
        scene.remove(name)
    for name, obstacle in source.obstacles.items():
        if name != perception.unknown_name and (
            name not in scene.obstacles or scene.obstacles[name].shape is not obstacle.shape
        ):
            scene.put(name, obstacle.shape, obstacle.pose)
    for name, item in source.attached.items():
        if name not in scene.attached:
            scene.attach(name, item.shape, item.frame, item.pose, item.touch)
    return scene


def _counted_unknown(perception: Perception) -> np.ndarray:
    """Mask over the grid of the unknown voxels the perception counts as an obstacle."""
    grid = perception.grid
    mask = np.zeros(grid.occupied.shape, dtype=bool)
    mask[grid.unknown_keys("all" if perception.unknown == "occupied" else "occluded")] = True
    return mask


def _swept_unknown(perception: Perception, configurations: np.ndarray, widen: float) -> np.ndarray:
    """Keys of the counted unknown voxels within ``widen`` [m] of the robot's bodies at ``configurations`` (the
    bodies that do not move between them: once)."""
    counted = _counted_unknown(perception)
    segments = [perception.robot_segments(q) for q in configurations]
    starts = np.array([s for s, _, _ in segments])  # (C, B, 3)
    ends = np.array([e for _, e, _ in segments])
    radii = segments[0][2] + widen
    still = np.all(np.abs(starts - starts[:1]).max(axis=2) < 1e-9, axis=0) & np.all(
        np.abs(ends - ends[:1]).max(axis=2) < 1e-9, axis=0
    )
    found = [perception.grid.near_segments(starts[0, still], ends[0, still], radii[still])]
    for k in range(len(configurations)):
        found.append(perception.grid.near_segments(starts[k, ~still], ends[k, ~still], radii[~still]))
    keys = np.unique(np.concatenate(found))
    return keys[counted[keys]]


def _sweep(plan: MotionPlan) -> np.ndarray:
    """Configurations along the timed trajectory, at most ``SWEEP_STEP`` apart in every joint (up to ``MAX_SWEEP``)."""
    trajectory = plan.trajectory
    fine = trajectory(np.linspace(0.0, trajectory.duration, 200))
    travel = float(np.abs(np.diff(fine, axis=0)).max(axis=1).sum()) if len(fine) > 1 else 0.0
    count = int(np.clip(np.ceil(travel / SWEEP_STEP) + 1, 2, MAX_SWEEP))
    return trajectory(np.linspace(0.0, trajectory.duration, count))


def _aimed(
    robot: Any, perception: Perception, points: np.ndarray, base: np.ndarray, count: int, rng: np.random.Generator
) -> list[tuple[str, np.ndarray]]:
    """Configurations whose wrist camera looks at one of ``points`` from ``AIM_DISTANCE`` away (IK of the camera
    frame at a pose looking at the point from a seeded direction on the robot's side, seeded roll): random arm
    draws rarely face a small unseen patch."""
    out = []
    for frame in perception.cameras:
        for _ in range(count):
            target = points[rng.integers(len(points))]
            direction = rng.normal(size=3)
            direction[0] = -abs(direction[0])  # the camera between the robot and the point
            direction /= np.linalg.norm(direction)
            eye = target + rng.uniform(*AIM_DISTANCE) * direction
            z = (target - eye) / np.linalg.norm(target - eye)
            x = np.cross(rng.normal(size=3), z)
            x /= np.linalg.norm(x)
            T = np.eye(4)
            T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
            T[:3, 3] = eye
            result = solve_pose(
                robot,
                {frame: T},
                base,
                tolerance=(0.03, 0.15),
                max_iterations=40,
                restarts=1,
                seed=int(rng.integers(1 << 30)),
            )
            out.append((frame, result.q))  # near enough is a candidate too: the view choice judges what it sees
    return out


def _kept_margin(
    robot: Any,
    world: CollisionWorld,
    ends: list[tuple[str, np.ndarray]],
    active: np.ndarray,
    margin: float,
    floor: float,
) -> float:
    """The margin the plans can keep: ``margin``, or, when an end (the start, where the robot stands; a joint goal)
    is closer than ``margin`` to what ``world`` holds and no short certified segment leads from it to ``margin``
    clearance (plan_motion's bent ends), what such a segment keeps: ``floor + (d - floor) / 2`` for an end ``d``
    from the nearest voxel. Seen voxels overstate a surface by up to a voxel and depth noise adds a few mm, so a
    robot standing 1 cm from a surface may stand in a slot of voxels narrower than twice the margin: the plan then
    keeps what a bent end would keep rather than refusing to move (an end inside ``floor`` is still refused)."""
    limits = robot.planning_limits
    kept = margin
    for end, q in ends:
        d = world.min_distance(q)[0]
        if (
            floor <= d < margin
            and approach_segment(world, q, end, active, limits.lower, limits.upper, margin, floor) is None
        ):
            kept = min(kept, floor + (d - floor) / 2)
    return kept


def _plan_retried(
    robot: Any, q0: np.ndarray, goal: Any, world: CollisionWorld, options: dict[str, Any]
) -> tuple[MotionPlan, float, float]:
    """``plan_motion`` in ``world``; a sampled search that ran out of time is tried once more with the next seed
    (other random choices). Returns the plan and the successful call's wall and CPU time [s]."""
    wall, cpu = time.perf_counter(), time.process_time()
    try:
        plan = plan_motion(robot, q0, goal, world=world, **options)
    except PlanningError as exc:
        if "no collision-free path found within" not in str(exc):
            raise
        wall, cpu = time.perf_counter(), time.process_time()
        plan = plan_motion(robot, q0, goal, world=world, **{**options, "seed": options["seed"] + 1})
    return plan, time.perf_counter() - wall, time.process_time() - cpu


def _describe(perception: Perception, keys: np.ndarray) -> str:
    centres = perception.grid.centers(keys)
    lo, hi = centres.min(axis=0), centres.max(axis=0)
    box = ", ".join(f"{a:+.2f}..{b:+.2f}" for a, b in zip(lo, hi, strict=True))
    return f"{len(keys)} voxels ({perception.grid.resolution * 100:g} cm) in x, y, z = [{box}] m"


def plan_seen(
    robot: Any,
    perception: Perception,
    start: npt.ArrayLike,
    goal: npt.ArrayLike | Mapping[str, Any],
    capture: Callable[[str, np.ndarray], tuple[np.ndarray, PinholeCamera] | None],
    *,
    rounds: int = 10,
    views_per_round: int = 4,
    samples: int = 400,
    aimed: int = 12,
    nothing_unshadows: bool = False,
    camera: PinholeCamera = WRIST_DEPTH_CAMERA,
    margin: float = DEFAULT_MARGIN,
    max_time: float = 10.0,
    seed: int = 0,
    **plan_options: Any,
) -> SeenPlan:
    """Plan from ``start`` to ``goal`` in the space ``perception``'s images saw free, looking where the arm goes.

    Args:
        robot: The robot.
        perception: The perceived scene so far; it must count unseen space (``unknown`` not ``"free"``). The loop
            fuses its new images into it (the robot's space at ``start`` is marked known free).
        start, goal: As for :func:`~taplan.planning.plan_motion` (a configuration, or pose targets).
        capture: ``capture(camera frame, configuration) -> (depth image [m], PinholeCamera)``: the image that
            camera takes with the robot at that configuration (:class:`~taplan.scene.scan.RenderedViews` in a
            simulation; on the robot: move there in the seen space and return the next image), or None when it
            cannot go there.
        rounds: Rounds of looking at most; views_per_round: views per round at most. A round whose views resolve
            nothing (none found, none captured, or none saw what was needed) is retried with fresh candidates,
            twice as many random ones; the second such round in a row ends the looking.
        samples: Random candidate configurations per wrist camera for each round's view choice; aimed: candidates
            per wrist camera aimed at the unseen space by IK. The defaults (400, 12) found views for goals that 150
            and 6 did not (3 of 100 benchmark problems ended in UnseenSpaceError with them), for a loop about 0.8 s
            of CPU longer per problem (6 problems measured).
        camera: The camera model the views are chosen for (its field of view and range).
        nothing_unshadows: A shadowed voxel a view looks at through pixels without any return counts no longer
            (``Perception.integrate_depth``): right for rendered images, where no return means nothing within
            range; a real depth camera also returns nothing from dark, shiny or too-close surfaces.
        margin, max_time, seed, plan_options: Passed to every ``plan_motion`` call (``max_time`` per call; an
            optimistic or conservative plan that finds no path within it is tried once more with the next seed).

    Returns:
        The plan, certified against the occupied and the counted unknown voxels, and how it was found.

    Raises:
        InvalidInputError: ``perception`` does not count unseen space, or a bad option.
        UnseenSpaceError: the motion needs space the views could not see (names it); PlanningError /
            CollisionError: no motion even with unseen space taken as free (occupied space blocks it).
    """
    begin = time.perf_counter()
    if not isinstance(perception, Perception) or perception.unknown == "free":
        raise InvalidInputError(
            "perception", getattr(perception, "unknown", perception), "a Perception with unknown='occluded'/'occupied'"
        )
    if not callable(capture):
        raise InvalidInputError("capture", capture, "a callable (camera frame, configuration) -> (depth, camera)")
    for name, value, least in (
        ("rounds", rounds, 0),
        ("views_per_round", views_per_round, 1),
        ("samples", samples, 1),
        ("aimed", aimed, 0),
    ):
        if not (isinstance(value, int) and not isinstance(value, bool) and value >= least):
            raise InvalidInputError(name, value, f"a whole number >= {least}")
    q0 = robot.check_configuration(start, "start")
    perception.mark_robot_free(q0)  # the robot stands there: nothing else does
    perception.update_scene()
    optimistic_scene = _optimistic_scene(perception, None)
    optimistic = CollisionWorld(robot, optimistic_scene)
    full = CollisionWorld(robot, perception.scene)
    widen = margin + perception.grid.resolution
    floor = plan_options.get("floor", DEFAULT_FLOOR)
    ends = [("start", q0)]
    if isinstance(goal, Mapping):
        active = np.arange(robot.nq)  # the goal configuration is the IK's: any joint may move
    else:
        ends.append(("goal", robot.check_configuration(goal, "goal")))
        active = np.flatnonzero(np.abs(ends[1][1] - q0) > 1e-12)
    margin = _kept_margin(robot, full, ends, active, margin, floor) if active.size else margin
    options = {"margin": margin, "max_time": max_time, "seed": seed, **plan_options}
    rounds_log: list[LookRound] = []
    targets = np.zeros(0, dtype=np.int64)
    if not isinstance(goal, Mapping):  # a goal in unseen space: look at it first
        targets = _swept_unknown(perception, robot.check_configuration(goal, "goal")[None, :], widen)
    plan: MotionPlan | None = None
    plan_time, plan_cpu, stalled = 0.0, 0.0, 0
    for round_ in range(rounds + 1):
        round_plan = 0.0
        if plan is None and not len(targets):
            plan, plan_time, plan_cpu = _plan_retried(robot, q0, goal, optimistic, options)
            round_plan = plan_time
        if plan is not None and not len(targets):
            targets = _swept_unknown(perception, _sweep(plan), widen)
            if not len(targets):
                check = verify_trajectory(full, plan.trajectory, margin / 4)
                if check.collision_free:
                    total = time.perf_counter() - begin
                    return SeenPlan(
                        plan, True, tuple(rounds_log), plan_time, plan_cpu, total, check.min_clearance, margin
                    )
                # unseen space just beyond the sampled sweep: look at what lies around the failing instant
                t = np.clip(check.time + np.linspace(-0.1, 0.1, 9), 0.0, plan.trajectory.duration)
                targets = _swept_unknown(perception, plan.trajectory(t), widen + perception.grid.resolution)
                if not len(targets):
                    break  # close to occupied space seen after it was planned: plan with everything counted
        if round_ == rounds:
            break
        look_clock = time.perf_counter()
        points = perception.grid.centers(targets)
        rng = np.random.default_rng(seed + 7919 * (round_ + 1))
        views = views_seeing(
            perception,
            points,
            base=q0,
            camera=camera,
            count=views_per_round,
            samples=samples * (1 + stalled),  # fresh candidates after a round that resolved nothing: more of them
            seed=seed + 7919 * (round_ + 1),
            clear_of=optimistic,  # not inside what was seen occupied (unseen space may hold the view: see below)
            extra=_aimed(robot, perception, points, q0, aimed, rng),
        )
        taken = []
        for frame, q in views:
            image = capture(frame, q)
            if image is None:
                continue  # the capture could not go there (e.g. no motion to it in the seen space)
            depth, used = image
            # the robot's space at the view is not marked known free: only what the image sees counts (a view may
            # stand in unseen space; in a simulation the arm never went there)
            perception.integrate_depth(
                depth, used, frame=frame, q=q, robot_there=False, nothing_unshadows=nothing_unshadows
            )
            taken.append((frame, q))
        views = taken
        perception.update_scene()
        _optimistic_scene(perception, optimistic_scene)
        resolved = int(np.count_nonzero(~_counted_unknown(perception)[targets]))
        rounds_log.append(LookRound(len(targets), tuple(views), resolved, round_plan, time.perf_counter() - look_clock))
        log.debug(
            "round %d: %d unseen voxels, %d views, %d resolved, plan %.2f s, look %.2f s",
            round_,
            len(targets),
            len(views),
            resolved,
            round_plan,
            rounds_log[-1].look_time,
        )
        stalled = stalled + 1 if resolved == 0 else 0
        if stalled == STALLS:
            break  # fresh candidates saw nothing more either: plan with the unseen space counted
        if perception.grid.occupied[targets].any():
            plan = None  # something stands where the plan goes: plan again around it
        targets = np.zeros(0, dtype=np.int64)
    # the conservative fallback: unseen space is an obstacle
    try:
        plan, plan_time, plan_cpu = _plan_retried(robot, q0, goal, full, options)
    except (PlanningError, CollisionError) as exc:
        unseen = targets if len(targets) else _swept_unknown(perception, q0[None, :], widen)
        where = _describe(perception, unseen) if len(unseen) else "none near the start"
        raise UnseenSpaceError(
            f"the motion needs space no view has seen free after {len(rounds_log)} round(s) of looking "
            f"({sum(len(r.views) for r in rounds_log)} views): {where}; with that space counted as occupied: {exc}",
            perception.grid.centers(unseen),
        ) from exc
    total = time.perf_counter() - begin
    return SeenPlan(
        plan, False, tuple(rounds_log), plan_time, plan_cpu, total, float(plan.report.min_clearance), margin
    )
