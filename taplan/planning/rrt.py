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

The found path is then smoothed with the same fast test, at states ``SMOOTH_SPACING_SHARE · margin`` apart
(:func:`smooth_path`: the arms moved together instead of one after the other, shortcuts between points along the
path, corners blended, a B-spline; 0.05-0.3 s where the optimiser as a smoother took 0.5-2.5 s) and certified again
by the caller.

taplan's own implementation rather than OMPL's: the ``ompl`` wheel is a large binary dependency for one stage.
OMPL's RRT-Connect is the peer in ``benchmarks/bench_planning.py``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from taplan.planning.compiled_check import ClearanceCheck
from taplan.planning.verify import check_path, check_segment, check_segments
from taplan.scene.world import CollisionWorld

__all__ = [
    "rrt_connect",
    "rrt_connect_shrinking",
    "rrt_connect_groups",
    "shortcut",
    "certify_path",
    "smooth_path",
    "synchronise",
    "blend_corners",
    "spline_path",
]

STEP = 1.2  # [rad] longest extension of a tree toward a sample (max-norm over the moving joints)
SPACING_SHARE = 2.5  # tested states are at most this share of the margin of robot-point travel apart (module doc)
SHORTCUTS = 200  # shortcut attempts with the fast test (each a straight segment between two path points)
# the smoother's tested states are at most this share of the margin apart: coarser than the exploration's, since
# the smoothed path is certified (and on refusal the unsmoothed one is used). On the 60 blocked problems of the
# 39-suite and the hard set with the sampler forced (issue 22, /work/notes/s32/i22s-notes.md) 4 instead of 2.5
# tested a third fewer states (smoothing CPU -26 %) with every smoothed path certified and no duration longer by
# more than 2 % (sum -0.4 %); at 6, one smoothed path was refused and three durations were 8-18 % longer
SMOOTH_SPACING_SHARE = 4.0
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
    ``margin / 2`` too: the sampler's test already kept ``margin`` at its states): first the whole polyline as one
    curve (:func:`~taplan.planning.verify.check_path`: each vertex evaluated once, the edges split only where
    needed); when that refuses it, the edges in one batch, refused edges split in halves up to ``SPLITS`` deep. None
    when an edge still fails or ``deadline`` passes."""
    if len(path) >= 2 and check_path(world, np.array(path), margin, points=margin / 2, deadline=deadline).valid:
        return list(path)
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
    certify: bool = True,
) -> tuple[list[np.ndarray], float] | None:
    """(path, the margin it keeps): RRT-Connect at each of ``margins`` (widest first) in turn, ``shares[k]`` of the
    time left at margin ``k`` (the last margin: all of it), the trees growing on across margins; the path is
    shortcut and every edge certified to keep half its margin. None when ``max_time`` [s] runs out. Without
    ``certify`` the first path found is returned uncertified (its explored states passed the compiled test): the
    caller certifies what it keeps (a smoothed path, whose certificate then replaces this one's)."""
    rng = rng or np.random.default_rng(0)
    deadline = time.perf_counter() + max_time
    full = start.copy()
    lo, hi = lower[active], upper[active]
    search = _Connect(start[active], goal[active], step, rng)
    for k, margin in enumerate(margins):
        share = shares[k] if k < min(len(shares), len(margins) - 1) else 1.0
        until = time.perf_counter() + share * max(deadline - time.perf_counter(), 0.0)
        # the ends keep this margin on every pair (the sampler's test leaves out the pairs the moving joints do not
        # move): the compiled test over every pair, ~0.3 ms where the ends' exact distances took 2-5 ms
        ends = ClearanceCheck(world, margin)
        if not (ends(start) and ends(goal)):
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
            if not certify:
                return path, margin
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
    certify: bool = True,
) -> tuple[list[np.ndarray], float] | None:
    """(path, the margin it keeps): one group of joints after the other (an arm moves to its goal while the others
    hold), each by :func:`rrt_connect_shrinking` in its own joints, in the given order and then in the reverse
    order (half the time left each). Two 7-joint searches are much smaller than one 14-joint search: on the real
    body a two-arm cabinet or clutter problem that the joint search did not solve in 6 s was solved in 1-2 s this
    way. The path keeps the smaller of its parts' margins; every edge is certified as in
    :func:`rrt_connect_shrinking` (not without ``certify``). None when neither order finds one within ``max_time``
    [s]."""
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
                world,
                q,
                target,
                moving,
                lower,
                upper,
                margins,
                shares=shares,
                step=step,
                max_time=left,
                rng=rng,
                certify=certify,
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


