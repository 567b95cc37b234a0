"""Keep the robot away from a scene's obstacles (and its torso and head): velocity-damper rows on signed distances.

The same constraint as the arm-arm :class:`~taplan.ik.limits.CollisionLimit`, on the pairs of a
:class:`~taplan.scene.CollisionWorld` (robot bodies vs obstacles, attached objects, the robot's torso, chest and
head; the arm-arm pairs stay with CollisionLimit). For each pair closer than ``influence`` with distance ``d`` and
Jacobian ``J_d`` [m/rad]:

.. math::

    -J_d v \\le \\min\\left(\\gamma \\frac{d - d_m}{dt},\\ \\sqrt{2 \\alpha (d - d_m)}\\right), \\qquad
    \\alpha = \\tfrac12 \\sum_j |J_{d,j}| a_j

so one step closes at most the fraction ``γ`` of the gap above the margin ``d_m`` and the approach speed is one the
joints can still brake from; below the margin the right-hand side becomes a separation speed. A target inside an
obstacle therefore ends at the closest configuration that keeps the margin: the hand slides along the surface.

Screening: distances are recomputed only when a point of the robot may have moved enough to enter the influence
distance since the last evaluation (``travel @ |q - q_eval|`` per pair, :class:`~taplan.scene.Distances`).
"""

from __future__ import annotations

import numpy as np

from taplan.ik.limits.collision_limit import check_damper
from taplan.ik.limits.limit import RowLimit, StepContext
from taplan.scene.world import CollisionWorld

__all__ = ["SceneLimit"]

MAX_ROWS = 64


class SceneLimit(RowLimit):
    """Velocity-damper rows for the scene's pairs within ``influence``.

    Args:
        world: Robot and scene.
        margin: Minimum distance [m], >= 0.
        influence: Distance below which a pair is constrained [m], > margin.
        gain: Fraction ``γ`` of the gap a step may close, in (0, 1].
        acceleration: Joint acceleration limits [rad/s²] (nv,) for the braking term, or None.
        arm_pairs: Also constrain arm-arm pairs (False when a CollisionLimit already does).
    """

    name = "scene"

    def __init__(
        self,
        world: CollisionWorld,
        margin: float = 0.02,
        influence: float = 0.10,
        gain: float = 0.5,
        acceleration: np.ndarray | None = None,
        arm_pairs: bool = False,
    ) -> None:
        check_damper(margin, influence, gain)
        self.world = world
        self.margin, self.influence, self.gain = float(margin), float(influence), float(gain)
        self.acceleration = None if acceleration is None else np.asarray(acceleration, dtype=float)
        self.max_rows = MAX_ROWS
        groups = {b.name: b.group for b in world.bodies}
        self._skip = set()
        if not arm_pairs:
            self._skip = {(a, b) for a in groups for b in groups if groups[a] and groups[b] and groups[a] != groups[b]}
        self.min_distance = np.inf
        self.reset()

    def reset(self) -> None:
        self._q_eval: np.ndarray | None = None
        self._slack = -np.inf
        self._travel = np.zeros((0, self.world.model.nv))
        self._clear = np.zeros(0)

    def rows(self, ctx: StepContext, G: np.ndarray, h: np.ndarray) -> int:
        q = ctx.kin.q
        if self._q_eval is not None and self._travel.size:
            moved = self._travel @ np.abs(q - self._q_eval)
            if np.all(moved < self._clear):  # no pair can have entered the influence distance
                return 0
        far = self.influence + 0.1  # evaluate a band beyond the influence: pairs that may enter it soon
        d = self.world.distances(q, cutoff=far)
        self._q_eval = q.copy()
        keep = [k for k, p in enumerate(d.pairs) if p not in self._skip]
        self._travel = d.travel[keep] if keep else np.zeros((0, q.size))
        self._clear = (d.distance[keep] - self.influence) if keep else np.zeros(0)
        # pairs beyond the band were skipped by the broad phase: they need to move at least `far - influence`
        self._travel = np.vstack([self._travel, self.world.reach[None, :]])
        self._clear = np.append(self._clear, far - self.influence)
        self.min_distance = float(d.distance[keep].min()) if keep else np.inf
        count = 0
        for k in keep:
            dist = float(d.distance[k])
            if dist >= self.influence or count >= self.max_rows:
                continue
            J = d.jacobian[k]
            gap = dist - self.margin
            rhs = self.gain * gap / ctx.dt
            if self.acceleration is not None and gap > 0:
                alpha = 0.5 * float(np.abs(J) @ self.acceleration)
                rhs = min(rhs, float(np.sqrt(2.0 * alpha * gap)))
            G[count] = -J
            h[count] = rhs
            count += 1
        return count
