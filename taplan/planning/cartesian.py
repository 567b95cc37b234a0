"""Cartesian straight-line motions: end-effector poses A to B (position linear, orientation slerp) through IK.

Method
------
1. **Line.** For every moving frame, ``p(λ) = p_A + λ (p_B - p_A)`` and ``R(λ) = slerp(R_A, R_B, λ)``
   (``pinocchio.Quaternion.slerp``), one parameter ``λ ∈ [0, 1]`` shared by all moving frames, so two hands move
   together and arrive together.
2. **Samples.** ``λ`` starts on a uniform grid of ``max(ceil(|Δp| / step), ceil(θ / angle_step), 2)`` intervals over
   the moving frames (``step`` [m], ``angle_step`` [rad], ``θ`` the rotation angle A to B): 5 mm and 0.05 rad by
   default, so a 12 cm line has 24 intervals.
3. **IK continuation.** Each sample is solved by damped least-squares Newton iterations on the moving joints,
   warm-started from the previous sample (the minimum-norm step keeps the joint path close to the previous sample,
   i.e. continuous), to ``ik_tolerance`` (a sample where IK stalls within a quarter of ``max_deviation`` is accepted
   too). Position bounds are hard: a joint that would leave its bound is locked and the step re-solved with the
   others. Joints within ``LIMIT_ZONE`` of a bound are pushed inwards in the task's null space (gradient
   projection, ``NULL_SPACE_RATE``). Independent frames (each arm) are solved separately. Joints that no moving
   frame depends on are held exactly (the other arm stays still); another group's end effector whose joints
   overlap the moving ones is held by an IK target at its start pose. (This is the continuation loop of
   :mod:`taplan.ik`'s damped least squares, specialised for following a line: :func:`taplan.ik.solve_pose`'s
   posture term toward the warm start would bias the line.)
4. **Adaptive refinement.** An interval is bisected (up to ``max_bisections`` times) when IK fails at its end, when a
   joint jumps by more than ``max_joint_step`` [rad] across it, or when the midpoint of the joint-space chord leaves
   the line by more than a quarter of ``max_deviation``. A failure that survives the bisections raises
   :class:`~taplan.errors.InfeasibleError` (IK: unreachable or outside the joint limits) or
   :class:`~taplan.errors.TimingError` (discontinuous joint path: a branch flip or a singularity), naming the sample.
5. **Timing.** The joint waypoints of the moving joints are timed by
   :func:`~taplan.timing.jerk_limited.jerk_limited` (default) or :func:`~taplan.timing.toppra_retime.retime` under
   ``limits``; held joints stay constant.
6. **Verification.** The timed trajectory is evaluated at ``check_rate`` (1 kHz) and forward kinematics gives the
   deviation from the line (distance to the segment [m]) and from the slerp orientation at the same ``λ`` [rad]
   (``λ`` from the projection onto the line; for a pure rotation, from the projection onto the rotation axis).
   If it exceeds ``max_deviation`` the sampling is refined (halved step, up to ``refinements`` times), then
   :class:`~taplan.errors.TimingError` is raised.

A joint that starts outside the planning position bounds of ``limits`` (but inside ``robot.limits``) may stay where
it is or move inwards: its bound is widened to its start value (``CartesianResult.widened`` lists such joints).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from taplan._validation import as_positive, as_vector
from taplan.errors import InfeasibleError, InvalidInputError, PlanningError, TimingError, UnknownNameError
from taplan.limits import JointLimits
from taplan.planning.verify import verify_trajectory
from taplan.robot import Robot
from taplan.scene.scene import Scene
from taplan.scene.world import CollisionWorld
from taplan.trajectory import Trajectory, concatenate

__all__ = [
    "CartesianResult",
    "cartesian_line",
    "cartesian_offset",
    "line_deviation",
    "DEFAULT_STEP",
    "DEFAULT_ANGLE_STEP",
    "DEFAULT_MAX_DEVIATION",
]

DEFAULT_STEP = 0.005  # [m] initial sample spacing along the line
DEFAULT_ANGLE_STEP = 0.05  # [rad] initial sample spacing of the rotation
DEFAULT_MAX_DEVIATION = (1e-3, 1e-2)  # ([m], [rad]) allowed deviation of the timed motion from the line
DEFAULT_IK_TOLERANCE = (1e-6, 1e-5)  # ([m], [rad]) IK accuracy at each sample
DEFAULT_MAX_JOINT_STEP = 0.1  # [rad] largest joint change between consecutive samples
DEFAULT_MAX_BISECTIONS = 6  # an interval is split at most this many times (1/64 of the initial spacing)
DEFAULT_REFINEMENTS = 2  # global step halvings when the timed motion deviates too much
CHECK_RATE = 1000.0  # [Hz] rate at which the timed trajectory is checked against the line
IK_MAX_STEP = 0.05  # [rad] largest joint change per IK iteration
IK_ITERATIONS = 50
IK_DAMPING = 1e-10  # damped least squares: constant part of the damping [m²]
IK_LM_DAMPING = 1e-3  # Levenberg-Marquardt part, per squared error
LIMIT_ZONE = 0.15  # fraction of a joint's range near each bound where the null-space avoidance acts
NULL_SPACE_RATE = 1.0  # [rad] null-space motion away from a bound per unit of λ (a whole line), at the bound
BOUND_MARGIN = 2e-3  # [rad] IK samples stay this far inside the position bounds (the spline may bulge between)
AT_BOUND = 1e-3  # [rad] a joint this close to a bound is reported as blocking in an IK failure
_METHODS = ("jerk", "topp")
_MIN_MOTION = 1e-9  # [m] / [rad]: below this a frame's translation / rotation counts as zero


@dataclass(frozen=True)
class CartesianResult:
    """A timed Cartesian straight-line motion and how well it follows the line.

    Attributes:
        trajectory: The timed trajectory over all the robot's joints (held joints constant), from t = 0.
        waypoints: Joint samples [rad] solved by IK along the line(s), shape (K, nq) (legs joined, shared corners
            once).
        path_parameters: Line parameter of each waypoint: ``leg + λ`` with ``λ ∈ [0, 1]``, shape (K,).
        moving_joints: Names of the joints that move (the others are held).
        max_position_deviation: Largest distance of a moving frame from its line over the timed trajectory [m],
            measured with forward kinematics at ``check_rate``.
        max_orientation_deviation: Largest angle between a moving frame's orientation and the slerp orientation at
            the same line parameter [rad].
        position_deviation: Per moving frame, the largest distance from its line [m].
        orientation_deviation: Per moving frame, the largest angle from the slerp orientation [rad].
        endpoint_error: Per moving frame, (position [m], orientation [rad]) error at the end of the trajectory.
        method: ``"jerk"`` or ``"topp"``.
        leg_durations: Duration of each leg [s].
        widened: Joints whose position bound was widened to their start value (see the module notes).
        min_clearance: With a ``scene``: the smallest clearance at the certificate's evaluations [m]; else NaN.
        min_clearance_pair: Where it occurs.
    """

    trajectory: Trajectory
    waypoints: np.ndarray
    path_parameters: np.ndarray
    moving_joints: tuple[str, ...]
    max_position_deviation: float
    max_orientation_deviation: float
    position_deviation: dict[str, float] = field(default_factory=dict)
    orientation_deviation: dict[str, float] = field(default_factory=dict)
    endpoint_error: dict[str, tuple[float, float]] = field(default_factory=dict)
    method: str = "jerk"
    leg_durations: tuple[float, ...] = ()
    widened: tuple[str, ...] = ()
    min_clearance: float = float("nan")
    min_clearance_pair: tuple[str, str] = ("", "")

    @property
    def duration(self) -> float:
        """[s]."""
        return self.trajectory.duration


# ------------------------------------------------------------------------------------------------------- geometry
class _Line:
    """Straight line with slerp orientation between two poses of one frame."""

    def __init__(self, T_start: np.ndarray, T_goal: np.ndarray) -> None:
        self.p0 = T_start[:3, 3].copy()
        self.dp = T_goal[:3, 3] - self.p0
        self.length = float(np.linalg.norm(self.dp))
        self.R0 = T_start[:3, :3].copy()
        self.q0 = pin.Quaternion(self.R0)
        self.q0.normalize()
        self.q1 = pin.Quaternion(T_goal[:3, :3].copy())
        self.q1.normalize()
        self.omega = pin.log3(self.R0.T @ T_goal[:3, :3])  # rotation A -> B in the start frame [rad]
        self.angle = float(np.linalg.norm(self.omega))

    def pose(self, lam: float) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = self.rotation(lam)
        T[:3, 3] = self.p0 + lam * self.dp
        return T

    def rotation(self, lam: float) -> np.ndarray:
        return self.q0.slerp(float(lam), self.q1).toRotationMatrix()

    def deviation(self, p: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Distance to the segment [m], angle to the slerp orientation [rad] and λ, for poses p (k, 3), R (k, 3, 3)."""
        if self.length > _MIN_MOTION:
            lam = np.clip((p - self.p0) @ self.dp / self.length**2, 0.0, 1.0)
        elif self.angle > _MIN_MOTION:
            logs = np.array([pin.log3(self.R0.T @ Rk) for Rk in R])
            lam = np.clip(logs @ self.omega / self.angle**2, 0.0, 1.0)
        else:
            lam = np.zeros(len(p))
        dist = np.linalg.norm(p - (self.p0 + lam[:, None] * self.dp), axis=1)
        angle = np.array([np.linalg.norm(pin.log3(self.rotation(lk).T @ Rk)) for lk, Rk in zip(lam, R, strict=True)])
        return dist, angle, lam