def _arc_lengths(path: list[np.ndarray], joints: np.ndarray) -> np.ndarray:
    steps = [np.linalg.norm((b - a)[joints]) for a, b in zip(path[:-1], path[1:], strict=True)]
    return np.concatenate([[0.0], np.cumsum(steps)])


def _point_on(path: list[np.ndarray], s: np.ndarray, length: float) -> tuple[int, np.ndarray]:
    """(index of the segment, configuration) at arc length ``length`` (``s``: the vertices' arc lengths)."""
    k = int(np.clip(np.searchsorted(s, length, side="right") - 1, 0, len(path) - 2))
    span = s[k + 1] - s[k]
    t = 0.0 if span <= 0 else (length - s[k]) / span
    return k, path[k] + t * (path[k + 1] - path[k])


def _valid_path(valid_motion: Any, path: list[np.ndarray]) -> bool:
    return all(valid_motion(a, b) for a, b in zip(path[:-1], path[1:], strict=True))


def _dedupe(path: list[np.ndarray]) -> list[np.ndarray]:
    """``path`` without the configurations within 1e-9 rad (max-norm) of the one before them."""
    if len(path) < 2:
        return list(path)
    kept = np.abs(np.diff(np.array(path), axis=0)).max(axis=1) > 1e-9
    return [path[0]] + [q for q, keep in zip(path[1:], kept, strict=True) if keep]


def synchronise(valid_motion: Any, path: list[np.ndarray], groups: list[np.ndarray]) -> list[np.ndarray]:
    """The groups (e.g. the arms) moving at once, each along its own part of ``path`` at the same fraction of its
    own arc length (a path that moves one arm after the other becomes one that moves both together: the duration of
    the longer instead of the sum), when every new edge passes ``valid_motion``; else ``path``."""
    moving = [g for g in groups if _arc_lengths(path, g)[-1] > 0]
    if len(moving) < 2:
        return path
    P = np.array(path)
    fractions = []
    for g in moving:
        s = _arc_lengths(path, g)
        fractions.append(s / s[-1])
    u = np.unique(np.concatenate(fractions))
    out = np.repeat(P[:1], len(u), axis=0)
    for g, f in zip(moving, fractions, strict=True):
        keep = np.concatenate([[True], np.diff(f) > 0])  # the group's own vertices (where it moved)
        for j in g:
            out[:, j] = np.interp(u, f[keep], P[keep, j])
    candidate = _dedupe(list(out))
    return candidate if _valid_path(valid_motion, candidate) else path


def smooth_path(
    valid_motion: Any,
    path: list[np.ndarray],
    active: np.ndarray,
    groups: list[np.ndarray] = (),
    *,
    shortcuts: int = 40,
    blend: bool = True,
    spline: bool = True,
    rng: np.random.Generator | None = None,
    deadline: float = float("inf"),
) -> list[np.ndarray]:
    """Shorter and rounder, with the sampler's fast test only: the groups synchronised (:func:`synchronise`), then
    ``shortcuts`` tries between random points along the path (not only its vertices: OMPL's ``shortcutPath``), in
    all the active joints or, every other try, in one group's (a partial shortcut: the other joints keep their
    motion), each kept when shorter and every new edge passes ``valid_motion``, then (``blend``) the corners
    blended (:func:`blend_corners`) and (``spline``) the path made a B-spline (:func:`spline_path`). Nothing is
    certified here: the caller certifies the result."""
    rng = rng or np.random.default_rng(0)
    path = _dedupe([np.asarray(q, dtype=float) for q in path])
    groups = [np.asarray(g) for g in groups if np.size(g)]
    path = synchronise(valid_motion, path, groups)
    choices = [np.asarray(active)] + groups
    s = _arc_lengths(path, active)  # the path's arc lengths, again only when a shortcut changes it
    for attempt in range(shortcuts):
        if len(path) <= 2 or time.perf_counter() >= deadline:
            break
        joints = choices[0] if attempt % 2 == 0 or len(choices) == 1 else choices[int(rng.integers(1, len(choices)))]
        a_len, b_len = np.sort(rng.uniform(0.0, s[-1], 2))
        i, a = _point_on(path, s, a_len)
        j, b = _point_on(path, s, b_len)
        if i == j:
            continue
        if joints is choices[0]:
            middle: list[np.ndarray] = []
        else:  # the group goes straight from a to b, the others keep their vertices in between
            middle = []
            for k in range(i + 1, j + 1):
                q = path[k].copy()
                q[joints] = a[joints] + (s[k] - a_len) / (b_len - a_len) * (b[joints] - a[joints])
                middle.append(q)
        candidate = [a] + middle + [b]
        old = path[i + 1 : j + 1]
        before = _arc_lengths([a] + old + [b], active)[-1]
        if _arc_lengths(candidate, active)[-1] < before - 1e-6 and _valid_path(valid_motion, candidate):
            path = _dedupe(path[: i + 1] + candidate + path[j + 1 :])
            s = _arc_lengths(path, active)
    if blend:
        path = blend_corners(valid_motion, path, active, deadline=deadline)
    if spline and time.perf_counter() < deadline:
        path = spline_path(valid_motion, path, active)
    return path


