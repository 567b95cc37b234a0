"""The sampler's clearance test against perceived occupancy: do the moving bodies keep ``clearance`` from every
obstacle that answers capsule distances itself (:class:`~taplan.scene.occupancy.Occupancy`)?

:class:`~taplan.planning.compiled_check.ClearanceCheck` tests the robot's own pairs and the closed-form obstacles in
one pinocchio call; occupancy voxels are not coal shapes it can hold (a coal octree of 100k voxels costs tens of ms
per query). This test gets the bodies' segments at ``q`` from the distance engine's compiled kernel and asks each
occupancy obstacle for its capsules' distances with ``cutoff = clearance``: the voxel surface's coarse field and
k-d tree bound every capsule from below (:mod:`taplan.scene.voxel_surface`) and compute the exact distance only for
the capsules those bounds leave within ``clearance``. So "clear" is never answered for a capsule closer than
``clearance`` (the bounds are lower bounds; the rest is exact). Attached objects are tested by their bounding sphere,
as :class:`~taplan.scene.CollisionWorld` does.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from taplan.scene.world import CollisionWorld

__all__ = ["FieldClearance"]


def _moved(model: pin.Model, joint: int, active: np.ndarray | None) -> bool:
    """Whether a body carried by ``joint`` moves when the configuration entries ``active`` (None: all) change."""
    if joint == 0:
        return False
    if active is None:
        return True
    indices = {int(i) for i in np.asarray(active).ravel()}
    return any(model.joints[j].idx_q in indices for j in model.supports[joint] if j > 0)


class FieldClearance:
    """Whether the bodies moved by ``active`` (configuration indices; None: every moving body) and the attached
    objects keep ``clearance`` [m] from the occupancy obstacles of ``world`` (see the module). ``ready`` is False
    when the world has no distance engine (meshes in the scene, or the engine disabled): use the world's test."""

    def __init__(self, world: CollisionWorld, clearance: float, active: np.ndarray | None = None) -> None:
        self.world = world
        self.clearance = float(clearance)
        model = world.model
        self.fields = [o for o in world.scene.obstacles.values() if hasattr(o.shape, "capsule_distances")]
        engine = world.engine()
        self.ready = engine is not None
        self._segments: Any = engine.segments if engine is not None else None
        self.bodies = np.array([k for k, b in enumerate(world.bodies) if _moved(model, b.joint, active)], dtype=int)
        self.radii = np.array([world.bodies[k].radius for k in self.bodies])
        robot = world.robot
        self.attached = []
        for item in world.scene.attached.values():
            frame = robot.frame_id(item.frame)
            if _moved(model, model.frames[frame].parentJoint, active):
                self.attached.append((frame, np.asarray(item.pose, dtype=float), item.shape.bounding_radius()))
        self.model = model
        self.data = model.createData() if self.attached else None

    def __call__(self, q: np.ndarray) -> bool:
        """True when every tested body and attached object is at least ``clearance`` from every occupancy obstacle
        at ``q`` (nq,)."""
        return bool(self.many(np.asarray(q, dtype=float)[None])[0])

    def many(self, Q: np.ndarray) -> np.ndarray:
        """:meth:`__call__` at several configurations (N, nq) in one query per obstacle: (N,) bool."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        N, B = len(Q), len(self.bodies)
        E, _ = self._segments(Q, jacobian=False)
        starts = E[:, self.bodies, 0].reshape(-1, 3)
        ends = E[:, self.bodies, 1].reshape(-1, 3)
        radii = np.tile(self.radii, N)
        owner = np.repeat(np.arange(N), B)
        if self.attached:
            centres, spheres = [], []
            for q in Q:
                pin.framesForwardKinematics(self.model, self.data, q)
                for frame, pose, radius in self.attached:
                    centres.append((self.data.oMf[frame].homogeneous @ pose)[:3, 3])
                    spheres.append(radius)
            centres = np.array(centres)
            starts, ends = np.concatenate([starts, centres]), np.concatenate([ends, centres])
            radii = np.concatenate([radii, spheres])
            owner = np.concatenate([owner, np.repeat(np.arange(N), len(self.attached))])
        clear = np.ones(N, dtype=bool)
        for o in self.fields:
            R, t = o.pose[:3, :3], o.pose[:3, 3]
            ok = o.shape.capsules_clear((starts - t) @ R, (ends - t) @ R, radii, self.clearance)
            clear[owner[~ok]] = False
        return clear
