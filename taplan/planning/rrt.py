"""RRT-Connect (Kuffner & LaValle, 2000) in the joints that move: explored with a fast compiled clearance test,
shortcut, then certified edge by edge.

Exploration is where a sampler spends its budget: thousands of configurations. Each is tested with
:class:`~taplan.planning.compiled_check.ClearanceCheck` (pinocchio + coal with a security margin, ~0.01-0.1 ms, the
pairs the moving joints move) at states no more than ``SPACING_SHARE · margin`` of robot-point travel apart (bound
``Σ reach_j |Δq_j|``), so the planner explores at the speed of a compiled validity check (OMPL's users' setup)
instead of one Python distance evaluation (milliseconds) per state. The spacing (2.5 x the margin) cannot step over
an obstacle of 2 cm or thicker (the band a state may not enter is the obstacle plus the margin on both sides). It
does not by itself keep ``margin / 2`` between the tested states, but the travel bound is loose (the sum of every
joint's longest lever): on the issue-27 suite on the real body every sampled path at 3.2 x the margin passed the
certificate, with 2-4 times fewer tests than at 0.8 x. The certificate has the last word: the found path is shortcut
with the same test and then every edge certified by conservative advancement
(:func:`~taplan.planning.verify.check_segment`) to keep ``margin / 2``; a refused edge is split and certified in
halves, and a path that still fails is dropped and the search goes on.

taplan's own implementation rather than OMPL's: the ``ompl`` wheel is a large binary dependency for one stage.
OMPL's RRT-Connect is the peer in ``benchmarks/bench_planning.py``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from taplan.planning.compiled_check import ClearanceCheck
from taplan.planning.verify import check_segment, check_segments
from taplan.scene.world import CollisionWorld

__all__ = ["rrt_connect", "rrt_connect_shrinking", "rrt_connect_groups", "shortcut", "certify_path"]

STEP = 1.2  # [rad] longest extension of a tree toward a sample (max-norm over the moving joints)
SPACING_SHARE = 2.5  # tested states are at most this share of the margin of robot-point travel apart (module doc)
SHORTCUTS = 200  # shortcut attempts with the fast test (each a straight segment between two path points)
SPLITS = 3  # an edge the certificate refuses is split in halves at most this deep


class _Tree:
    """Nodes in the moving joints, in a growing array (nearest neighbour by the max-norm, vectorised)."""

    def __init__(self, root: np.ndarray) -> None:
        self.nodes = np.empty((256, root.size))
        self.nodes[0] = root
        self.parents = [-1]

    def __len__(self) -> int:
        return len(self.parents)

    def nearest(self, q: np.ndarray) -> int:
        return int(np.argmin(np.abs(self.nodes[: len(self)] - q).max(axis=1)))

    def add(self, q: np.ndarray, parent: int) -> int:
        n = len(self)
        if n == len(self.nodes):
            self.nodes = np.vstack([self.nodes, np.empty_like(self.nodes)])
        self.nodes[n] = q
        self.parents.append(parent)
        return n

    def path_to_root(self, index: int) -> list[np.ndarray]:
        out = []
        while index >= 0:
            out.append(self.nodes[index].copy())
            index = self.parents[index]
        return out


class _Connect:
    """RRT-Connect's two trees in the moving joints; :meth:`grow` extends them until they meet. The trees outlive a
    call: a state that kept a wider clearance keeps a narrower one, so a search that shrinks its clearance goes on
    from what it explored."""

    def __init__(self, start: np.ndarray, goal: np.ndarray, step: float, rng: np.random.Generator) -> None:
        self.trees = (_Tree(start), _Tree(goal))
        self.start_tree = self.trees[0]
        self.step = step
        self.rng = rng

    def _steer(self, tree: _Tree, target: np.ndarray, valid_motion: Any) -> tuple[int, bool]:
        """Extend toward ``target`` by at most ``step`` (max-norm); (new node or -1, target reached)."""
        near = tree.nearest(target)
        q_near = tree.nodes[near]
        delta = target - q_near
        length = float(np.abs(delta).max())
        reached = length <= self.step
        q_new = target.copy() if reached else q_near + delta * (self.step / length)
        if not valid_motion(q_near, q_new):
            return -1, False
        return tree.add(q_new, near), reached

    def grow(self, valid_motion: Any, lower: np.ndarray, upper: np.ndarray, deadline: float) -> list[np.ndarray] | None:
        """A path from the start to the goal whose motions passed ``valid_motion(a, b)``, or None at
        ``deadline``."""
        while time.perf_counter() < deadline:
            a, b = self.trees
            new, _ = self._steer(a, self.rng.uniform(lower, upper), valid_motion)
            if new >= 0:
                target = a.nodes[new].copy()
                while time.perf_counter() < deadline:  # connect: extend the other tree toward the new node
                    other, reached = self._steer(b, target, valid_motion)
                    if other < 0:
                        break
                    if reached:
                        path = a.path_to_root(new)[::-1] + b.path_to_root(other)[1:]
                        return path if a is self.start_tree else path[::-1]
            self.trees = (self.trees[1], self.trees[0])
        return None


def _fast_shortcut(
    valid_motion: Any, path: list[np.ndarray], attempts: int, rng: np.random.Generator, deadline: float
) -> list[np.ndarray]:
    """Replace sub-paths by straight segments that pass ``valid_motion`` (random pairs of path points)."""
    path = list(path)
    for _ in range(attempts):
        if len(path) <= 2 or time.perf_counter() >= deadline:
            break
        i, j = sorted(rng.choice(len(path), size=2, replace=False))
        if j - i >= 2 and valid_motion(path[i], path[j]):
            path = path[: i + 1] + path[j:]
    return path


def certify_path(
    world: CollisionWorld, path: list[np.ndarray], margin: float, deadline: float = float("inf")
) -> list[np.ndarray] | None:
    """``path`` (full configurations) with every edge certified to keep ``margin / 2`` (its points evaluated at
    ``margin / 2`` too: the sampler's test already kept ``margin`` at its states), all edges in one batch; refused
    edges are split in halves up to ``SPLITS`` deep. None when an edge still fails or ``deadline`` passes."""
    edges = [(a, b) for a, b in zip(path[:-1], path[1:], strict=True)]
    for _ in range(SPLITS + 1):
        if time.perf_counter() >= deadline:
            return None
        starts, ends = np.array([a for a, _ in edges]), np.array([b for _, b in edges])
        checks = check_segments(world, starts, ends, margin, points=margin / 2, deadline=deadline)
        if all(c.valid for c in checks):
            return [edges[0][0]] + [b for _, b in edges]
        refined = []
        for (a, b), c in zip(edges, checks, strict=True):
            refined += [(a, (a + b) / 2), ((a + b) / 2, b)] if not c.valid else [(a, b)]
        edges = refined
    return None


def rrt_connect(
    world: CollisionWorld,
    start: np.ndarray,
    goal: np.ndarray,
    active: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    margin: float,
    *,
    step: float = STEP,
    max_time: float = 10.0,
    rng: np.random.Generator | None = None,
) -> list[np.ndarray] | None:
    """A path (list of configurations) from ``start`` to ``goal`` moving only the ``active`` joints (indices),
    shortcut, with every edge certified to keep ``margin / 2``; None when ``max_time`` [s] runs out."""
    found = rrt_connect_shrinking(
        world, start, goal, active, lower, upper, (margin,), step=step, max_time=max_time, rng=rng
    )
    return None if found is None else found[0]


def rrt_connect_shrinking(
    world: CollisionWorld,
    start: np.ndarray,
    goal: np.ndarray,
    active: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    margins: tuple[float, ...],
    *,
    shares: tuple[float, ...] = (),
    step: float = STEP,
    max_time: float = 10.0,
    rng: np.random.Generator | None = None,
) -> tuple[list[np.ndarray], float] | None:
    """(path, the margin it keeps): RRT-Connect at each of ``margins`` (widest first) in turn, ``shares[k]`` of the
    time left at margin ``k`` (the last margin: all of it), the trees growing on across margins; the path is
    shortcut and every edge certified to keep half its margin. None when ``max_time`` [s] runs out."""
    rng = rng or np.random.default_rng(0)
    deadline = time.perf_counter() + max_time
    full = start.copy()
    lo, hi = lower[active], upper[active]
    search = _Connect(start[active], goal[active], step, rng)
    # the ends' clearance over every pair (the sampler's test leaves out the pairs the moving joints do not move)
    ends = min(world.min_distance(start)[0], world.min_distance(goal)[0])
    for k, margin in enumerate(margins):
        share = shares[k] if k < min(len(shares), len(margins) - 1) else 1.0
        until = time.perf_counter() + share * max(deadline - time.perf_counter(), 0.0)
        if ends < margin:
            continue  # an end inside this margin: no tree grows from it, the next margin gets the time
        check = ClearanceCheck(world, margin, active)
        spacing = SPACING_SHARE * margin

        def valid_motion(a: np.ndarray, b: np.ndarray, check: ClearanceCheck = check, spacing: float = spacing) -> bool:
            qa, qb = full.copy(), full.copy()
            qa[active], qb[active] = a, b
            return check.motion(qa, qb, spacing)

        while time.perf_counter() < until:
            found = search.grow(valid_motion, lo, hi, until)
            if found is None:
                break
            found = _fast_shortcut(valid_motion, found, SHORTCUTS, rng, deadline)
            path = []
            for x in found:
                q = full.copy()
                q[active] = x
                path.append(q)
            path[0], path[-1] = start.copy(), goal.copy()
            certified = certify_path(world, path, margin, deadline)
            if certified is not None:
                return certified, margin
            search = _Connect(start[active], goal[active], step, rng)  # the trees met through an uncertified edge
    return None


def rrt_connect_groups(
    world: CollisionWorld,
    start: np.ndarray,
    goal: np.ndarray,
    groups: list[np.ndarray],
    lower: np.ndarray,
    upper: np.ndarray,
    margins: tuple[float, ...],
    *,
    shares: tuple[float, ...] = (),
    step: float = STEP,
    max_time: float = 10.0,
    rng: np.random.Generator | None = None,
) -> tuple[list[np.ndarray], float] | None:
    """(path, the margin it keeps): one group of joints after the other (an arm moves to its goal while the others
    hold), each by :func:`rrt_connect_shrinking` in its own joints, in the given order and then in the reverse
    order (half the time left each). Two 7-joint searches are much smaller than one 14-joint search: on the real
    body a two-arm cabinet or clutter problem that the joint search did not solve in 6 s was solved in 1-2 s this
    way. The path keeps the smaller of its parts' margins; every edge is certified as in
    :func:`rrt_connect_shrinking`. None when neither order finds one within ``max_time`` [s]."""
    rng = rng or np.random.default_rng(0)
    deadline = time.perf_counter() + max_time
    orders = (groups, groups[::-1])
    for k, order in enumerate(orders):
        until = time.perf_counter() + max(deadline - time.perf_counter(), 0.0) / (len(orders) - k)
        q, path, kept = start.copy(), [start.copy()], np.inf
        for n, group in enumerate(order):
            target = q.copy()
            target[group] = goal[group]
            moving = group[np.abs(target[group] - q[group]) > 1e-12]
            if moving.size == 0:
                continue
            left = max(until - time.perf_counter(), 0.0) / (len(order) - n)  # the later parts get what is not used
            found = rrt_connect_shrinking(
                world, q, target, moving, lower, upper, margins, shares=shares, step=step, max_time=left, rng=rng
            )
            if found is None:
                break
            path += found[0][1:]
            kept = min(kept, found[1])
            q = target
        else:
            return path, float(kept)
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