BLEND_STEP = 0.05  # [rad] chord of a corner's blend (Euclidean over the active joints)
BLEND_TRIES = 3  # blend sizes tried per corner: the largest that fits, then halves


def blend_corners(
    valid_motion: Any, path: list[np.ndarray], active: np.ndarray, *, deadline: float = float("inf")
) -> list[np.ndarray]:
    """Every interior corner replaced by a parabolic blend (a quadratic Bezier curve from a point on the incoming
    edge through the corner's pull to a point on the outgoing edge, as chords ``BLEND_STEP`` long) where it passes
    ``valid_motion``: the largest that fits (half of each adjacent edge), else halved, else the corner stays.

    A corner of a polyline is a stop for the timing (the spline through the densified path turns within one
    0.1 rad step: its curvature caps the speed there); a blend of size ``d`` caps it at about ``sqrt(a d / θ)``."""
    if len(path) <= 2:
        return path
    P = [np.asarray(q, dtype=float) for q in path]
    lengths = [float(np.linalg.norm((b - a)[active])) for a, b in zip(P[:-1], P[1:], strict=True)]
    out = [P[0]]
    for k in range(1, len(P) - 1):
        before, corner, after = P[k - 1], P[k], P[k + 1]
        blended = False
        # half of each edge: the neighbouring corners' blends use the other halves
        size = 0.5 * min(lengths[k - 1], lengths[k])
        for _ in range(BLEND_TRIES if time.perf_counter() < deadline else 0):
            a = corner + size / lengths[k - 1] * (before - corner)
            b = corner + size / lengths[k] * (after - corner)
            count = max(2, int(np.ceil(2 * size / BLEND_STEP)))
            t = np.linspace(0.0, 1.0, count + 1)[:, None]
            curve = list((1 - t) ** 2 * a + 2 * t * (1 - t) * corner + t**2 * b)
            if _valid_path(valid_motion, curve):
                out += curve
                blended = True
                break
            size /= 2
        if not blended:
            out.append(corner)
    out.append(P[-1])
    return _dedupe(out)


SPLINE_SPACINGS = (0.8, 0.4, 0.2)  # [rad] control-point spacings tried for a smoothed path's B-spline, widest first
SPLINE_SAMPLES = 0.1  # [rad] at most this far apart (Euclidean) the spline is sampled into a polyline


def _bspline(control: np.ndarray, samples_per_span: int) -> np.ndarray:
    """Points of the uniform cubic B-spline of ``control`` (M, n), its ends repeated three times so that the curve
    starts and ends on them, ``samples_per_span`` points per span (the ends included)."""
    P = np.concatenate([control[:1], control[:1], control, control[-1:], control[-1:]])
    t = np.linspace(0.0, 1.0, samples_per_span + 1)[:-1]
    basis = np.stack([(1 - t) ** 3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1, t**3], axis=1) / 6
    spans = len(P) - 3
    window = P[np.arange(spans)[:, None] + np.arange(4)[None, :]]  # (spans, 4, n)
    points = np.einsum("sk,ckn->csn", basis, window).reshape(-1, P.shape[1])
    points[0] = control[0]  # exactly (the weights' sum rounds)
    return np.concatenate([points, control[-1:]])


def spline_path(valid_motion: Any, path: list[np.ndarray], active: np.ndarray) -> list[np.ndarray]:
    """The cubic B-spline whose control points are ``path`` resampled every ``SPLINE_SPACINGS[k]`` rad, sampled
    as a polyline, for the widest spacing whose every edge passes ``valid_motion``; else ``path``. A B-spline
    spreads each corner's turn over its control spacing (its curvature is continuous), which the timing needs: a
    polyline's corner is a near stop."""
    from taplan.planning.optimize import resample

    P = np.array(path)
    length = float(np.linalg.norm(np.diff(P[:, active], axis=0), axis=1).sum())
    for spacing in SPLINE_SPACINGS:
        count = int(np.ceil(length / spacing)) + 1
        if count < 3:
            continue
        moved = _bspline(resample(P[:, active], count), max(1, int(np.ceil(spacing / SPLINE_SAMPLES))))
        curve = np.repeat(P[:1], len(moved), axis=0)  # the joints that do not move keep their value exactly
        curve[:, active] = moved
        candidate = _dedupe(list(curve))
        if _valid_path(valid_motion, candidate):
            return candidate
    return path
