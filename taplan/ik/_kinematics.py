"""One forward-kinematics + Jacobian pass per step, shared by every task and limit."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

__all__ = ["Kinematics"]

LOCAL_WORLD_ALIGNED = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


class Kinematics:
    """Pinocchio model and data evaluated at one configuration.

    ``update(q)`` runs ``computeJointJacobians`` (which includes forward kinematics) and ``updateFramePlacements``
    once; tasks and limits then read frame placements and Jacobians from ``data`` without recomputing.

    Args:
        model: Pinocchio model (1-DoF joints, ``nq == nv``).
        data: Its data (owned by this object from now on; the caller should not use it concurrently).

    Attributes:
        q: The configuration of the last ``update`` [rad]. Shape (nv,).
    """

    def __init__(self, model: pin.Model, data: pin.Data | None = None) -> None:
        self.model = model
        self.data = model.createData() if data is None else data
        self.nv = int(model.nv)
        self.q = np.zeros(self.nv)
        self.stale = False  # ``q`` changed without ``data`` being updated (a native kernel computed the step)

    def refresh(self) -> None:
        """Bring ``data`` up to date with ``q`` if a native kernel moved ``q`` without it."""
        if self.stale:
            self.update(self.q)

    def update(self, q: np.ndarray) -> None:
        """Evaluate kinematics at ``q`` [rad], shape (nv,) (copied)."""
        self.q[:] = q
        pin.computeJointJacobians(self.model, self.data, self.q)
        pin.updateFramePlacements(self.model, self.data)
        self.stale = False

    def frame_jacobian(self, frame_id: int) -> np.ndarray:
        """Jacobian (6, nv) of a frame: linear velocity of its origin and angular velocity, in root axes."""
        return pin.getFrameJacobian(self.model, self.data, frame_id, LOCAL_WORLD_ALIGNED)

    def joint_jacobian(self, joint_id: int) -> np.ndarray:
        """Jacobian (6, nv) of a joint frame's origin, in root axes."""
        return pin.getJointJacobian(self.model, self.data, joint_id, LOCAL_WORLD_ALIGNED)