def line_deviation(
    robot: Robot,
    trajectory: Trajectory,
    frame: str,
    T_start: npt.ArrayLike,
    T_goal: npt.ArrayLike,
    *,
    rate: float = CHECK_RATE,
) -> tuple[np.ndarray, np.ndarray]:
    """Deviation of ``frame`` along ``trajectory`` from the straight line ``T_start`` -> ``T_goal``.

    Args:
        robot: The robot (the trajectory's joint names must be the robot's joints).
        trajectory: Timed trajectory over ``robot.joint_names``.
        frame: Frame name.
        T_start: Start pose 4x4 ``T_root_frame``.
        T_goal: Goal pose 4x4.
        rate: Sampling rate [Hz].

    Returns:
        (distance to the segment [m], angle to the slerp orientation at the projected line parameter [rad]), each
        shape (k,) over the samples.
    """
    from taplan.ik._targets import as_transform

    if tuple(trajectory.joint_names) != tuple(robot.joint_names):
        raise InvalidInputError("trajectory", trajectory.joint_names, f"a trajectory over {robot.joint_names}")
    line = _Line(as_transform(T_start, "T_start"), as_transform(T_goal, "T_goal"))
    p, R = _sample_poses(robot, trajectory(trajectory.sample_times(as_positive(rate, "rate"))), robot.frame_id(frame))
    dist, angle, _ = line.deviation(p, R)
    return dist, angle


