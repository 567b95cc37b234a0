"""QP differential inverse kinematics: tasks, limits that always hold, a control-loop stepper, converge-to-pose.

Quick use::

    from taplan.ik import DifferentialIK, solve_pose
    ik = DifferentialIK(robot, dt=0.01)          # both arms, acceleration limits and collision avoidance on
    ik.reset(q)
    out = ik.step({"left_ee": T_left, "right_ee": T_right})   # out.velocity [rad/s], out.q [rad]
    res = solve_pose(robot, {"left_ee": T_left}, q)          # res.q, res.success, res.position_error, ...

Building blocks (``taplan.ik.tasks``, ``taplan.ik.limits``, :func:`build_ik`, :func:`solve_ik`) are public for
custom problems.
"""

from taplan.ik._kinematics import Kinematics
from taplan.ik._targets import as_transform
from taplan.ik.differential_ik import DifferentialIK, IKStep
from taplan.ik.limits import (
    AccelerationLimit,
    BoxLimit,
    CollisionLimit,
    PositionLimit,
    RowLimit,
    StepContext,
    TargetBraking,
    VelocityLimit,
)
from taplan.ik.problem import Problem, ProblemBuilder, build_ik, solve_ik, solve_problem
from taplan.ik.solve_pose import IKResult, solve_pose
from taplan.ik.solvers import DAQPSolver, ProxQPSolver, QPSolver, QPSolversSolver, available_solvers, get_solver
from taplan.ik.tasks import DampingTask, FrameTask, PostureTask, RelativeFrameTask, Task

__all__ = [
    "DifferentialIK",
    "IKStep",
    "solve_pose",
    "IKResult",
    "Kinematics",
    "Problem",
    "ProblemBuilder",
    "build_ik",
    "solve_ik",
    "solve_problem",
    "Task",
    "FrameTask",
    "RelativeFrameTask",
    "PostureTask",
    "DampingTask",
    "BoxLimit",
    "RowLimit",
    "StepContext",
    "VelocityLimit",
    "PositionLimit",
    "AccelerationLimit",
    "TargetBraking",
    "CollisionLimit",
    "QPSolver",
    "ProxQPSolver",
    "DAQPSolver",
    "QPSolversSolver",
    "get_solver",
    "available_solvers",
    "as_transform",
]
