"""Frame task: drive a frame's pose (position and orientation) to a target pose in the root frame."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from taplan.ik._kinematics import LOCAL_WORLD_ALIGNED, Kinematics
from taplan.ik._targets import as_transform, check_matrix, pose_keys
from taplan.ik.tasks.task import Task, check_cost, check_gain

__all__ = ["FrameTask"]


class FrameTask(Task):
    r"""Pose of one frame in the root frame.

    The error (6,) is, in root-frame axes,

    .. math::

        e = \begin{bmatrix} p - p^* \\ \log(R R^{*T}) \end{bmatrix}

    with position ``p`` [m] and rotation ``R`` of the frame, target ``p*``, ``R*``, and ``log`` the rotation vector
    [rad]. Its exact Jacobian is ``[J_v; J_log(R R*ᵀ)ᵀ J_ω]`` with the frame Jacobian ``[J_v; J_ω]`` (root axes,
    origin of the frame) and pinocchio's ``Jlog3`` (the inverse right Jacobian of SO(3); its transpose is the
    inverse left Jacobian, which maps the world angular velocity to the rate of the rotation vector).

    Args:
        frame_id: Pinocchio frame index.
        position_cost: Cost per [m], a number or per root axis (3,).
        orientation_cost: Cost per [rad], a number or per root axis (3,).
        gain: Fraction of the error removed per step, in (0, 1].
        name: The frame's name (for messages).
    """

    rows = 6

    def __init__(
        self,
        frame_id: int,
        position_cost: npt.ArrayLike = 1.0,
        orientation_cost: npt.ArrayLike = 1.0,
        gain: float = 1.0,
        name: str = "",
    ) -> None:
        self.frame_id = int(frame_id)
        self.name = name
        self.gain = check_gain(gain)
        self._weights = np.concatenate(
            [check_cost(position_cost, "position_cost", 3), check_cost(orientation_cost, "orientation_cost", 3)]
        )
        self._unit = bool(np.all(self._weights == 1.0))
        self.target: np.ndarray | None = None
        self._target = np.eye(4)
        self._R_target_T = self._target[:3, :3].T  # views of the target buffer
        self._p_target = self._target[:3, 3]
        # target motion (feed-forward): the target at the last ``feedforward`` call, an explicit twist for the step
        self.estimate_velocity = False
        self._last = np.eye(4)  # the target at the last velocity estimate
        self._p_last = self._last[:3, 3]
        self._rot_key = self._last_rot = b""  # the rotation's bytes and the translation of the target and of _last
        self._pos_key: tuple[float, ...] = ()
        self._last_pos: tuple[float, ...] = ()
        self._rot_moved = self._pos_moved = False
        self._ff_views: tuple[np.ndarray, ...] | None = None
        self._twist: np.ndarray | None = None
        self._twist_buffer = np.zeros(6)
        self._zero: np.ndarray | None = None  # the motion buffer last zeroed by ``motion``
        self._M = np.eye(3)
        self._JlogT = np.eye(3)
        self._views: tuple[np.ndarray, ...] | None = None
        self._checked = b""  # rotation block of the last target validated by _set_matrix

    def set_target(self, target: Any) -> None:
        """Target pose ``T_root_frame``: 4x4, ``(position, quaternion_xyzw)`` or (7,) (validated)."""
        self._set(as_transform(target, f"target[{self.name}]" if self.name else "target"))

    def _set_matrix(self, T: np.ndarray, frame: str) -> None:
        """Set a float64 (4, 4) array target given as ``targets[frame]``, validated by
        :func:`~taplan.ik._targets.check_matrix` (hot path)."""
        keys = check_matrix(T, self._checked, frame)
        self._checked = keys[0]
        self._set(T, keys)

    def _set(self, T: np.ndarray, keys: tuple[bytes, tuple[float, float, float]] | None = None) -> None:
        """Set a 4x4 target that is already validated (hot path; copied into the task's buffer); ``keys`` are its
        :func:`~taplan.ik._targets.pose_keys` if known."""
        target = self._target
        target[:] = T
        self.target = target
        # which parts moved since the last velocity estimate (the rotation's bytes, the translation's values)
        self._rot_key, self._pos_key = pose_keys(target) if keys is None else keys
        self._rot_moved = self._rot_key != self._last_rot
        self._pos_moved = self._pos_key != self._last_pos

    def set_target_from_configuration(self, kin: Kinematics) -> None:
        """Target = the frame's current pose (hold it); forgets the target's motion."""
        self._set(kin.data.oMf[self.frame_id].homogeneous.copy())
        self.reset_motion()

    def reset_motion(self) -> None:
        """Forget the target's motion: the current target is the reference of the next velocity estimate."""
        self._last[:] = self._target
        self._last_rot, self._last_pos = self._rot_key, self._pos_key
        self._rot_moved = self._pos_moved = False
        self._twist = None

    def set_target_velocity(self, twist: np.ndarray) -> None:
        """Target twist ``[ṗ* (3,) [m/s], ω* (3,) [rad/s]]`` in root axes for the next step only (validated by the
        caller); it is fed forward in the objective and in target braking."""
        self._twist_buffer[:] = twist
        self._twist = self._twist_buffer

    def feedforward(self, dt: float, b: np.ndarray) -> int:
        """Write the weighted task-space velocity that follows the target's motion, ``W [ṗ*; J_logᵀ M ω*]``, into
        ``b`` (6,) [m/s, rad/s] (after ``fill`` at the same configuration).

        The motion is the one :meth:`motion` reports (its return value is returned); ``b`` is left all zero when 0
        is returned.
        """
        code = self.motion(dt, b)
        if code:
            self.map_motion(b, b)
        return code

    def motion(self, dt: float, out: np.ndarray) -> int:
        """Write the target's motion ``[ṗ* (3,) [m/s], ω* (3,) [rad/s]]`` (root axes) into ``out`` (6,).

        The motion is the explicit twist given with ``set_target_velocity`` (returns 2: also fed forward in the
        objective), else, if ``estimate_velocity``, the finite difference of the target since the previous call over
        ``dt`` (returns 1: used by target braking only; 0 if the target did not move), else none (returns 0). ``out``
        is left all zero when 0 is returned.
        """
        twist = self._twist
        if twist is not None:
            self.reset_motion()
            out[:] = twist
            self._zero = None
            return 2
        if self.estimate_velocity and (self._pos_moved or self._rot_moved):
            views = self._ff_views
            if views is None or views[0] is not out:
                views = self._ff_views = (out, out[:3], out[3:])
            _, out_pos, out_rot = views
            inv_dt = 1.0 / dt
            if self._pos_moved:
                np.subtract(self._p_target, self._p_last, out=out_pos)
                out_pos *= inv_dt
                self._p_last[:] = self._p_target
            else:
                out_pos.fill(0.0)
            if self._rot_moved:
                R_last = self._last[:3, :3]
                np.multiply(pin.log3(self._target[:3, :3] @ R_last.T), inv_dt, out=out_rot)
                R_last[:] = self._target[:3, :3]
            else:
                out_rot.fill(0.0)
            self._last_rot, self._last_pos = self._rot_key, self._pos_key
            self._rot_moved = self._pos_moved = False
            self._zero = None
            return 1
        if self._zero is not out:  # zeroed once per buffer until a motion is written into it
            out.fill(0.0)
            self._zero = out
        return 0

    def map_motion(self, motion: np.ndarray, b: np.ndarray) -> None:
        """``b = W [ṗ*; J_logᵀ M ω*]`` from ``motion = [ṗ*, ω*]`` (may be ``b`` itself), with ``M = R R*ᵀ`` and
        ``J_log`` of the last ``fill``: the target's rotation ω* moves the error ``M`` by ``-M ω*`` (left), i.e. the
        rotation vector by ``-J_logᵀ M ω*``; following it needs ``+J_logᵀ M ω*``."""
        if b is not motion:
            b[:3] = motion[:3]
        np.matmul(self._JlogT, self._M @ motion[3:], out=b[3:])
        if not self._unit:
            b *= self._weights

    def weights(self) -> np.ndarray:
        return self._weights

    def _require_target(self) -> None:
        if self.target is None:
            from taplan.errors import InvalidInputError

            raise InvalidInputError("target", None, f"a target set with set_target() for frame {self.name!r}")

    def compute_error(self, kin: Kinematics) -> np.ndarray:
        self._require_target()
        placement = kin.data.oMf[self.frame_id]
        e = np.empty(6)
        e[:3] = placement.translation - self._p_target
        e[3:] = pin.log3(placement.rotation @ self._R_target_T)
        return e

    def compute_jacobian(self, kin: Kinematics) -> np.ndarray:
        self._require_target()
        J = kin.frame_jacobian(self.frame_id)
        M = kin.data.oMf[self.frame_id].rotation @ self._R_target_T
        J[3:] = pin.Jlog3(M).T @ J[3:]
        return J

    def fill(self, kin: Kinematics, A: np.ndarray, b: np.ndarray) -> None:
        if self.target is None:
            self._require_target()
        placement = kin.data.oMf[self.frame_id]
        M = np.matmul(placement.rotation, self._R_target_T)
        J = pin.getFrameJacobian(kin.model, kin.data, self.frame_id, LOCAL_WORLD_ALIGNED)
        w = self._weights
        self._M = M
        self._JlogT = JlogT = pin.Jlog3(M).T
        if self._unit and self.gain == 1.0:  # hot path: the row blocks of A and b are cached views
            views = self._views
            if views is None or views[0] is not A or views[1] is not b:
                views = self._views = (A, b, A[:3], A[3:], b[:3], b[3:])
            np.matmul(JlogT, J[3:], out=views[3])
            views[2][:] = J[:3]
            np.subtract(self._p_target, placement.translation, out=views[4])
            np.negative(pin.log3(M), out=views[5])
            return
        pose = placement.homogeneous
        np.matmul(JlogT, J[3:], out=A[3:])
        if self._unit:
            np.subtract(pose[:3, 3], self._p_target, out=b[:3])
            b[3:] = pin.log3(M)
            A[:3] = J[:3]
            b *= -self.gain
        else:
            np.subtract(pose[:3, 3], self._p_target, out=b[:3])
            b[3:] = pin.log3(M)
            np.multiply(w[:3, None], J[:3], out=A[:3])
            A[3:] *= w[3:, None]
            b *= w
            b *= -self.gain