def _sample_poses(robot: Robot, q: np.ndarray, fid: int) -> tuple[np.ndarray, np.ndarray]:
    return _sample_poses_with(robot, robot.model.createData(), q, fid)


def _components(robot: Robot, frames: list[str], held: Mapping[str, Any]) -> list[tuple[list[str], np.ndarray]]:
    """Split the IK frames into groups with disjoint joint supports (solved independently), with their joints."""
    comps: list[tuple[list[str], set[int]]] = []
    for f in [*frames, *held]:
        support = _support(robot, f)
        merged = [c for c in comps if c[1] & support]
        comps = [c for c in comps if not (c[1] & support)]
        comps.append(([g for c in merged for g in c[0]] + [f], support.union(*(c[1] for c in merged))))
    return [(fs, np.array(sorted(js), dtype=int)) for fs, js in comps]


def _support(robot: Robot, frame: str) -> set[int]:
    """Configuration indices of the joints that move ``frame``."""
    joint = robot.model.frames[robot.frame_id(frame)].parentJoint
    out = set()
    while joint > 0:
        out.add(int(robot.model.joints[joint].idx_q))
        joint = robot.model.parents[joint]
    return out


# --------------------------------------------------------------------------------------------------- validation
def _as_legs(targets: Any, name: str) -> list[Mapping[str, Any]]:
    if isinstance(targets, Mapping):
        legs = [targets]
    elif isinstance(targets, Sequence) and not isinstance(targets, str) and targets:
        legs = list(targets)
    else:
        raise InvalidInputError(name, targets, "a mapping {frame: goal} or a non-empty sequence of such mappings")
    for i, leg in enumerate(legs):
        if not isinstance(leg, Mapping) or not leg:
            raise InvalidInputError(f"{name}[{i}]", leg, "a non-empty mapping {frame: goal}")
    return legs


def _position_limits(robot: Robot, limits: JointLimits, q: np.ndarray) -> tuple[JointLimits, tuple[str, ...]]:
    """Limits whose position bounds include ``q`` (joints out of the planning bounds but within the hardware)."""
    hard = robot.limits
    outside = (q < hard.lower - 1e-9) | (q > hard.upper + 1e-9)
    if np.any(outside):
        j = int(np.argmax(outside))
        raise InvalidInputError(
            "start_q", f"{robot.joint_names[j]} = {q[j]:.6g} rad", f"within [{hard.lower[j]:.6g}, {hard.upper[j]:.6g}]"
        )
    lower = np.minimum(limits.lower, q)
    upper = np.maximum(limits.upper, q)
    moved = (lower < limits.lower) | (upper > limits.upper)
    widened = tuple(n for n, w in zip(limits.names, moved, strict=True) if w)
    if not widened:
        return limits, ()
    return limits.replace(lower=lower, upper=upper), widened


