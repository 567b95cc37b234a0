"""A compact RRT-Connect (Kuffner & LaValle, 2000) in joint space, with certified edges, and path shortcutting.

taplan's own implementation rather than OMPL's: the ``ompl`` wheel is a large binary dependency for a fallback
stage, and its Python callbacks would call the same certified checks (:func:`~taplan.planning.verify.check_segment`)
anyway. OMPL's RRT-Connect is the peer in ``benchmarks/bench_planning.py``.
"""

from __future__ import annotations

import time

import numpy as np

from taplan.planning.verify import check_segment
from taplan.scene.world import CollisionWorld

__all__ = ["rrt_connect", "shortcut"]


class _Tree:
    def __init__(self, root: np.ndarray) -> None:
        self.nodes = [root]
        self.parents = [-1]
        self._array = root[None, :].copy()

    def nearest(self, q: np.ndarray) -> int:
        return int(np.argmin(np.abs(self._array - q).max(axis=1)))

    def add(self, q: np.ndarray, parent: int) -> int:
        self.nodes.append(q)
        self.parents.append(parent)
        self._array = np.vstack([self._array, q])
        return len(self.nodes) - 1

    def path_to_root(self, index: int) -> list[np.ndarray]:
        out = []
        while index >= 0:
            out.append(self.nodes[index])
            index = self.parents[index]
        return out


def rrt_connect(
    world: CollisionWorld,
    start: np.ndarray,
    goal: np.ndarray,
    active: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    margin: float,
    *,
    step: float = 0.3,
    max_time: float = 10.0,
    rng: np.random.Generator | None = None,
) -> list[np.ndarray] | None:
    """A collision-free path (list of configurations) from ``start`` to ``goal`` moving only the ``active`` joints
    (indices), with every edge certified to keep ``margin / 2``; None when ``max_time`` [s] runs out."""
    rng = rng or np.random.default_rng(0)
    trees = (_Tree(start.copy()), _Tree(goal.copy()))
    start_tree = trees[0]
    deadline = time.perf_counter() + max_time

    def steer(tree: _Tree, target: np.ndarray) -> tuple[int, bool]:
        """Extend toward target by at most ``step`` (max-norm); returns (new node or -1, reached target)."""
        near = tree.nearest(target)
        q_near = tree.nodes[near]
        delta = target - q_near
        length = float(np.abs(delta).max())
        reached = length <= step
        q_new = target if reached else q_near + delta * (step / length)
        if not check_segment(world, q_near, q_new, margin).valid:
            return -1, False
        return tree.add(q_new, near), reached

    while time.perf_counter() < deadline:
        sample = start.copy()
        sample[active] = rng.uniform(lower[active], upper[active])
        a, b = trees
        new, _ = steer(a, sample)
        if new >= 0:
            target = a.nodes[new]
            while time.perf_counter() < deadline:  # connect: extend the other tree toward the new node
                other, reached = steer(b, target)
                if other < 0:
                    break
                if reached:
                    first = a.path_to_root(new)[::-1]
                    second = b.path_to_root(other)
                    path = first + second[1:]
                    return path if a is start_tree else path[::-1]
        trees = (trees[1], trees[0])
    return None


def shortcut(
    world: CollisionWorld,
    path: list[np.ndarray],
    margin: float,
    attempts: int = 60,
    rng: np.random.Generator | None = None,
    deadline: float = float("inf"),
) -> list[np.ndarray]:
    """Remove detours: replace sub-paths by straight segments that are certified collision-free (at most
    ``attempts`` tries, none started after ``deadline``, a ``time.perf_counter()`` value)."""
    rng = rng or np.random.default_rng(0)
    path = list(path)
    for _ in range(attempts):
        if len(path) <= 2 or time.perf_counter() >= deadline:
            break
        i, j = sorted(rng.choice(len(path), size=2, replace=False))
        if j - i < 2:
            continue
        if check_segment(world, path[i], path[j], margin).valid:
            path = path[: i + 1] + path[j:]
    return path
