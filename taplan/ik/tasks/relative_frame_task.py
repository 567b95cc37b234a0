"""Relative frame task: the pose of one frame in another (e.g. one hand relative to the other)."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from taplan.ik._kinematics import Kinematics
from taplan.ik._targets import as_transform
from taplan.ik.tasks.task import Task, check_cost, check_gain

__all__ = ["RelativeFrameTask"]


def _skew(r: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


class RelativeFrameTask(Task):
    r"""Pose of ``frame`` expressed in ``root``: ``T_root_frame = T_world_root⁻¹ T_world_frame``.

    Used to keep two hands at a fixed relative pose while carrying an object with both. The error (6,) is in the
    ``root`` frame's axes:

    .. math::

        e = \begin{bmatrix} R_r^T (p_f - p_r) - p^* \\ \log(R_r^T R_f R^{*T}) \end{bmatrix}

    and its Jacobian follows from the two frame Jacobians ``J_f``, ``J_r`` (root-frame axes, at each origin):
    ``de_p = R_rᵀ (J_f,v − J_r,v + [p_f − p_r]× J_r,ω) dq`` and ``de_r = J_log(M)ᵀ R_rᵀ (J_f,ω − J_r,ω) dq``.

    Args:
        frame_id: Pinocchio index of the moving frame.
        root_id: Pinocchio index of the frame it is expressed in.
        position_cost: Cost per [m], a number or per axis of ``root`` (3,).
        orientation_cost: Cost per [rad], a number or per axis of ``root`` (3,).
        gain: Fraction of the error removed per step, in (0, 1].
    """

    rows = 6

    def __init__(
        self,
        frame_id: int,
        root_id: int,
        position_cost: npt.ArrayLike = 1.0,
        orientation_cost: npt.ArrayLike = 1.0,
        gain: float = 1.0,
        name: str = "",
    ) -> None:
        self.frame_id = int(frame_id)
        self.root_id = int(root_id)
        self.name = name
        self.gain = check_gain(gain)
        self._weights = np.concatenate(
            [check_cost(position_cost, "position_cost", 3), check_cost(orientation_cost, "orientation_cost", 3)]
        )
        self.target = np.eye(4)

    def set_target(self, target: Any) -> None:
        """Target ``T_root_frame``: 4x4, ``(position, quaternion_xyzw)`` or (7,)."""
        self.target = as_transform(target, "target")

    def set_target_from_configuration(self, kin: Kinematics) -> None:
        """Target = the current relative pose."""
        self.target = self._relative(kin).homogeneous

    def _relative(self, kin: Kinematics) -> pin.SE3:
        return kin.data.oMf[self.root_id].actInv(kin.data.oMf[self.frame_id])

    def weights(self) -> np.ndarray:
        return self._weights

    def compute_error(self, kin: Kinematics) -> np.ndarray:
        rel = self._relative(kin)
        e = np.empty(6)
        e[:3] = rel.translation - self.target[:3, 3]
        e[3:] = pin.log3(rel.rotation @ self.target[:3, :3].T)
        return e

    def compute_jacobian(self, kin: Kinematics) -> np.ndarray:
        root = kin.data.oMf[self.root_id]
        frame = kin.data.oMf[self.frame_id]
        Rr_T = root.rotation.T
        Jf = kin.frame_jacobian(self.frame_id)
        Jr = kin.frame_jacobian(self.root_id)
        J = np.empty_like(Jf)
        J[:3] = Rr_T @ (Jf[:3] - Jr[:3] + _skew(frame.translation - root.translation) @ Jr[3:])
        M = Rr_T @ frame.rotation @ self.target[:3, :3].T
        J[3:] = pin.Jlog3(M).T @ Rr_T @ (Jf[3:] - Jr[3:])
        return J