# ------------------------------------------------------------------------------------------------ continuation
@dataclass
class _Leg:
    frames: list[str]
    lines: list[_Line]
    held_targets: dict[str, np.ndarray]
    moving: np.ndarray  # configuration indices that move
    q_start: np.ndarray
    components: list[tuple[list[str], np.ndarray]] = field(default_factory=list)  # independent (frames, joints)


class _Solver:
    """Damped least-squares Newton continuation on the moving joints, with joint-limit avoidance in the null space."""

    def __init__(
        self,
        robot: Robot,
        limits: JointLimits,
        ik_tolerance: tuple[float, float],
        max_joint_step: float,
        max_deviation: tuple[float, float],
        max_bisections: int,
    ) -> None:
        self.robot = robot
        self.limits = limits
        self.ik_tolerance = ik_tolerance
        self.max_joint_step = max_joint_step
        self.max_deviation = max_deviation
        self.max_bisections = max_bisections
        self.data = robot.model.createData()
        # IK keeps BOUND_MARGIN inside the bounds, so the timing spline between samples does not overshoot them
        self.lower = np.asarray(limits.lower, dtype=float) + BOUND_MARGIN
        self.upper = np.asarray(limits.upper, dtype=float) - BOUND_MARGIN
        self.zone = LIMIT_ZONE * (self.upper - self.lower)

    def _errors(
        self, moving: np.ndarray, targets: dict[str, np.ndarray], q: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, list[tuple[str, float, float]]]:
        """Stacked task error (6k,) [m, rad] (world axes), Jacobian (6k, m) on the moving joints, per-frame errors."""
        model, data = self.robot.model, self.data
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        errors, rows, per_frame = [], [], []
        for frame, T in targets.items():
            fid = self.robot.frame_id(frame)
            M = data.oMf[fid]
            e_p = T[:3, 3] - M.translation
            e_r = M.rotation @ pin.log3(M.rotation.T @ T[:3, :3])
            errors.append(np.concatenate([e_p, e_r]))
            J = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
            rows.append(J[:, moving])
            per_frame.append((frame, float(np.linalg.norm(e_p)), float(np.linalg.norm(e_r))))
        return np.concatenate(errors), np.vstack(rows), per_frame

    def _avoidance(self, q: np.ndarray) -> np.ndarray:
        """Joint-space direction away from nearby position bounds, in [0, 1] per joint (0 outside the zone)."""
        to_lower, to_upper = q - self.lower, self.upper - q
        push_up = np.clip((self.zone - to_lower) / self.zone, 0.0, 1.0)
        push_down = np.clip((self.zone - to_upper) / self.zone, 0.0, 1.0)
        return push_up - push_down

    def solve(self, leg: _Leg, lam: float, q_warm: np.ndarray, dlam: float) -> tuple[np.ndarray | None, str]:
        """IK of the line poses at ``λ`` from ``q_warm`` (at ``λ - dlam``), each independent component on its own."""
        targets: dict[str, np.ndarray] = {f: line.pose(lam) for f, line in zip(leg.frames, leg.lines, strict=True)}
        targets.update(leg.held_targets)
        q = q_warm.copy()
        for frames, moving in leg.components:
            q, why = self._solve_component({f: targets[f] for f in frames}, moving, q, NULL_SPACE_RATE * dlam)
            if why:
                return None, why
        return q, ""

    def _solve_component(
        self, targets: dict[str, np.ndarray], m: np.ndarray, q_warm: np.ndarray, null_step: float
    ) -> tuple[np.ndarray, str]:
        q = q_warm.copy()
        lo, hi = self.lower[m], self.upper[m]
        lo_q, hi_q = np.minimum(lo, q[m]), np.maximum(hi, q[m])  # a joint outside its bound may only move inwards
        tol_p, tol_r = self.ik_tolerance
        best: tuple[float, np.ndarray, list] | None = None
        for iteration in range(IK_ITERATIONS):
            e, J, per_frame = self._errors(m, targets, q)
            score = max(max(p / tol_p, r / tol_r) for _, p, r in per_frame)
            if best is None or score < best[0]:
                best = (score, q.copy(), per_frame)
            if score <= 1.0:
                return q, ""
            free = np.ones(len(m), dtype=bool)
            secondary = null_step * self._avoidance(q)[m] if iteration == 0 else np.zeros(len(m))
            for _ in range(len(m)):
                Jf = J[:, free]
                mu = IK_DAMPING + IK_LM_DAMPING * float(e @ e)
                pinv = Jf.T @ np.linalg.inv(Jf @ Jf.T + mu * np.eye(len(e)))
                dq = np.zeros(len(m))
                dq[free] = pinv @ e + secondary[free] - pinv @ (Jf @ secondary[free])
                biggest = float(np.max(np.abs(dq)))
                if biggest > IK_MAX_STEP:
                    dq *= IK_MAX_STEP / biggest
                new = q[m] + dq
                out = free & ((new < lo_q - 1e-12) | (new > hi_q + 1e-12))
                if not np.any(out):
                    break
                free &= ~out  # lock the joints that would leave their bounds, re-solve with the others
                if not np.any(free):
                    break
            q[m] = np.clip(q[m] + dq, lo_q, hi_q)
            lo_q, hi_q = np.minimum(lo_q, q[m]), np.maximum(hi_q, q[m])
        assert best is not None
        score, q_best, per_frame = best
        close = all(p <= 0.25 * self.max_deviation[0] and r <= 0.25 * self.max_deviation[1] for _, p, r in per_frame)
        if close:
            return q_best, ""
        frame, p, r = max(per_frame, key=lambda x: max(x[1] / tol_p, x[2] / tol_r))
        at_bound = [
            self.robot.joint_names[j]
            for j, v in zip(m, q_best[m], strict=True)
            if v <= self.lower[j] + AT_BOUND or v >= self.upper[j] - AT_BOUND
        ]
        bound = f"; joints at their position bounds: {at_bound}" if at_bound else ""
        return q_warm, (
            f"IK did not converge: {frame} stays {p * 1e3:.3g} mm and {r:.3g} rad from the line "
            f"(unreachable, singular, or blocked by the joint limits{bound})"
        )

    def chord_deviation(self, leg: _Leg, qa: np.ndarray, qb: np.ndarray) -> float:
        """Largest deviation (relative to the allowed one) of the joint-space chord midpoint from the lines."""
        qm = 0.5 * (qa + qb)
        pin.forwardKinematics(self.robot.model, self.data, qm)
        worst = 0.0
        for frame, line in zip(leg.frames, leg.lines, strict=True):
            M = pin.updateFramePlacement(self.robot.model, self.data, self.robot.frame_id(frame))
            dist, angle, _ = line.deviation(M.translation[None, :], M.rotation[None, :, :])
            worst = max(worst, float(dist[0]) / self.max_deviation[0], float(angle[0]) / self.max_deviation[1])
        return worst

    def run(self, leg: _Leg, lams: np.ndarray, leg_index: int) -> tuple[np.ndarray, np.ndarray]:
        """Joint samples (K, nq) and their λ (K,) along one leg."""
        qs, out_lams = [leg.q_start.copy()], [0.0]
        pending = list(lams[1:][::-1])  # stack, next target last
        min_dlam = float(np.min(np.diff(lams))) / 2**self.max_bisections
        while pending:
            lam = pending[-1]
            lam_prev, q_prev = out_lams[-1], qs[-1]
            can_split = lam - lam_prev > min_dlam * (1 + 1e-9)
            q, why = self.solve(leg, lam, q_prev, lam - lam_prev)
            if q is not None:
                jump = np.abs(q - q_prev)
                if float(jump.max()) > self.max_joint_step:
                    j = int(np.argmax(jump))
                    why = (
                        f"discontinuous joint path: {self.robot.joint_names[j]} jumps {jump[j]:.3g} rad "
                        f"(> max_joint_step {self.max_joint_step:g} rad) between λ={lam_prev:.6g} and λ={lam:.6g} "
                        "(a branch change or a singularity)"
                    )
                    if not can_split:
                        raise TimingError(f"cartesian leg {leg_index}, sample {len(qs)}: {why}")
                    q = None
                elif can_split and self.chord_deviation(leg, q_prev, q) > 0.25:
                    pending.append(0.5 * (lam_prev + lam))
                    continue
            if q is None:
                if not can_split:
                    raise InfeasibleError(f"cartesian leg {leg_index}, sample {len(qs)} at λ={lam:.6g}: {why}")
                pending.append(0.5 * (lam_prev + lam))
                continue
            pending.pop()
            qs.append(q)
            out_lams.append(lam)
        return np.array(qs), np.array(out_lams)


