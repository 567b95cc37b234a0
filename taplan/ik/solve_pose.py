"""Converge-to-pose: iterate the QP (Levenberg-Marquardt steps within the joint limits) until the targets are met."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from taplan.errors import InvalidInputError, UnknownNameError
from taplan.ik._kinematics import Kinematics
from taplan.ik._targets import as_transform
from taplan.ik.limits import CollisionLimit, PositionLimit, VelocityLimit
from taplan.ik.limits.limit import BoxLimit, RowLimit
from taplan.ik.problem import ProblemBuilder, project
from taplan.ik.solvers import QPSolver, get_solver
from taplan.ik.tasks import FrameTask, PostureTask
from taplan.ik.tasks.task import Task
from taplan.limits import JointLimits
from taplan.robot import Robot

__all__ = ["IKResult", "solve_pose"]


@dataclass
class IKResult:
    """Outcome of :func:`solve_pose`.

    Attributes:
        q: Best configuration found [rad] (nq,), within the position limits.
        success: Every target met within the tolerance (never True otherwise).
        position_error: Per frame, distance to the target position [m].
        orientation_error: Per frame, rotation angle to the target orientation [rad].
        iterations: QP iterations used in total (over all restarts).
        restarts: Random restarts used.
    """

    q: np.ndarray
    success: bool
    position_error: dict[str, float] = field(default_factory=dict)
    orientation_error: dict[str, float] = field(default_factory=dict)
    iterations: int = 0
    restarts: int = 0


def solve_pose(
    robot: Robot,
    targets: Mapping[str, Any],
    q0: npt.ArrayLike | None = None,
    *,
    limits: JointLimits | None = None,
    tolerance: tuple[float, float] = (1e-3, 1e-2),
    max_iterations: int = 100,
    max_step: float = 1.0,
    posture_cost: float = 1e-3,
    restarts: int = 10,
    collision: bool = False,
    solver: str | QPSolver = "proxqp",
    seed: int = 0,
    lm_damping: float = 1e-3,
) -> IKResult:
    """Find a configuration that puts each frame at its target pose.

    Gauss-Newton steps with Levenberg-Marquardt damping proportional to the squared error, each a QP that keeps the
    configuration within the position limits (and optionally the arms apart) and moves each joint by at most
    ``max_step``. When an attempt stalls or runs out of iterations, it restarts from a random configuration within
    the limits (seeded), up to ``restarts`` times. Joints that no target depends on stay near ``q0`` (posture task).

    Args:
        robot: The robot.
        targets: ``{frame: pose}``, poses ``T_root_frame`` as 4x4, ``(position, quaternion_xyzw)`` or (7,).
        q0: Initial configuration [rad] (nq,); default ``robot.home``. Clipped into the limits.
        limits: Joint limits (position bounds used); default ``robot.planning_limits``.
        tolerance: (position [m], orientation [rad]) that counts as reached.
        max_iterations: QP iterations per attempt.
        max_step: Largest joint change per iteration [rad].
        posture_cost: Cost per [rad] toward ``q0``.
        restarts: Random restarts after a failed attempt.
        collision: Keep the arms' capsules apart (dual-arm robots).
        solver: QP backend.
        seed: Seed of the restarts' random configurations.
        lm_damping: Levenberg-Marquardt damping per squared error ([m²] + [rad²]).

    Returns:
        The result; ``success`` is True only if every error is within ``tolerance``.

    Raises:
        UnknownNameError: an unknown frame.
        InvalidInputError: malformed targets, q0 or tolerance.
    """
    if not isinstance(targets, Mapping) or not targets:
        raise InvalidInputError("targets", targets, "a non-empty mapping {frame name: pose}")
    limits = robot.planning_limits if limits is None else limits
    if not isinstance(limits, JointLimits) or limits.names != robot.joint_names:
        raise InvalidInputError("limits", limits, "JointLimits over the robot's joints")
    try:
        tol_p, tol_r = (float(t) for t in tolerance)
    except (TypeError, ValueError):
        raise InvalidInputError("tolerance", tolerance, "(position [m], orientation [rad])") from None
    if not (tol_p > 0 and tol_r > 0 and np.isfinite(tol_p) and np.isfinite(tol_r)):
        raise InvalidInputError("tolerance", tolerance, "two finite numbers > 0")
    if int(max_iterations) < 1:
        raise InvalidInputError("max_iterations", max_iterations, "an integer >= 1")
    q_start = robot.home if q0 is None else robot.check_configuration(q0, "q0")
    q_start = np.clip(q_start, limits.lower, limits.upper)

    kin = Kinematics(robot.model)
    tasks: list[FrameTask] = []
    for frame, target in targets.items():
        if not isinstance(frame, str) or not robot.model.existFrame(frame):
            raise UnknownNameError("frame", frame, robot.frame_names)
        task = FrameTask(robot.frame_id(frame), 1.0, 1.0, name=frame)
        task.set_target(as_transform(target, f"targets[{frame!r}]"))
        tasks.append(task)
    posture = PostureTask(robot.nq, posture_cost, q_start)
    lims: list[BoxLimit | RowLimit] = [
        PositionLimit(limits.lower, limits.upper, gain=1.0),
        VelocityLimit(np.full(robot.nq, float(max_step))),
    ]
    if collision and {"left", "right"} <= set(robot.groups):
        lims.append(CollisionLimit(robot.capsule_pairs("left", "right"), robot.model, gain=0.5))
    all_tasks: list[Task] = [*tasks, posture]
    builder = ProblemBuilder(kin, all_tasks, lims, damping=1e-9)
    backend = get_solver(solver) if isinstance(solver, str) else solver
    rng = np.random.default_rng(seed)

    best_q, best_cost, best_err = q_start.copy(), np.inf, ({}, {})
    iterations = 0
    q = q_start.copy()
    for attempt in range(int(restarts) + 1):
        if attempt:
            q = rng.uniform(limits.lower, limits.upper)
        previous = np.inf
        stall = 0
        for step in range(int(max_iterations) + 1):  # the last pass only evaluates the final configuration
            kin.update(q)
            pos, rot, cost = _errors(kin, tasks, tol_p, tol_r)
            if cost < best_cost:
                best_q, best_cost, best_err = q.copy(), cost, (pos, rot)
            if all(pos[f] <= tol_p for f in pos) and all(rot[f] <= tol_r for f in rot):
                return IKResult(q.copy(), True, pos, rot, iterations, attempt)
            stall = stall + 1 if cost > 0.999 * previous else 0
            if stall >= 5 or step == int(max_iterations):
                break
            previous = cost
            builder.damping = 1e-9 + lm_damping * _squared_error(kin, tasks)  # Levenberg-Marquardt
            problem = builder.build(q, 1.0)
            v = project(problem, backend.solve(problem))
            q = q + v
            iterations += 1
    return IKResult(best_q, False, best_err[0], best_err[1], iterations, int(restarts))


def _errors(
    kin: Kinematics, tasks: list[FrameTask], tol_p: float, tol_r: float
) -> tuple[dict[str, float], dict[str, float], float]:
    """Per-frame errors and a scalar progress measure (errors normalised by their tolerances, squared)."""
    pos, rot = {}, {}
    cost = 0.0
    for task in tasks:
        e = task.compute_error(kin)
        p, r = float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:]))
        pos[task.name], rot[task.name] = p, r
        cost += (p / tol_p) ** 2 + (r / tol_r) ** 2
    return pos, rot, float(np.sqrt(cost))


def _squared_error(kin: Kinematics, tasks: list[FrameTask]) -> float:
    return float(sum(np.dot(e, e) for e in (t.compute_error(kin) for t in tasks)))
