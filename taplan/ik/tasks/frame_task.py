"""Frame task: drive a frame's pose (position and orientation) to a target pose in the root frame."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from taplan.ik._kinematics import LOCAL_WORLD_ALIGNED, Kinematics
from taplan.ik._targets import as_transform
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

    def set_target(self, target: Any) -> None:
        """Target pose ``T_root_frame``: 4x4, ``(position, quaternion_xyzw)`` or (7,) (validated)."""
        self._set(as_transform(target, f"target[{self.name}]" if self.name else "target"))

    def _set(self, T: np.ndarray) -> None:
        """Set a 4x4 target that is already validated (hot path; copied into the task's buffer)."""
        self._target[:] = T
        self.target = self._target

    def set_target_from_configuration(self, kin: Kinematics) -> None:
        """Target = the frame's current pose (hold it)."""
        self._set(kin.data.oMf[self.frame_id].homogeneous.copy())

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
        pose = kin.data.oMf[self.frame_id].homogeneous
        M = np.matmul(pose[:3, :3], self._R_target_T)
        J = pin.getFrameJacobian(kin.model, kin.data, self.frame_id, LOCAL_WORLD_ALIGNED)
        w = self._weights
        np.matmul(pin.Jlog3(M).T, J[3:], out=A[3:])
        if self._unit and self.gain == 1.0:
            np.subtract(self._p_target, pose[:3, 3], out=b[:3])
            np.negative(pin.log3(M), out=b[3:])
            A[:3] = J[:3]
        elif self._unit:
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