# ------------------------------------------------------------------------------------------------------- public
def cartesian_line(
    robot: Robot,
    start_q: npt.ArrayLike,
    targets: Mapping[str, Any] | Sequence[Mapping[str, Any]],
    *,
    limits: JointLimits | None = None,
    method: str = "jerk",
    step: float = DEFAULT_STEP,
    angle_step: float = DEFAULT_ANGLE_STEP,
    samples: int | None = None,
    max_deviation: tuple[float, float] = DEFAULT_MAX_DEVIATION,
    ik_tolerance: tuple[float, float] = DEFAULT_IK_TOLERANCE,
    max_joint_step: float = DEFAULT_MAX_JOINT_STEP,
    max_bisections: int = DEFAULT_MAX_BISECTIONS,
    refinements: int = DEFAULT_REFINEMENTS,
    check_rate: float = CHECK_RATE,
    scene: Scene | CollisionWorld | None = None,
    clearance: float = 0.0,
) -> CartesianResult:
    """Move end-effector frames along straight lines (position linear, orientation slerp), timed within the limits.

    Args:
        robot: The robot.
        start_q: Start configuration [rad], shape (nq,), within ``robot.limits``.
        targets: ``{frame: goal pose}`` with poses ``T_root_frame`` (4x4, ``(position, quaternion_xyzw)`` or (7,)),
            one or several frames moving at once along one shared line parameter; or a sequence of such mappings,
            one per leg (the motion stops at each corner). Frames of the robot's groups that are not targets are
            held.
        limits: Joint limits (positions, velocity, acceleration, jerk); default ``robot.planning_limits``.
        method: ``"jerk"`` (jerk-limited, :func:`~taplan.timing.jerk_limited.jerk_limited`) or ``"topp"``
            (TOPP-RA, :func:`~taplan.timing.toppra_retime.retime`).
        step: Initial sample spacing along the line [m].
        angle_step: Initial sample spacing of the rotation [rad].
        samples: Initial number of intervals per leg (overrides ``step`` and ``angle_step``).
        max_deviation: Allowed (position [m], orientation [rad]) deviation of the timed motion from the line.
        ik_tolerance: IK accuracy at each sample, (position [m], orientation [rad]).
        max_joint_step: Largest joint change between consecutive samples [rad]; larger jumps are bisected, then
            rejected as discontinuities.
        max_bisections: How many times an interval may be halved.
        refinements: How many times the whole sampling may be halved when the timed motion deviates too much.
        check_rate: Rate at which the timed trajectory is checked against the line [Hz].
        scene: Obstacles (a :class:`~taplan.scene.Scene` or a ready :class:`~taplan.scene.CollisionWorld`): the
            start must keep ``clearance`` and the whole timed motion is certified to keep more than ``clearance``
            [m] (conservative advancement, :func:`~taplan.planning.verify.verify_trajectory`); None: not checked.
        clearance: Required clearance [m] from obstacles and between robot bodies when ``scene`` is given.

    Returns:
        The timed motion, its joint waypoints and its measured deviation from the line.

    Raises:
        InvalidInputError: malformed inputs. UnknownNameError: unknown frame or method.
        InfeasibleError: a sample is unreachable (the message names the leg, the sample and the frame).
        TimingError: a discontinuous joint path, no feasible timing, or a deviation above ``max_deviation``.
        CollisionError: the start collides (names the pair and the depth in mm).
        PlanningError: the line comes closer than ``clearance`` to an obstacle or to the robot itself (names the
            pair, the distance in mm and the time); :func:`~taplan.planning.plan_motion` finds a way around.
    """
    q0 = robot.check_configuration(start_q, "start_q")
    world = _collision_world(robot, scene)
    if not (isinstance(clearance, (int, float)) and np.isfinite(clearance) and clearance >= 0):
        raise InvalidInputError("clearance", clearance, "a clearance >= 0 [m]")
    if world is not None:
        world.check_configuration(q0, "start_q", margin=float(clearance))
    limits = robot.planning_limits if limits is None else limits
    if not isinstance(limits, JointLimits) or tuple(limits.names) != tuple(robot.joint_names):
        raise InvalidInputError("limits", limits, "JointLimits over the robot's joints, in model order")
    if method not in _METHODS:
        raise UnknownNameError("method", method, _METHODS)
    step = as_positive(step, "step")
    angle_step = as_positive(angle_step, "angle_step")
    if samples is not None and (int(samples) != samples or int(samples) < 1):
        raise InvalidInputError("samples", samples, "an integer >= 1 or None")
    dev = _pair(max_deviation, "max_deviation")
    ik_tol = _pair(ik_tolerance, "ik_tolerance")
    max_joint_step = as_positive(max_joint_step, "max_joint_step")
    if int(max_bisections) < 0 or int(refinements) < 0:
        raise InvalidInputError("max_bisections/refinements", (max_bisections, refinements), "integers >= 0")
    check_rate = as_positive(check_rate, "check_rate")
    legs = _as_legs(targets, "targets")
    limits, widened = _position_limits(robot, limits, q0)
    solver = _Solver(robot, limits, ik_tol, max_joint_step, dev, int(max_bisections))

    last_error: TimingError | None = None
    for round_ in range(int(refinements) + 1):
        scale = 0.5**round_
        try:
            result = _plan(
                robot, q0, legs, limits, method, solver, step * scale, angle_step * scale,
                None if samples is None else int(samples) * 2**round_, check_rate, widened,
            )  # fmt: skip
        except _DeviationError as exc:
            last_error = exc
            continue
        return result if world is None else _certified(world, result, q0, float(clearance))
    assert last_error is not None
    raise TimingError(f"{last_error} (after {refinements} refinements of the sampling)")


