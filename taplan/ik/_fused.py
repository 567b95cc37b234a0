"""The default stepper's QP assembled in one pass: the hot path of :class:`~taplan.ik.DifferentialIK`.

:class:`~taplan.ik.problem.ProblemBuilder` assembles any combination of tasks and limits through their methods. For a
14-joint problem the arithmetic is tiny and the time goes to interpreter and numpy call overhead (0.3-1.5 µs per
operation), so the default configuration (frame tasks, one posture task, damping; velocity, position, acceleration
and target-braking bounds; collision rows) gets this builder, which returns the same :class:`Problem` with about half
the operations:

- the posture rows are not stored: ``H = AᵀA + diag(w² + λ)`` with ``A`` the frame rows only;
- the orientation error is taken on ``M' = R* Rᵀ``, whose ``log3`` and ``Jlog3`` are the rows themselves
  (``log(M') = -log(R R*ᵀ)``, ``Jlog3(M') = Jlog3(R R*ᵀ)ᵀ``), saving the sign and transpose operations;
- both right-hand sides (the objective's and the targets' motion) go through one Cholesky call;
- the box layers are written into one array (L, 2, nv) and intersected by one reduction. The sequential relaxed
  intersection of :mod:`taplan.ik.limits.limit` runs only when that intersection is empty: when it is not, no layer
  can have been relaxed and both give the same box.

Parameters are read from the same task and limit objects the generic builder uses (one definition of each limit);
``tests/test_ik_fused.py`` checks that both builders produce the same problems and steps.

With ``native=True`` (the default) the whole assembly above, kinematics included, is one compiled CasADi function
(:mod:`taplan.ik._kernel`, :mod:`taplan.ik._native`) when the model's joints are supported and a C compiler is
available; Python then only estimates the targets' motion, calls it and adds the collision rows. The numpy code
below stays the reference and the fallback (the kernel hands it the rare steps it does not cover).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin
from scipy.linalg.lapack import dposv as _dposv

from taplan.ik._kernel import param_layout, step_function
from taplan.ik._kinematics import LOCAL_WORLD_ALIGNED, Kinematics
from taplan.ik._native import NativeFunction, compile_function
from taplan.ik.limits import AccelerationLimit, CollisionLimit, PositionLimit, TargetBraking, VelocityLimit
from taplan.ik.limits.limit import StepContext, intersect_stacked
from taplan.ik.problem import Problem, _free_velocity, check_damping
from taplan.ik.tasks import FrameTask, PostureTask

__all__ = ["FusedBuilder"]

_SIGN = np.array([[1.0], [-1.0]])
_INF = np.inf

_log3 = pin.log3
_Jlog3 = pin.Jlog3
_frame_jacobian = pin.getFrameJacobian
_frame_placement = pin.updateFramePlacement
_joint_jacobians = pin.computeJointJacobians


class FusedBuilder:
    """Builds the default stepper's :class:`Problem` (same contract as ``ProblemBuilder.build``).

    Args:
        kin: Kinematics (its ``q`` and ``data`` are updated by ``build``; frame placements only for task frames).
        frames: Frame tasks.
        posture: The posture task.
        damping: Levenberg-Marquardt damping ``λ`` >= 0.
        velocity: Velocity limit.
        position: Position limit.
        acceleration: Acceleration limit, or None.
        braking: Target braking (requires ``acceleration``), or None.
        collision: Collision rows, or None.
        native: Compute the problem with a compiled kernel when possible (see the module docstring).
    """

    def __init__(
        self,
        kin: Kinematics,
        frames: Sequence[FrameTask],
        posture: PostureTask,
        damping: float,
        velocity: VelocityLimit,
        position: PositionLimit,
        acceleration: AccelerationLimit | None = None,
        braking: TargetBraking | None = None,
        collision: CollisionLimit | None = None,
        native: bool = True,
    ) -> None:
        n = kin.nv
        self.kin = kin
        self.tasks = [*frames, posture]
        self._frame_tasks = list(frames)
        self.posture = posture
        self.damping = damping
        self.velocity, self.position, self.acceleration, self.braking = velocity, position, acceleration, braking
        self.collision = collision
        self.box_limits = [lim for lim in (acceleration, velocity, position, braking) if lim is not None]
        self.row_limits = [] if collision is None else [collision]
        rows = 6 * len(frames)
        self._A = np.zeros((rows, n))
        self._AT = self._A.T
        self._b = np.zeros(rows)
        self._b_ff = np.zeros(rows)
        self._frames = []
        for i, task in enumerate(frames):
            r = slice(6 * i, 6 * i + 6)
            A, b = self._A[r], self._b[r]
            target = task._target  # the task's target buffer (fixed): its rotation and translation views
            views = (A, b, self._b_ff[r], A[:3], A[3:], b[:3], b[3:], target[:3, :3], target[:3, 3])
            self._frames.append((task, task.frame_id, *views))
        self._motions = [np.zeros(6) for _ in frames]  # each target's motion [ṗ*, ω*] (FrameTask.motion)
        self._codes = [0] * len(frames)
        self._H = np.zeros((n, n))
        self._c = np.zeros(n)
        self._c_ff = np.zeros(n)
        self._rhs = np.zeros((n, 2), order="F")
        self._rhs0, self._rhs1 = self._rhs[:, 0], self._rhs[:, 1]
        self._tmp = np.zeros(n)
        self._v_prev = np.zeros(n)
        self._x = np.zeros((n, 2), order="F")  # [v_free, v_ff] as solved together (contiguous columns)
        self._v_free, self._v_ff = self._x[:, 0], self._x[:, 1]
        self._minimiser = np.zeros(n)
        self._stack = np.zeros((len(self.box_limits), 2, n))
        self._box = np.zeros((2, n))
        self._scratch = np.zeros((2, n))
        self._width = np.zeros(n)
        self._neg = np.zeros(n, dtype=bool)
        self._relative = np.zeros(n)
        self._ratio = np.zeros(n)
        self._away = np.zeros((2, n), dtype=bool)
        k = 1 if braking is None else 2  # layers sharing the braking formula: position (and target braking)
        self._X = np.zeros((k, 2, n))
        self._T = np.zeros((k, 2, n))
        self._S = np.zeros((k, 2, n))
        self._upper_bound, self._lower_bound = position.upper, position.lower
        self._distance = self._X[0]
        self._distance_flat = self._distance.reshape(-1)
        self._X_upper, self._X_lower = self._X[0, 0], self._X[0, 1]
        self._X_speed = self._X[k - 1]
        self._S_brake = self._S[k - 1, 0]
        self._away_upper, self._away_lower = self._away[0], self._away[1]
        self._lower = np.zeros(n)
        self._upper = self._box[0]
        layer = {id(lim): self._stack[k] for k, lim in enumerate(self.box_limits)}
        self._acc_out = None if acceleration is None else layer[id(acceleration)]
        self._pos_out = layer[id(position)]
        self._brake_out = None if braking is None else layer[id(braking)]
        index = self.box_limits.index(position)  # position and braking layers are adjacent (priorities 20, 30)
        self._braking_out = self._stack[index : index + k]
        if acceleration is not None:
            self._acc_upper, self._acc_lower = self._acc_out[0], self._acc_out[1]
        if braking is not None:
            self._brake_upper, self._brake_lower = self._brake_out[0], self._brake_out[1]
        layer[id(velocity)][:] = velocity.velocity  # constant: [v_max, v_max]
        self._dt = -1.0
        self._posture_weights: np.ndarray | None = None
        self._ctx = StepContext(kin, 0.01, self._v_prev, self._v_free, self._v_ff)
        max_rows = 0 if collision is None else collision.max_rows
        self._G = np.zeros((max_rows, n))
        self._h = np.zeros(max_rows)
        self.problem = Problem(
            self._H,
            self._c,
            self._lower,
            self._upper,
            self._G[:0],
            self._h[:0],
            0.01,
            self._v_prev,
            self._v_free,
            [(lim.name, layer[id(lim)]) for lim in self.box_limits],
            minimiser=self._minimiser,
        )
        self.frame_errors = np.zeros(2 * len(frames))  # the kernel's [position [m], orientation [rad]] per frame
        self._kernel: NativeFunction | None = None
        self._kernel_state: tuple = (None, None, None)
        if native:
            self._kernel = self._attach_kernel()
        self.native_steps = 0  # steps computed by the kernel (the others by numpy)

    @property
    def native(self) -> bool:
        """Whether a compiled kernel computes the problems (else the numpy code of this module)."""
        return self._kernel is not None

    def _attach_kernel(self) -> NativeFunction | None:
        frames = self._frame_tasks
        if not all(type(task) is FrameTask for task in frames) or type(self.posture) is not PostureTask:
            return None
        acceleration, braking = self.acceleration is not None, self.braking is not None
        collision = self.collision
        pairs = 0 if collision is None else len(collision.pairs)
        function = step_function(self.kin.model, [t.frame_id for t in frames], acceleration, braking, pairs)
        if function is None:
            return None
        n = self.kin.nv
        self._layout = param_layout(n, len(frames), acceleration, braking, pairs)
        self._params = np.zeros(self._layout["size"].stop)
        self._step = np.zeros(1 + len(frames))
        self._flag = np.zeros(1)
        per_frame = [x for task, m in zip(frames, self._motions, strict=True) for x in (task._target.reshape(-1), m)]
        inputs = [self.kin.q, self._v_prev, self.posture.target, self._params, self._step, *per_frame]
        outputs = [
            self._H.reshape(-1),
            self._c,
            self._minimiser,
            self._x.reshape(-1, order="F"),  # [v_free, v_ff]
            self._stack.reshape(-1),
            self._box.reshape(-1),
            self._lower,
            self._flag,
            self.frame_errors,
        ]
        self._screen = np.zeros(2)
        if pairs:
            inputs += [collision._q_eval, collision._abs_grads.reshape(-1), collision._braking_factor]
            inputs.append(collision._distances_eval)
            outputs.append(self._screen)
        return compile_function(function, inputs, outputs)

    def _write_params(self, dt: float) -> None:
        """The kernel's parameters for step ``dt`` and the current weights, gains and damping."""
        frames = self._frame_tasks
        self._kernel_state = (dt, self.posture._weights, self._damping, *[t.gain for t in frames])
        if dt != self._dt:
            self._new_dt(dt)
        if self.posture._weights is not self._posture_weights:
            self._new_posture_weights()
        put = {
            "diagonal": np.diag(self._diagonal),
            "posture_gain": self._posture_gain,
            "velocity": self.velocity.velocity,
            "upper": self.position.upper,
            "lower": self.position.lower,
            "position_gain": self.position.gain,
        }
        if self.collision is not None and self.collision.pairs:
            put["reach"] = self.collision.reach
        if self.acceleration is not None:
            put["acceleration"] = self.acceleration.acceleration
            put["position_acceleration"] = self.position.acceleration
        if self.braking is not None:
            put["braking_acceleration"] = self.braking.acceleration
        for i, task in enumerate(frames):
            put[f"weights{i}"] = task._weights
            put[f"gain{i}"] = task.gain
        for name, value in put.items():
            self._params[self._layout[name]] = value
        self._step[0] = dt

    @property
    def damping(self) -> float:
        """Levenberg-Marquardt damping ``λ`` on the Hessian's diagonal."""
        return self._damping

    @damping.setter
    def damping(self, value: float) -> None:
        self._damping = check_damping(value)
        self._posture_weights = None  # rebuild the diagonal

    def _new_dt(self, dt: float) -> None:
        self._dt = dt
        if self.acceleration is None:
            return
        self._adt_vec = self.acceleration.acceleration * dt
        rows = [self.position.acceleration]
        if self.braking is not None:
            rows.append(self.braking.acceleration)
        a = np.stack([np.stack([r, r]) for r in rows])  # (k, 2, nv)
        self._K = 2.0 * a
        if self.braking is not None:
            self._K[1] *= dt
            self._brake_two_adt = 2.0 * self.braking.acceleration * dt
        self._adt = a * dt
        self._adt2 = self._adt * self._adt

    def _new_posture_weights(self) -> None:
        w = self.posture._weights
        self._posture_weights = w
        self._posture_gain = w * w * self.posture.gain  # Aᵀb of the posture rows is w² gain (q* - q)
        self._diagonal = np.diag(w * w + self._damping)

    def build(self, q: np.ndarray, dt: float, v_prev: np.ndarray | None = None) -> Problem:
        """Update kinematics at ``q`` [rad] and fill the problem for a step of ``dt`` [s] (inputs not validated)."""
        kernel = self._kernel
        if kernel is None:
            return self._build_numpy(q, dt, v_prev, None)
        kin = self.kin
        kin.q[:] = q
        state = self._kernel_state
        if dt != state[0] or self.posture._weights is not state[1] or self._damping != state[2]:
            self._write_params(dt)
        else:
            for task, gain in zip(self._frame_tasks, state[3:], strict=True):
                if task.gain != gain:
                    self._write_params(dt)
                    break
        if v_prev is None:
            self._v_prev.fill(0.0)
        else:
            self._v_prev[:] = v_prev
        moving = False
        codes, flags = self._codes, self._step
        for i, (task, motion) in enumerate(zip(self._frame_tasks, self._motions, strict=True)):
            if task.target is None:
                task._require_target()
            code = codes[i] = task.motion(dt, motion)
            if code:
                moving = True
            flags[i + 1] = 1.0 if code == 2 else 0.0
        kernel()
        if self._flag[0] != 0.0:  # a case the kernel leaves to numpy (see taplan.ik._kernel)
            return self._build_numpy(q, dt, v_prev, codes)
        kin.stale = True
        self.native_steps += 1
        problem = self.problem
        problem.minimiser_exact = True
        return self._rows(problem, dt, moving, self._screen)

    def _build_numpy(self, q: np.ndarray, dt: float, v_prev: np.ndarray | None, codes: list[int] | None) -> Problem:
        """``build`` with numpy; ``codes`` are the targets' motion codes if :meth:`FrameTask.motion` already ran."""
        kin = self.kin
        model, data = kin.model, kin.data
        kq = kin.q
        kq[:] = q
        _joint_jacobians(model, data, kq)
        kin.stale = False
        if dt != self._dt:
            self._new_dt(dt)
        if self.posture._weights is not self._posture_weights:
            self._new_posture_weights()
        moving = False
        for i, (task, fid, A6, b6, bff6, A_pos, A_rot, b_pos, b_rot, R_target, p_target) in enumerate(self._frames):
            if task._unit and task.gain == 1.0:
                if task.target is None:
                    task._require_target()
                placement = _frame_placement(model, data, fid)
                Mt = np.dot(R_target, placement.rotation.T)  # R* Rᵀ
                J = _frame_jacobian(model, data, fid, LOCAL_WORLD_ALIGNED)
                JlogT = _Jlog3(Mt)
                np.dot(JlogT, J[3:], out=A_rot)
                A_pos[:] = J[:3]
                np.subtract(p_target, placement.translation, out=b_pos)
                b_rot[:] = _log3(Mt)
                task._M = Mt.T  # for the feed-forward of a rotating target
                task._JlogT = JlogT
            else:
                _frame_placement(model, data, fid)  # fill and the frame Jacobian read data.oMf
                task.fill(kin, A6, b6)
            motion = self._motions[i]
            code = task.motion(dt, motion) if codes is None else codes[i]
            if code:
                moving = True
                task.map_motion(motion, bff6)
                if code == 2:  # explicit target velocity: the step aims at where the target will be
                    b6 += bff6 * dt
            else:
                bff6.fill(0.0)
        H = self._H
        AT = self._AT
        np.dot(AT, self._A, out=H)
        H += self._diagonal
        rhs0 = self._rhs0  # -c dt: Aᵀb of the frame rows plus the posture rows
        np.dot(AT, self._b, out=rhs0)
        tmp = self._tmp
        np.subtract(self.posture.target, kq, out=tmp)
        tmp *= self._posture_gain
        rhs0 += tmp
        rhs0 *= 1.0 / dt
        c = self._c  # written at the end, with the objective scale; here only for the least-squares fallback
        v_free, v_ff = self._v_free, self._v_ff
        problem = self.problem
        if moving:
            np.dot(AT, self._b_ff, out=self._rhs1)  # -c_ff
            _, x, info = _dposv(H.T, self._rhs)  # H is symmetric: H.T is the Fortran-ordered view LAPACK wants
            if info == 0:
                self._x[:] = x
                problem.minimiser_exact = True
            else:
                np.negative(self._rhs1, out=self._c_ff)
                _free_velocity(H, self._c_ff, v_ff)
                np.negative(rhs0, out=c)
                problem.minimiser_exact = _free_velocity(H, c, v_free)
        else:
            _, x, info = _dposv(H.T, rhs0)
            if info == 0:
                v_free[:] = x
                problem.minimiser_exact = True
            else:
                np.negative(rhs0, out=c)
                problem.minimiser_exact = _free_velocity(H, c, v_free)
        v_prev_buffer = self._v_prev
        if v_prev is None:
            v_prev_buffer.fill(0.0)
        else:
            v_prev_buffer[:] = v_prev
        scale = self._box_layers(kq, v_prev_buffer, moving, dt)
        box = self._box
        np.minimum.reduce(self._stack, axis=0, out=box)
        width = self._width
        np.add(box[0], box[1], out=width)  # upper - lower
        if np.count_nonzero(np.less(width, 0.0, out=self._neg)):  # a layer must be relaxed: the sequential way
            stack, scratch = self._stack, self._scratch
            np.copyto(box, stack[0])
            for k in range(1, stack.shape[0]):
                intersect_stacked(box, stack[k], scratch)
        np.negative(box[1], out=self._lower)
        minimiser = self._minimiser
        # c = -rhs0 scaled by κ; with moving targets only the part relative to their motion is scaled:
        # c = c_ff + κ (c - c_ff) with c_ff = -rhs1, and the minimiser becomes v_ff + κ (v_free - v_ff)
        if scale != 1.0 and moving:
            rhs1 = self._rhs1
            np.subtract(rhs0, rhs1, out=c)
            c *= -scale
            c -= rhs1
            np.subtract(v_free, v_ff, out=minimiser)
            minimiser *= scale
            minimiser += v_ff
        elif scale != 1.0:
            np.multiply(rhs0, -scale, out=c)
            np.multiply(v_free, scale, out=minimiser)
        else:
            np.negative(rhs0, out=c)
            minimiser[:] = v_free
        return self._rows(problem, dt, moving)

    def _rows(self, problem: Problem, dt: float, moving: bool, screen: np.ndarray | None = None) -> Problem:
        """Set the step's ``dt`` and the collision rows of ``problem`` (``screen``: the kernel's collision
        screening, else computed here)."""
        problem.dt = dt
        k = 0
        if self.collision is not None:
            ctx = self._ctx
            ctx.dt = dt
            ctx.moving = moving
            collision = self.collision
            if screen is None or not collision.pairs:
                k = collision.rows(ctx, self._G, self._h)
            else:
                travel, closest = screen.tolist()
                k = collision.screened_rows(ctx, self._G, self._h, travel, closest)
        if problem.h.shape[0] != k:
            problem.G = self._G[:k]
            problem.h = self._h[:k]
        return problem

    def _box_layers(self, q: np.ndarray, v_prev: np.ndarray, moving: bool, dt: float) -> float:
        """Write the acceleration, position and braking layers (the velocity layer is constant); return the
        objective scale κ of target braking (1 without it).

        Position braking (distance ``D`` to each bound) and target braking (speed ``|v_free - v_ff|`` toward the
        target) share one formula, ``2aX / (sqrt(2aX + (a dt)²) + a dt)`` with ``X = D`` or ``X = speed dt``, so
        both are computed together on one (2k, nv) array.
        """
        acc_out = self._acc_out
        X = self._X
        np.subtract(self._upper_bound, q, out=self._X_upper)  # distances to the bounds
        np.subtract(q, self._lower_bound, out=self._X_lower)
        if acc_out is None:
            np.multiply(self._distance, self.position.gain / dt, out=self._pos_out)
            return 1.0
        np.add(v_prev, self._adt_vec, out=self._acc_upper)  # v_prev ± a dt
        np.subtract(self._adt_vec, v_prev, out=self._acc_lower)
        brake_out = self._brake_out
        if brake_out is not None:
            if moving:
                relative = self._relative
                np.subtract(self._v_free, self._v_ff, out=relative)
            else:
                relative = self._v_free
            np.abs(relative, out=self._X_speed)  # the speed toward the target, in both rows
        outside = min(self._distance_flat.tolist()) < 0.0
        if outside:  # the general formula below; keep the square root real
            np.maximum(self._distance, 0.0, out=self._distance)
        T, S = self._T, self._S
        np.multiply(self._K, X, out=T)  # 2aD and 2a dt speed
        np.add(T, self._adt2, out=S)
        np.sqrt(S, out=S)
        S += self._adt
        np.divide(T, S, out=self._braking_out)
        if outside:
            self._ctx.dt = dt
            self._pos_out[:] = self.position.stacked(self._ctx)
        if brake_out is None:
            return 1.0
        ratio = self._ratio  # bound / speed, as in TargetBraking
        np.divide(self._brake_two_adt, self._S_brake, out=ratio)
        kappa = min(ratio.tolist())
        away = self._away  # moving away from the target: no bound on that side
        np.less(relative, 0.0, out=self._away_upper)
        np.greater(relative, 0.0, out=self._away_lower)
        np.copyto(brake_out, _INF, where=away)
        if moving:
            v_ff = self._v_ff
            self._brake_upper += v_ff
            self._brake_lower -= v_ff
        return 1.0 if kappa >= 1.0 else kappa * (1.0 - 1e-12)
