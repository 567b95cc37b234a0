"""The control-loop stepper: one QP per cycle, both arms in one problem, limits that always hold."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from taplan._validation import as_positive, as_vector
from taplan.errors import InvalidInputError, UnknownNameError
from taplan.ik._fused import FusedBuilder
from taplan.ik._kinematics import Kinematics
from taplan.ik._targets import as_transform
from taplan.ik.limits import AccelerationLimit, CollisionLimit, PositionLimit, TargetBraking, VelocityLimit
from taplan.ik.limits.limit import BoxLimit, RowLimit
from taplan.ik.limits.scene_limit import SceneLimit
from taplan.ik.problem import Problem, ProblemBuilder, project
from taplan.ik.solvers import QPSolver, get_solver
from taplan.ik.tasks import FrameTask, PostureTask
from taplan.ik.tasks.task import Task
from taplan.limits import JointLimits
from taplan.robot import Robot
from taplan.scene.scene import Scene
from taplan.scene.world import CollisionWorld

__all__ = ["DifferentialIK", "IKStep"]


class IKStep(NamedTuple):
    """Result of one :meth:`DifferentialIK.step`.

    Attributes:
        velocity: Commanded joint velocity [rad/s], shape (nq,); within the velocity and acceleration limits.
        q: Next configuration ``q + velocity dt`` [rad], shape (nq,).
        min_distance: Lower bound of the smallest arm-arm capsule distance at the step's start [m] (inf without
            collision avoidance).
        iterations: Solver iterations (0 for backends that do not report them).
        problem: The QP that was solved (the stepper's buffers: overwritten at the next step; ``.copy()`` it).
    """

    velocity: np.ndarray
    q: np.ndarray
    min_distance: float
    iterations: int
    problem: Problem


class DifferentialIK:
    """Differential inverse kinematics for control loops.

    Each ``step`` solves one QP for the joint velocity that best moves the task frames toward their targets,
    subject to position, velocity and acceleration limits and arm-arm collision avoidance, and integrates it over
    ``dt``. The velocity box is never empty (bounds are relaxed in the order documented in
    :mod:`taplan.ik.limits.limit`), so a step never fails for infeasibility; the returned velocity always respects
    the velocity and acceleration limits (given a previous velocity within the velocity limits). When the
    objective's unconstrained minimiser already satisfies every limit it is returned without calling the QP backend
    (it is then the QP's exact optimum); ``qp_solves`` and ``steps`` count how often the backend was needed.

    Moving targets: target braking (with acceleration limits) brakes relative to the targets' motion, estimated
    from successive targets (finite difference over ``dt``) or given explicitly as twists to ``step``; so a moving
    target is tracked as closely as without acceleration limits (on 5 cm circles at 0.5 Hz, about 1.3 mm against
    11 mm when braking treated the target as fixed) while a target that stops is still reached without overshoot.
    Estimated velocities only move the braking bounds; explicit twists also feed forward in the objective (the step
    aims at the target's pose one ``dt`` later).

    Known limitations: the acceleration limit wins over the position limit, so a state that already moves too fast
    to stop before a joint bound (e.g. given to ``reset``) overruns it by what braking at ``a`` requires, then comes
    back. A target that stops (or turns) faster than the acceleration limits can follow is overshot by what braking
    at ``a`` from its speed requires.

    Args:
        robot: The robot.
        dt: Control period [s], > 0.
        limits: Joint limits; default ``robot.planning_limits``.
        solver: Backend name (``"proxqp"``, ``"daqp"``, ``"quadprog"``, ``"osqp"``) or a ``QPSolver``.
        frames: Task frames (one :class:`~taplan.ik.tasks.FrameTask` each, cost 1 per [m] and per [rad]).
        posture_cost: Cost per [rad] of the posture task (toward ``posture`` or the ``reset`` configuration).
        damping: Levenberg-Marquardt damping on the step.
        collision: Keep the ``left`` and ``right`` groups' capsules ``collision_margin`` apart (if the robot has
            both groups and capsules).
        acceleration_limit: Bound ``|v - v_prev| <= a dt`` and brake toward position limits and task targets.
        position_cost: Frame tasks' position cost: a number or per root axis (3,).
        orientation_cost: Frame tasks' orientation cost: a number or per root axis (3,).
        collision_margin: Minimum capsule distance [m].
        collision_influence: Distance below which a capsule pair is constrained [m].
        target_braking: With the acceleration limit, brake toward the task target (no overshoot).
        posture: Posture reference [rad] (nq,); default: the configuration given to ``reset``.
        extra_tasks: More tasks (e.g. a :class:`~taplan.ik.tasks.RelativeFrameTask`).
        extra_limits: More limits.
        scene: Obstacles to keep ``collision_margin`` away from (a :class:`~taplan.scene.Scene` or a ready
            :class:`~taplan.scene.CollisionWorld`): adds a :class:`~taplan.ik.limits.SceneLimit` (robot bodies vs
            obstacles and attached objects, the arms vs the torso, chest and head; the generic builder is used).
        fused: Build the default configuration's QP with the fused builder (:mod:`taplan.ik._fused`); False, or any
            extra task or limit, uses the generic :class:`~taplan.ik.problem.ProblemBuilder` (same problem, slower).
        native: With the fused builder, compute each problem with a kernel compiled from CasADi-generated C (once
            per machine, cached; :mod:`taplan.ik._native`) when a C compiler is available and the joints are
            revolute or prismatic; else, or with False, numpy. Same problems either way (``tests/test_ik_native.py``).
    """

    def __init__(
        self,
        robot: Robot,
        dt: float = 0.01,
        limits: JointLimits | None = None,
        solver: str | QPSolver = "proxqp",
        frames: Sequence[str] = ("left_ee", "right_ee"),
        posture_cost: float = 1e-2,
        damping: float = 1e-3,
        collision: bool = True,
        acceleration_limit: bool = True,
        *,
        position_cost: npt.ArrayLike = 1.0,
        orientation_cost: npt.ArrayLike = 1.0,
        collision_margin: float = 0.02,
        collision_influence: float = 0.10,
        target_braking: bool = True,
        posture: npt.ArrayLike | None = None,
        extra_tasks: Sequence[Task] = (),
        extra_limits: Sequence[BoxLimit | RowLimit] = (),
        scene: Scene | CollisionWorld | None = None,
        fused: bool = True,
        native: bool = True,
    ) -> None:
        self.robot = robot
        self.dt = as_positive(dt, "dt")
        self.limits = robot.planning_limits if limits is None else limits
        if not isinstance(self.limits, JointLimits) or self.limits.names != robot.joint_names:
            raise InvalidInputError("limits", self.limits, f"JointLimits over the robot's joints {robot.joint_names}")
        if isinstance(frames, str):
            frames = (frames,)
        self.frames = tuple(frames)
        self.kin = Kinematics(robot.model)
        self.tasks: dict[str, FrameTask] = {
            f: FrameTask(robot.frame_id(f), position_cost, orientation_cost, name=f) for f in self.frames
        }
        self.posture_task = PostureTask(robot.nq, posture_cost)
        self._posture = None if posture is None else robot.check_configuration(posture, "posture")
        lim = self.limits
        self.acceleration_limit = bool(acceleration_limit)
        acc = lim.acceleration if self.acceleration_limit else None
        velocity, position = VelocityLimit(lim.velocity), PositionLimit(lim.lower, lim.upper, acc)
        box: list[BoxLimit | RowLimit] = [velocity, position]
        acceleration = braking = None
        if acc is not None:
            acceleration = AccelerationLimit(acc)
            box.append(acceleration)
            if target_braking:
                braking = TargetBraking(acc)
                box.append(braking)
                for task in self.tasks.values():
                    task.estimate_velocity = True  # brake relative to the targets' motion
        self.collision: CollisionLimit | None = None
        if collision and {"left", "right"} <= set(robot.groups):
            pairs = robot.capsule_pairs("left", "right")
            if pairs:
                self.collision = CollisionLimit(
                    pairs, robot.model, collision_margin, collision_influence, acceleration=acc
                )
                box.append(self.collision)
        self.scene_limit: SceneLimit | None = None
        if scene is not None:
            world = scene if isinstance(scene, CollisionWorld) else CollisionWorld(robot, scene)
            self.scene_limit = SceneLimit(world, collision_margin, collision_influence, acceleration=acc)
            extra_limits = [*extra_limits, self.scene_limit]
        tasks: list[Task] = [*self.tasks.values(), self.posture_task, *extra_tasks]
        self.builder: ProblemBuilder | FusedBuilder
        if fused and not extra_tasks and not extra_limits:
            self.builder = FusedBuilder(
                self.kin,
                list(self.tasks.values()),
                self.posture_task,
                damping,
                velocity,
                position,
                acceleration,
                braking,
                self.collision,
                native=native,
            )
        else:
            self.builder = ProblemBuilder(self.kin, tasks, [*box, *extra_limits], damping)
        self.solver: QPSolver = get_solver(solver) if isinstance(solver, str) else solver
        self._q = np.zeros(robot.nq)
        self._v = np.zeros(robot.nq)
        self._q_next = np.zeros(robot.nq)
        self._initialised = False
        self.steps = 0
        self.qp_solves = 0
        self.reset(robot.home)

    # ------------------------------------------------------------------------------------------------------ state
    @property
    def q(self) -> np.ndarray:
        """Integrated configuration [rad] (nq,) (a copy)."""
        return self._q.copy()

    @property
    def velocity(self) -> np.ndarray:
        """Last commanded velocity [rad/s] (nq,) (a copy): the acceleration limit's state."""
        return self._v.copy()

    def reset(self, q: npt.ArrayLike, velocity: npt.ArrayLike | None = None) -> None:
        """Restart from configuration ``q`` [rad] (nq,) with previous velocity ``velocity`` [rad/s] (default 0).

        Every frame task's target becomes the frame's pose at ``q`` (hold), and the posture reference becomes ``q``
        unless one was given.
        """
        q = self.robot.check_configuration(q, "q")
        v = np.zeros(self.robot.nq) if velocity is None else as_vector(velocity, "velocity", self.robot.nq)
        self._q[:] = q
        self._v[:] = v
        self.kin.update(q)
        for task in self.tasks.values():
            task.set_target_from_configuration(self.kin)
        self.posture_task.set_target(q if self._posture is None else self._posture)
        if self.collision is not None:
            self.collision.reset()
        if self.scene_limit is not None:
            self.scene_limit.reset()
        self._initialised = True

    def set_posture(self, q: npt.ArrayLike) -> None:
        """Posture reference [rad] (nq,), kept across resets."""
        self._posture = self.robot.check_configuration(q, "posture")
        self.posture_task.set_target(self._posture)

    def set_targets(self, targets: Mapping[str, Any]) -> None:
        """Set frame targets without stepping: ``{frame: 4x4 | (position, quaternion_xyzw) | (7,)}``."""
        if not isinstance(targets, Mapping):
            raise InvalidInputError("targets", targets, "a mapping {frame name: pose}")
        tasks = self.tasks
        for frame, target in targets.items():
            task = tasks.get(frame)
            if task is None:
                raise UnknownNameError("task frame", frame, self.frames)
            if type(target) is np.ndarray and target.shape == (4, 4) and target.dtype == np.float64:
                task._set_matrix(target, frame)
            else:
                task._set(as_transform(target, f"targets[{frame!r}]"))

    # ------------------------------------------------------------------------------------------------------- step
    def set_target_velocities(self, velocities: Mapping[str, Any]) -> None:
        """Target twists for the next step only: ``{frame: (6,) [vx, vy, vz [m/s], wx, wy, wz [rad/s]]}`` in root
        axes (the velocity of the target frame's origin and its angular velocity)."""
        if not isinstance(velocities, Mapping):
            raise InvalidInputError("target_velocities", velocities, "a mapping {frame name: twist (6,)}")
        for frame, twist in velocities.items():
            task = self.tasks.get(frame)
            if task is None:
                raise UnknownNameError("task frame", frame, self.frames)
            twist = as_vector(twist, f"target_velocities[{frame!r}]", 6)
            if not np.isfinite(twist).all():
                raise InvalidInputError(f"target_velocities[{frame!r}]", twist, "finite values (no NaN or inf)")
            task.set_target_velocity(twist)

    def step(
        self,
        targets: Mapping[str, Any] | None = None,
        q: npt.ArrayLike | None = None,
        target_velocities: Mapping[str, Any] | None = None,
    ) -> IKStep:
        """One control cycle.

        Args:
            targets: ``{frame: pose}`` with poses ``T_root_frame`` as 4x4, ``(position, quaternion_xyzw)`` or (7,);
                a subset of ``frames`` is fine (the others keep their last target). None keeps all targets.
            q: Measured configuration [rad] (nq,); None uses the stepper's own integrated state.
            target_velocities: Optional ``{frame: twist (6,)}`` of the targets [m/s, rad/s] (root axes), for this
                step only: fed forward (the step aims at ``target + twist dt``) and braked relative to. Frames
                without one use the finite-difference estimate (braking only; see the class docstring).

        Returns:
            The step: velocity [rad/s] and next configuration [rad], plus diagnostics.

        Raises:
            UnknownNameError: a target frame that is not a task frame.
            InvalidInputError: a malformed target or ``q``.
            SolverError: the QP backend failed (with the problem attached).
        """
        if targets:
            self.set_targets(targets)
        if target_velocities:
            self.set_target_velocities(target_velocities)
        q_now = self._q if q is None else self.robot.check_configuration(q, "q")
        problem = self.builder.build(q_now, self.dt, self._v)
        solver = self.solver
        if solver.exact_shortcut and problem.minimiser_is_feasible():
            v = problem.minimiser  # the QP's exact optimum (see taplan.ik.problem.solve_problem)
            iterations = 0
        else:
            v = project(problem, solver.solve(problem))
            iterations = solver.iterations
            self.qp_solves += 1
        self.steps += 1
        self._v[:] = v
        q_next = v * self.dt
        q_next += q_now
        self._q[:] = q_next
        collision = self.collision
        return IKStep(
            v.copy(),
            q_next,
            np.inf if collision is None else collision.min_distance,
            iterations,
            problem,
        )

    def step_errors(self) -> dict[str, tuple[float, float]]:
        """Per task frame ``(position error [m], orientation error [rad])`` to its target at the configuration the
        last step started from (after ``reset``: the reset configuration), read from that step's own kinematics
        (nothing is recomputed: the native kernel's values, or pinocchio's data)."""
        if self.kin.stale:  # the native kernel evaluated the step and pinocchio's data were not needed
            e = self.builder.frame_errors.tolist()
            return {frame: (e[2 * i], e[2 * i + 1]) for i, frame in enumerate(self.frames)}
        oMf = self.kin.data.oMf
        out = {}
        for frame, task in self.tasks.items():
            placement = oMf[task.frame_id]
            e_p = float(np.linalg.norm(placement.translation - task._p_target))
            out[frame] = (e_p, float(np.linalg.norm(pin.log3(placement.rotation @ task._R_target_T))))
        return out

    def task_errors(self, q: npt.ArrayLike | None = None) -> dict[str, tuple[float, float]]:
        """Per task frame ``(position error [m], orientation error [rad])`` at ``q`` (default: current state)."""
        self.kin.update(self._q if q is None else self.robot.check_configuration(q, "q"))
        out = {}
        for frame, task in self.tasks.items():
            e = task.compute_error(self.kin)
            out[frame] = (float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:])))
        return out