class _DeviationError(TimingError):
    pass


def _collision_world(robot: Robot, scene: Scene | CollisionWorld | None) -> CollisionWorld | None:
    if scene is None or isinstance(scene, CollisionWorld):
        return scene
    if isinstance(scene, Scene):
        return CollisionWorld(robot, scene)
    raise InvalidInputError("scene", type(scene).__name__, "a taplan.scene.Scene, a CollisionWorld or None")


def _certified(world: CollisionWorld, result: CartesianResult, q0: np.ndarray, clearance: float) -> CartesianResult:
    verification = verify_trajectory(world, result.trajectory, floor=clearance, hold=q0)
    if not verification.collision_free:
        a, b = verification.pair
        raise PlanningError(
            f"the straight line comes within {verification.min_clearance * 1e3:.1f} mm of collision ({a} / {b} at "
            f"t = {verification.time:.3f} s; {clearance * 1e3:.1f} mm required): use plan_motion to go around"
        )
    return replace(result, min_clearance=verification.min_clearance, min_clearance_pair=verification.pair)


def _pair(value: Any, name: str) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in value)
    except (TypeError, ValueError):
        raise InvalidInputError(name, value, "(position [m], orientation [rad])") from None
    if not (np.isfinite(a) and np.isfinite(b) and a > 0 and b > 0):
        raise InvalidInputError(name, value, "two finite numbers > 0")
    return a, b


def _plan(
    robot: Robot,
    q0: np.ndarray,
    legs: list[Mapping[str, Any]],
    limits: JointLimits,
    method: str,
    solver: _Solver,
    step: float,
    angle_step: float,
    samples: int | None,
    check_rate: float,
    widened: tuple[str, ...],
) -> CartesianResult:
    from taplan.ik._targets import as_transform

    group_frames = [g.ee_frame for g in robot.groups.values()]
    q_start = q0.copy()
    built: list[_Leg] = []
    all_q, all_lam = [], []
    for i, leg_targets in enumerate(legs):
        frames = list(leg_targets)
        for f in frames:
            robot.frame_id(f)
        poses = robot.frame_poses(q_start, frames + [f for f in group_frames if f not in frames])
        lines = [_Line(poses[f], as_transform(leg_targets[f], f"targets[{i}][{f!r}]")) for f in frames]
        moving = sorted(set().union(*(_support(robot, f) for f in frames)))
        held = {f: poses[f] for f in group_frames if f not in frames and _support(robot, f) & set(moving)}
        leg = _Leg(frames, lines, held, np.array(moving, dtype=int), q_start.copy(), _components(robot, frames, held))
        if samples is not None:
            count = samples
        else:
            count = max(2, *(int(np.ceil(max(ln.length / step, ln.angle / angle_step) - 1e-9)) for ln in lines))
        if all(ln.length <= _MIN_MOTION and ln.angle <= _MIN_MOTION for ln in lines):
            raise InvalidInputError(f"targets[{i}]", "goal poses equal to the start poses", "a motion")
        q, lam = solver.run(leg, np.linspace(0.0, 1.0, count + 1), i)
        built.append(leg)
        all_q.append(q)
        all_lam.append(lam + i)
        q_start = q[-1]

    trajs, durations = [], []
    moving_all = sorted(set().union(*(set(leg.moving.tolist()) for leg in built)))
    for i, (leg, q) in enumerate(zip(built, all_q, strict=True)):
        trajs.append(_time_leg(robot, q, leg.moving, limits, method, i))
        durations.append(trajs[-1].duration)
    traj = concatenate(trajs) if len(trajs) > 1 else trajs[0]

    # verification: forward kinematics at check_rate against each leg's lines
    pos_dev: dict[str, float] = {}
    rot_dev: dict[str, float] = {}
    end_err: dict[str, tuple[float, float]] = {}
    t0 = 0.0
    data = robot.model.createData()
    for i, (leg, dur) in enumerate(zip(built, durations, strict=True)):
        t = np.append(np.arange(0.0, dur, 1.0 / check_rate), dur) + t0
        qt = traj(t)
        for frame, line in zip(leg.frames, leg.lines, strict=True):
            p, R = _sample_poses_with(robot, data, qt, robot.frame_id(frame))
            dist, angle, _ = line.deviation(p, R)
            pos_dev[frame] = max(pos_dev.get(frame, 0.0), float(dist.max()))
            rot_dev[frame] = max(rot_dev.get(frame, 0.0), float(angle.max()))
            if i == len(built) - 1:
                goal = line.pose(1.0)
                end_err[frame] = (
                    float(np.linalg.norm(p[-1] - goal[:3, 3])),
                    float(np.linalg.norm(pin.log3(goal[:3, :3].T @ R[-1]))),
                )
        t0 += dur
    max_p, max_r = max(pos_dev.values()), max(rot_dev.values())
    if max_p > solver.max_deviation[0] or max_r > solver.max_deviation[1]:
        raise _DeviationError(
            f"the timed motion deviates {max_p * 1e3:.3g} mm / {max_r:.3g} rad from the line "
            f"(max_deviation {solver.max_deviation[0] * 1e3:.3g} mm / {solver.max_deviation[1]:.3g} rad)"
        )
    waypoints = np.vstack([all_q[0]] + [q[1:] for q in all_q[1:]])
    lams = np.concatenate([all_lam[0]] + [lam[1:] for lam in all_lam[1:]])
    return CartesianResult(
        trajectory=traj,
        waypoints=waypoints,
        path_parameters=lams,
        moving_joints=tuple(robot.joint_names[j] for j in moving_all),
        max_position_deviation=max_p,
        max_orientation_deviation=max_r,
        position_deviation=pos_dev,
        orientation_deviation=rot_dev,
        endpoint_error=end_err,
        method=method,
        leg_durations=tuple(durations),
        widened=widened,
    )


def _sample_poses_with(robot: Robot, data: pin.Data, q: np.ndarray, fid: int) -> tuple[np.ndarray, np.ndarray]:
    p = np.empty((len(q), 3))
    R = np.empty((len(q), 3, 3))
    for k, qk in enumerate(q):
        pin.forwardKinematics(robot.model, data, qk)
        M = pin.updateFramePlacement(robot.model, data, fid)
        p[k] = M.translation
        R[k] = M.rotation
    return p, R


def _time_leg(
    robot: Robot, q: np.ndarray, moving: np.ndarray, limits: JointLimits, method: str, leg_index: int
) -> Trajectory:
    """Time the moving joints' samples; held joints are constant. Returns a trajectory over all joints."""
    from taplan.timing.jerk_limited import jerk_limited
    from taplan.timing.toppra_retime import retime

    names = tuple(robot.joint_names[j] for j in moving)
    sub = limits.subset(names)
    qm = q[:, moving]
    try:
        # the filter of the path timing keeps the IK samples' geometric path (the line bound holds)
        part = jerk_limited(qm, sub, method="path").trajectory if method == "jerk" else retime(qm, sub)
    except TimingError as exc:
        raise TimingError(f"cartesian leg {leg_index}: {exc}") from exc
    except InvalidInputError as exc:
        raise TimingError(f"cartesian leg {leg_index}: the joint path cannot be timed ({exc})") from exc
    c = part.coefficients
    full = np.zeros((c.shape[0], c.shape[1], robot.nq))
    full[:, 0, :] = q[0]
    full[:, :, moving] = c
    return Trajectory.from_polynomials(part.times, full, robot.joint_names)


def cartesian_offset(
    robot: Robot,
    start_q: npt.ArrayLike,
    offsets: Mapping[str, npt.ArrayLike] | Sequence[Mapping[str, npt.ArrayLike]],
    **kwargs: Any,
) -> CartesianResult:
    """Translate frames by fixed offsets along straight lines, keeping their orientation.

    Args:
        robot: The robot.
        start_q: Start configuration [rad], shape (nq,).
        offsets: ``{frame: translation [m] (3,) in the root frame}`` (e.g. ``{"right_ee": [0, 0, -0.1]}``), or a
            sequence of such mappings, each leg relative to where the previous one ends.
        **kwargs: Passed to :func:`cartesian_line`.

    Returns:
        See :func:`cartesian_line`.
    """
    q0 = robot.check_configuration(start_q, "start_q")
    legs = _as_legs(offsets, "offsets")
    frames = sorted({f for leg in legs for f in leg})
    for f in frames:
        robot.frame_id(f)
    current = robot.frame_poses(q0, frames)
    targets = []
    for i, leg in enumerate(legs):
        goal = {}
        for f, d in leg.items():
            T = current[f].copy()
            T[:3, 3] += as_vector(d, f"offsets[{i}][{f!r}]", 3)
            goal[f] = T
            current[f] = T
        targets.append(goal)
    return cartesian_line(robot, q0, targets if not isinstance(offsets, Mapping) else targets[0], **kwargs)
