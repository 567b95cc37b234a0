"""Occupied space as voxels: a mutable grid that images and point clouds fill, and the obstacle it becomes.

:class:`OccupancyGrid` is the map: a dense boolean grid over a box of the robot's root frame (``bounds``) at a
``resolution`` [m]. Points are inserted (outside the bounds they are counted and dropped); a later depth image clears
the occupied voxels whose centre it sees through (:meth:`OccupancyGrid.clear_seen_through`), and with ``decay`` [s]
voxels not seen again for that long are dropped.

Inside a ``region`` box (the workspace) the grid also keeps which voxels are *known free*: a depth image sees past
the voxel's centre (:meth:`OccupancyGrid.mark_seen_free`), or the robot's own bodies stood there
(:meth:`OccupancyGrid.mark_free`). Every other voxel of the region that is not occupied is *unknown*
(:meth:`OccupancyGrid.unknown_snapshot`). Of those it also keeps which were ever inside an image's view
(``viewed``) and which lay behind a surface an image saw (``shadowed``): the unknown voxels never viewed or
shadowed are ``unknown_snapshot("occluded")``; the others were viewed only through pixels that measured nothing or
that the caller ignores (the robot's own bodies).

:class:`Occupancy` is a snapshot of the map as a scene shape: every occupied voxel is an axis-aligned box of edge
``resolution`` in the obstacle's frame. :class:`~taplan.scene.CollisionWorld` asks it for capsule distances
(:meth:`Occupancy.capsule_distances`): per robot body the exact distance to the nearest voxel box, or a lower bound
where the caller says one is enough (beyond ``cutoff`` / ``bound_beyond``). The voxels' surface
(:class:`~taplan.scene.voxel_surface.VoxelSurface`: the occupied voxels with a free face neighbour, a coarse
distance field and a k-d tree of their centres) bounds every capsule from below in a few lookups and gives the exact
distance of the near ones from the few surface voxels around them. An exact distance asked of a far capsule goes
through the merged boxes instead: the voxels merged into larger boxes covering exactly the same space
(:func:`merge_voxels`: runs along z, then equal runs along y, then along x; a table top of 50,000 voxels becomes a
handful of boxes), grouped by the 8x8x8-voxel block of their centre for a broad phase: each block's tight bounding
box gives a lower bound, the exact distance to the block's largest box an upper bound, and only blocks whose lower
bound is under the best upper bound are opened. A segment's distance to a box is found exactly: the squared
distance is piecewise quadratic in the segment parameter between the (at most six) face crossings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from taplan.errors import InvalidInputError
from taplan.scene.shapes import Shape
from taplan.scene.voxel_surface import VoxelSurface

__all__ = [
    "Occupancy",
    "OccupancyGrid",
    "segment_box_distance",
    "merge_voxels",
    "DEFAULT_BOUNDS",
    "DEFAULT_RESOLUTION",
]

DEFAULT_RESOLUTION = 0.02  # [m]
# the TeleAvatar's reach in its root frame (shoulder base), with room: x forward, y left, z up [m]
DEFAULT_BOUNDS = ((-0.6, -1.2, -1.0), (1.4, 1.2, 1.0))
BLOCK = 8  # voxels per block edge in the broad phase
NEAR = 0.2  # [m] exact distances asked of capsules farther than this come from the blocks, not the surface


def _bounds(bounds: Any) -> tuple[np.ndarray, np.ndarray]:
    try:
        lo, hi = (np.asarray(b, dtype=float).reshape(3) for b in bounds)
    except (TypeError, ValueError):
        raise InvalidInputError("bounds", bounds, "((x, y, z) low, (x, y, z) high) [m]") from None
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
        raise InvalidInputError("bounds", bounds, "finite corners with high > low on every axis [m]")
    return lo, hi


def _resolution(resolution: Any) -> float:
    if isinstance(resolution, bool) or not isinstance(resolution, (int, float)) or not 0.001 <= resolution <= 0.5:
        raise InvalidInputError("resolution", resolution, "a voxel edge in [0.001, 0.5] m")
    return float(resolution)


def segment_box_distance(
    start: np.ndarray, end: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact distances between segments ``[start, end]`` and axis-aligned boxes ``[lo, hi]`` (all (N, 3)).

    Returns (distance (N,), closest point on the segment (N, 3), closest point of the box (N, 3)); distance 0 when
    the segment meets the box. The squared distance ``Σ_i max(lo_i − p_i, 0, p_i − hi_i)²`` along ``p(t)`` is a
    quadratic between consecutive face crossings; each piece is minimised in closed form.
    """
    u = end - start
    with np.errstate(divide="ignore", invalid="ignore"):
        crossings = np.concatenate([(lo - start) / u, (hi - start) / u], axis=1)  # (N, 6)
    crossings = np.where(np.isfinite(crossings), crossings, 0.0)
    t = np.sort(np.clip(np.concatenate([np.zeros((len(u), 1)), np.ones((len(u), 1)), crossings], axis=1), 0, 1))
    t0, t1 = t[:, :-1], t[:, 1:]  # (N, 7) pieces
    mid = start[:, None, :] + ((t0 + t1) / 2)[:, :, None] * u[:, None, :]
    below, above = mid < lo[:, None, :], mid > hi[:, None, :]
    # on a piece, each axis contributes (alpha + beta t)^2 or nothing
    alpha = np.where(below, (lo - start)[:, None, :], np.where(above, (start - hi)[:, None, :], 0.0))
    beta = np.where(below, -u[:, None, :], np.where(above, u[:, None, :], 0.0))
    A = np.einsum("npk,npk->np", beta, beta)
    B = np.einsum("npk,npk->np", alpha, beta)
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = np.where(A > 0, -B / A, t0)
    ts = np.clip(vertex, t0, t1)
    value = np.einsum("npk,npk->np", alpha + beta * ts[:, :, None], alpha + beta * ts[:, :, None])
    best = ts[np.arange(len(u)), np.argmin(value, axis=1)]
    p = start + best[:, None] * u
    q = np.clip(p, lo, hi)
    return np.linalg.norm(p - q, axis=1), p, q


def _runs(keys: np.ndarray, position: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Group rows sorted by (``keys``, ``position``) into runs of equal keys and consecutive positions; returns the
    run index of every row."""
    if not len(position):
        return np.zeros(0, dtype=np.int64)
    new = np.ones(len(position), dtype=bool)
    new[1:] = np.any(keys[1:] != keys[:-1], axis=1) | (start[1:] != end[:-1])
    return np.cumsum(new) - 1


def merge_voxels(voxels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boxes covering exactly the voxels (N, 3): their low corners and exclusive high corners (M, 3) in voxel
    indices. Greedy, axis by axis: runs along z, runs of equal z-runs along y, runs of equal yz-rectangles along x."""
    v = np.asarray(voxels, dtype=np.int64).reshape(-1, 3)
    if not len(v):
        return np.zeros((0, 3), np.int64), np.zeros((0, 3), np.int64)
    lo, hi = v.copy(), v + 1
    for axis in (2, 1, 0):
        others = [k for k in range(3) if k != axis]
        keys = np.column_stack([lo[:, others], hi[:, others]])
        order = np.lexsort((lo[:, axis], *keys.T[::-1]))
        lo, hi, keys = lo[order], hi[order], keys[order]
        run = _runs(keys, lo[:, axis], lo[:, axis], hi[:, axis])
        first = np.flatnonzero(np.r_[True, run[1:] != run[:-1]])
        last = np.r_[first[1:], len(run)] - 1
        new_lo, new_hi = lo[first].copy(), hi[first].copy()
        new_hi[:, axis] = hi[last, axis]
        lo, hi = new_lo, new_hi
    return lo, hi


@dataclass(frozen=True, eq=False)
class Occupancy(Shape):
    """Occupied voxels as an obstacle shape: voxel ``(i, j, k)`` is the box ``origin + [i, i+1) * resolution`` (per
    axis) in the obstacle's frame.

    Attributes:
        resolution: Voxel edge [m].
        origin: The grid's corner [m]. Shape (3,).
        voxels: Occupied voxel indices. Shape (N, 3), int.
    """

    resolution: float
    origin: np.ndarray = field(repr=False)
    voxels: np.ndarray = field(repr=False)
    kind = "occupancy"

    def __post_init__(self) -> None:
        object.__setattr__(self, "resolution", _resolution(self.resolution))
        origin = np.asarray(self.origin, dtype=float).reshape(-1)
        if origin.shape != (3,) or not np.all(np.isfinite(origin)):
            raise InvalidInputError("origin", self.origin, "a finite grid corner (x, y, z) [m]")
        voxels = np.asarray(self.voxels)
        if voxels.size == 0:
            voxels = np.zeros((0, 3), dtype=np.int64)
        if voxels.ndim != 2 or voxels.shape[1] != 3 or not np.issubdtype(voxels.dtype, np.integer):
            raise InvalidInputError("voxels", f"shape {voxels.shape} {voxels.dtype}", "(N, 3) integer indices")
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "voxels", voxels.astype(np.int64))
        object.__setattr__(self, "_lo", origin + self.voxels * self.resolution)
        # the surface index answers the queries; the merged boxes and their blocks are built when first needed
        surface = VoxelSurface(self.resolution, origin, self.voxels) if len(self.voxels) else None
        object.__setattr__(self, "_surface", surface)
        object.__setattr__(self, "_blocks_built", False)

    def _build_blocks(self) -> None:
        """Merge the voxels into boxes, group the boxes by the block of their centre, and keep per block its box
        range, tight bounding box and largest box (once)."""
        if self._blocks_built:
            return
        object.__setattr__(self, "_blocks_built", True)
        h = self.resolution
        lo_index, hi_index = merge_voxels(self.voxels)
        block = (lo_index + hi_index) // (2 * BLOCK)
        order = np.lexsort((block[:, 2], block[:, 1], block[:, 0]))
        lo_index, hi_index, block = lo_index[order], hi_index[order], block[order]
        change = np.flatnonzero(np.any(np.diff(block, axis=0) != 0, axis=1)) + 1 if len(block) else np.zeros(0, int)
        starts = np.concatenate([[0], change]).astype(int) if len(block) else np.zeros(0, int)
        box_lo, box_hi = self.origin + lo_index * h, self.origin + hi_index * h
        counts = np.diff(np.append(starts, len(box_lo))).astype(int)
        if len(starts):
            block_lo = np.minimum.reduceat(box_lo, starts, axis=0)
            block_hi = np.maximum.reduceat(box_hi, starts, axis=0)
            volume = np.prod(hi_index - lo_index, axis=1)
            owner = np.repeat(np.arange(len(starts)), counts)
            # the largest box of each block: its exact distance bounds the block's from above
            best = np.lexsort((-volume, owner))
            representative = best[np.r_[0, np.cumsum(counts)[:-1]]]
        else:
            block_lo = block_hi = np.zeros((0, 3))
            representative = np.zeros(0, int)
        object.__setattr__(self, "_block_centre", (block_lo + block_hi) / 2)
        object.__setattr__(self, "_block_radius", np.linalg.norm(block_hi - block_lo, axis=1) / 2)
        object.__setattr__(self, "_box_lo", box_lo)
        object.__setattr__(self, "_box_hi", box_hi)
        object.__setattr__(self, "_starts", starts)
        object.__setattr__(self, "_counts", counts)
        object.__setattr__(self, "_block_lo", block_lo)
        object.__setattr__(self, "_block_hi", block_hi)
        object.__setattr__(self, "_representative", representative)

    def merged_boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """The merged boxes ``(lo, hi)`` [m] (M, 3) in the obstacle frame: exactly the occupied space."""
        self._build_blocks()
        return self._box_lo, self._box_hi

    def __len__(self) -> int:
        return len(self.voxels)

    def centers(self) -> np.ndarray:
        """Voxel centres [m] in the obstacle frame. Shape (N, 3)."""
        return self._lo + self.resolution / 2

    def boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """Per voxel its box ``(lo, hi)`` [m] in the obstacle frame; each (N, 3)."""
        return self._lo, self._lo + self.resolution

    def contains(self, points: npt.ArrayLike) -> np.ndarray:
        """Whether each point (P, 3) [m, obstacle frame] lies in an occupied voxel (a lookup in the voxels' dense
        grid: no octree to build)."""
        P = np.asarray(points, dtype=float).reshape(-1, 3)
        if self._surface is None:
            return np.zeros(len(P), dtype=bool)
        return self._surface.inside(P)

    def to_coal(self) -> Any:
        """A coal octree of the voxel centres at this resolution (for coal-side queries and comparison)."""
        import coal

        if not len(self.voxels):
            raise InvalidInputError("voxels", "an empty occupancy", "at least one voxel for a coal octree")
        return coal.makeOctree(self.centers(), self.resolution)

    def to_dict(self) -> dict[str, Any]:
        return {
            "type": "occupancy",
            "resolution": self.resolution,
            "origin": self.origin.tolist(),
            "voxels": self.voxels.tolist(),
        }

    def bounding_radius(self) -> float:
        if not len(self.voxels):
            return 0.0
        corners = np.concatenate([self._lo, self._lo + self.resolution])
        return float(np.max(np.linalg.norm(corners, axis=1)))

    def capsule_distances(
        self,
        starts: np.ndarray,
        ends: np.ndarray,
        radii: np.ndarray,
        cutoff: float = math.inf,
        bound_beyond: float = math.inf,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per capsule (segments ``starts``-``ends`` (C, 3) in the obstacle frame, ``radii`` (C,)) its signed
        distance [m] to the nearest voxel box, witness points on the capsule and on the box, and the unit normal
        from the box to the capsule.

        Capsules farther than ``cutoff`` report a lower bound above it; capsules farther than ``bound_beyond``
        report a lower bound of their distance. A capsule whose axis enters a voxel reports ``-radius`` (in
        collision; the depth is not computed). No voxels: ``inf`` for every capsule.

        The voxels' surface (:class:`~taplan.scene.voxel_surface.VoxelSurface`) bounds every capsule and answers
        the near ones exactly; capsules it leaves open (an exact distance asked for a far capsule), and every
        capsule when the limit is beyond ``NEAR`` (no cutoff: all exact), go through the merged boxes' block broad
        phase.
        """
        starts, ends = np.asarray(starts, dtype=float), np.asarray(ends, dtype=float)
        radii = np.asarray(radii, dtype=float)
        C = len(starts)
        if self._surface is None or not C:
            return np.full(C, np.inf), starts.copy(), starts.copy(), np.tile([0.0, 0.0, 1.0], (C, 1))
        if min(cutoff, bound_beyond) > NEAR:  # exact distances far out: the blocks are cheaper than the surface
            return self._block_distances(starts, ends, radii, math.inf, bound_beyond)
        d, pa, pb, n, _, unresolved = self._surface.capsules(starts, ends, radii, min(cutoff, bound_beyond), NEAR)
        rows = np.flatnonzero(unresolved)
        if len(rows):
            # exact (a bound near the limit from the blocks could exceed the distance)
            d[rows], pa[rows], pb[rows], n[rows] = self._block_distances(starts[rows], ends[rows], radii[rows])
        return d, pa, pb, n

    def capsules_clear(self, starts: np.ndarray, ends: np.ndarray, radii: np.ndarray, clearance: float) -> np.ndarray:
        """Per capsule (as in :meth:`capsule_distances`) whether its distance is at least ``clearance`` [m]: the
        surface's lower bounds settle most capsules; the others get their exact distance."""
        starts, ends = np.asarray(starts, dtype=float), np.asarray(ends, dtype=float)
        radii = np.asarray(radii, dtype=float)
        if self._surface is None or not len(starts):
            return np.ones(len(starts), dtype=bool)
        clear, undecided = self._surface.clear(starts, ends, radii, clearance)
        rows = np.flatnonzero(undecided)
        if len(rows):
            d = self.capsule_distances(starts[rows], ends[rows], radii[rows], cutoff=clearance)[0]
            clear[rows] = d >= clearance
        return clear

    def _block_distances(
        self,
        starts: np.ndarray,
        ends: np.ndarray,
        radii: np.ndarray,
        cutoff: float = math.inf,
        bound_beyond: float = math.inf,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`capsule_distances` through the merged boxes grouped by 8x8x8-voxel blocks (see the module)."""
        self._build_blocks()
        C = len(starts)
        d = np.full(C, np.inf)
        pa = np.array(starts, dtype=float)
        pb = np.array(starts, dtype=float)
        n = np.tile([0.0, 0.0, 1.0], (C, 1))
        K = len(self._starts)
        if not K or not C:
            return d, pa, pb, n
        # broad phase 1: bounding spheres of capsules and blocks (a cheap lower bound for every pair), and a first
        # upper bound per capsule: the exact distance to the largest box of the block nearest its centre
        centre = (starts + ends) / 2
        reach = np.linalg.norm(ends - starts, axis=1) / 2 + radii
        between = np.linalg.norm(centre[:, None, :] - self._block_centre[None, :, :], axis=2)
        sphere = between - reach[:, None] - self._block_radius[None, :]
        rep0 = self._representative[np.argmin(between - self._block_radius[None, :], axis=1)]
        gap0, p0, q0 = segment_box_distance(starts, ends, self._box_lo[rep0], self._box_hi[rep0])
        threshold = np.minimum(gap0 - radii, cutoff)
        # broad phase 2: the pairs the spheres cannot rule out, against the blocks' tight boxes (lower bound) and
        # their largest boxes (upper bound)
        # (beyond ``bound_beyond`` a lower bound is enough: blocks whose sphere is farther stay unopened, and their
        # sphere bound caps the answer so it never exceeds the distance to a block left unopened)
        examine = sphere <= np.minimum(threshold, bound_beyond)[:, None]
        unopened = np.where(examine, np.inf, sphere).min(axis=1)
        rows, blocks = np.nonzero(examine)
        gap, p, q = segment_box_distance(starts[rows], ends[rows], self._block_lo[blocks], self._block_hi[blocks])
        lower = gap - radii[rows]
        rep = self._representative[blocks]
        upper = segment_box_distance(starts[rows], ends[rows], self._box_lo[rep], self._box_hi[rep])[0] - radii[rows]
        np.minimum.at(threshold, rows, upper)
        nearest = np.where(np.isin(np.arange(C), rows), np.inf, sphere.min(axis=1))
        np.minimum.at(nearest, rows, lower)
        bounded = (nearest > threshold) | (nearest > bound_beyond)
        if np.any(bounded):
            # a lower bound; witnesses of the nearest pair examined (or of the first upper bound)
            order = np.lexsort((lower, rows))
            head = order[np.r_[True, rows[order][1:] != rows[order][:-1]]] if len(rows) else order
            best = np.full(C, -1)
            best[rows[head]] = head
            out = np.flatnonzero(bounded)
            d[out] = nearest[out]
            has = best[out] >= 0
            pa[out[has]], pb[out[has]] = p[best[out[has]]], q[best[out[has]]]
            pa[out[~has]], pb[out[~has]] = p0[out[~has]], q0[out[~has]]
            n[out] = _unit(pa[out] - pb[out])
            pa[out] -= radii[out, None] * n[out]
        keep = (lower <= threshold[rows]) & ~bounded[rows]
        rows, blocks = rows[keep], blocks[keep]
        if not len(rows):
            return d, pa, pb, n
        d = self._narrow(starts, ends, radii, rows, blocks, d, pa, pb, n)
        exact = ~bounded
        d[exact] = np.minimum(d[exact], unopened[exact])
        return d, pa, pb, n

    def _narrow(
        self,
        starts: np.ndarray,
        ends: np.ndarray,
        radii: np.ndarray,
        rows: np.ndarray,
        blocks: np.ndarray,
        d: np.ndarray,
        pa: np.ndarray,
        pb: np.ndarray,
        n: np.ndarray,
    ) -> np.ndarray:
        """The exact nearest merged box of each capsule among its candidate ``blocks`` (pairs with ``rows``);
        fills ``d``, ``pa``, ``pb``, ``n`` of those capsules."""
        # narrow phase: the merged boxes of the candidate blocks, capsule-major
        counts = self._counts[blocks]
        owner = np.repeat(rows, counts)
        first = np.repeat(self._starts[blocks] - np.cumsum(counts) + counts, counts)
        box = first + np.arange(counts.sum())
        lo, hi = self._box_lo[box], self._box_hi[box]
        gap, p, q = segment_box_distance(starts[owner], ends[owner], lo, hi)
        value = gap - radii[owner]
        order = np.lexsort((value, owner))
        head = order[np.concatenate([[True], np.diff(owner[order]) != 0])]
        c = owner[head]
        d[c] = value[head]
        inside = gap[head] <= 1e-12
        normal = _unit(p[head] - q[head])
        centre = (lo[head] + hi[head]) / 2
        normal[inside] = _unit(p[head][inside] - centre[inside])
        n[c] = normal
        pb[c] = q[head]
        pa[c] = p[head] - radii[c, None] * normal
        return d


def _nearest_around(depth: np.ndarray) -> np.ndarray:
    """Per pixel the smallest valid depth of its 3x3 neighbourhood (NaN where none is valid): separable, and
    ``fmin`` skips NaN."""
    row = depth.copy()
    np.fmin(row[:, 1:], depth[:, :-1], out=row[:, 1:])
    np.fmin(row[:, :-1], depth[:, 1:], out=row[:, :-1])
    out = row.copy()
    np.fmin(out[1:], row[:-1], out=out[1:])
    np.fmin(out[:-1], row[1:], out=out[:-1])
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    return np.where(norm > 1e-12, v / np.maximum(norm, 1e-12), [0.0, 0.0, 1.0])


class OccupancyGrid:
    """A dense occupancy map over ``bounds`` (root frame) at ``resolution`` [m].

    Args:
        resolution: Voxel edge [m] (default 2 cm).
        bounds: ``(low corner, high corner)`` [m] of the mapped box; points outside are counted in
            ``dropped_outside`` and ignored.
        decay: Seconds after which a voxel not seen again is dropped (None: never; it becomes unknown, not free).
        region: ``(low corner, high corner)`` [m] of the box where known-free space is tracked (None: nowhere, no
            voxel is ever unknown).
    """

    def __init__(
        self,
        resolution: float = DEFAULT_RESOLUTION,
        bounds: Any = DEFAULT_BOUNDS,
        *,
        decay: float | None = None,
        region: Any = None,
    ) -> None:
        self.resolution = _resolution(resolution)
        self.origin, high = _bounds(bounds)
        self.shape = tuple(int(v) for v in np.ceil((high - self.origin) / self.resolution - 1e-9))
        cells = math.prod(self.shape)
        if cells > 200_000_000:
            raise InvalidInputError("bounds", bounds, f"at most 2e8 voxels at {self.resolution} m (got {cells:.3g})")
        if decay is not None and not (isinstance(decay, (int, float)) and math.isfinite(decay) and decay > 0):
            raise InvalidInputError("decay", decay, "a positive number of seconds or None")
        self.decay = None if decay is None else float(decay)
        self.occupied = np.zeros(cells, dtype=bool)
        self._scratch = np.zeros(cells, dtype=bool)  # all False between calls
        self.seen = np.zeros(cells, dtype=np.float64) if self.decay is not None else None
        self._strides = np.array([self.shape[1] * self.shape[2], self.shape[2], 1], dtype=np.int64)
        self.dropped_outside = 0
        self.version = 0
        self.excluded_pixels: np.ndarray | None = None  # of the last insert_image
        self.free = np.zeros(cells, dtype=bool)  # known free (seen through, or the robot stood there)
        self.viewed = np.zeros(cells, dtype=bool)  # inside an image's view (within its range) at least once
        self.shadowed = np.zeros(cells, dtype=bool)  # an image saw a surface in front of it
        # an image viewed it with no return around and none of the robot's pixels: later surfaces in front of it
        # (seen from other sides) do not shadow it again
        self.into_nothing = np.zeros(cells, dtype=bool)
        self._set_region(region)

    def _set_region(self, region: Any) -> None:
        """The voxels whose known-free state is tracked: those whose box lies in ``region`` (clipped to the bounds),
        with their centres (float32, for projecting them into images)."""
        self.region = None if region is None else _bounds(region)
        if self.region is None:
            self._region_keys = np.zeros(0, dtype=np.int64)
            self._region_centres = np.zeros((0, 3), dtype=np.float32)
            return
        lo, hi = self.region
        first = np.maximum(np.ceil((lo - self.origin) / self.resolution - 1e-9).astype(np.int64), 0)
        last = np.minimum(np.floor((hi - self.origin) / self.resolution + 1e-9).astype(np.int64), self.shape)
        if np.any(last <= first):
            raise InvalidInputError("region", region, "a box that holds at least one voxel of the grid's bounds")
        i, j, k = np.meshgrid(*(np.arange(a, b) for a, b in zip(first, last, strict=True)), indexing="ij")
        index = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)
        # sorted by BLOCK^3-voxel block, so an image projects only the blocks its view cone can hold
        block = (index - first) // BLOCK
        order = np.lexsort((block[:, 2], block[:, 1], block[:, 0]))
        index, block = index[order], block[order]
        self._region_keys = index @ self._strides
        self._region_centres = (self.origin + (index + 0.5) * self.resolution).astype(np.float32)
        new = np.r_[True, np.any(block[1:] != block[:-1], axis=1)]
        starts = np.flatnonzero(new)
        self._region_counts = np.diff(np.r_[starts, len(index)])
        lo_corner = np.minimum.reduceat(self._region_centres, starts, axis=0).astype(float)
        hi_corner = np.maximum.reduceat(self._region_centres, starts, axis=0).astype(float)
        self._region_block_centre = (lo_corner + hi_corner) / 2
        self._region_block_radius = np.linalg.norm(hi_corner - lo_corner, axis=1) / 2 + self.resolution

    def _region_in_view(
        self, camera_centre: np.ndarray, axis: np.ndarray, half_angle: float, reach: float
    ) -> np.ndarray:
        """Mask of the region's voxels in blocks that may lie in a view cone (apex ``camera_centre``, unit ``axis``,
        ``half_angle`` [rad]) within ``reach`` [m]: a cheap superset of the voxels an image can see."""
        offset = self._region_block_centre - camera_centre
        distance = np.linalg.norm(offset, axis=1)
        radius = self._region_block_radius
        with np.errstate(invalid="ignore", divide="ignore"):
            angle = np.arccos(np.clip(offset @ axis / distance, -1.0, 1.0))
            widen = np.arcsin(np.clip(radius / distance, 0.0, 1.0))
        ok = (distance <= radius) | ((angle <= half_angle + widen) & (distance - radius <= reach))
        return np.repeat(ok, self._region_counts)

    def __len__(self) -> int:
        return int(np.count_nonzero(self.occupied))

    # ------------------------------------------------------------------------------------------------ indexing
    def keys(self, points: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Linear voxel keys of the points (N, 3) [m, root frame] inside the bounds, and the mask of those points."""
        P = np.asarray(points)
        cell = np.floor((P - self.origin) * (1.0 / self.resolution)).astype(np.int64)
        inside = np.all((cell >= 0) & (cell < self.shape), axis=1)
        return cell[inside] @ self._strides, inside

    def indices(self, keys: np.ndarray) -> np.ndarray:
        """Voxel indices (N, 3) of linear keys."""
        return np.stack(np.unravel_index(keys, self.shape), axis=1).astype(np.int64)

    def centers(self, keys: np.ndarray) -> np.ndarray:
        return self.origin + (self.indices(keys) + 0.5) * self.resolution

    def occupied_keys(self) -> np.ndarray:
        return np.flatnonzero(self.occupied)

    # ------------------------------------------------------------------------------------------------- updates
    def insert(self, points: npt.ArrayLike, stamp: float = 0.0, *, exclude: np.ndarray | None = None) -> int:
        """Mark the voxels of ``points`` (N, 3) [m, root frame] occupied; ``exclude``: keys of voxels whose points
        are dropped (the robot's own, :meth:`near_segments`). Returns the number of points kept."""
        P = np.asarray(points)
        if P.ndim != 2 or P.shape[1] != 3:
            raise InvalidInputError("points", f"shape {P.shape}", "(N, 3) positions [m]")
        if not np.issubdtype(P.dtype, np.floating):
            P = P.astype(float)
        finite = np.all(np.isfinite(P), axis=1)
        if not np.all(finite):
            P = P[finite]
        keys, inside = self.keys(P)
        self.dropped_outside += int(len(P) - len(keys))
        if exclude is not None and len(exclude):
            self._scratch[exclude] = True
            keys = keys[~self._scratch[keys]]
            self._scratch[exclude] = False
        self.occupied[keys] = True
        self.free[keys] = False  # what was hit is not known free (after ``decay`` it is unknown again)
        if self.seen is not None:
            self.seen[keys] = stamp
        self.version += 1
        return len(keys)

    def insert_image(
        self,
        depth: np.ndarray,
        ray_x: np.ndarray,
        ray_y: np.ndarray,
        T_root_camera: np.ndarray,
        stamp: float = 0.0,
        *,
        exclude: np.ndarray | None = None,
        thickness: float = 0.0,
    ) -> tuple[int, int]:
        """Mark the voxels a depth image (metres, NaN = no measurement) hits: pixel ``(row, col)`` is the point
        ``depth * (ray_x[col], ray_y[row], 1)`` of the camera at ``T_root_camera``. Separable rays make each root
        coordinate one multiply-add over the image, without forming the (N, 3) points. With ``thickness`` [m] the
        points up to that depth behind each hit are occupied too (every half voxel): surfaces are taken as solids
        at least that thick. Returns (measured, kept) pixels; ``self.excluded_pixels`` is then the mask of the
        pixels whose hit fell in ``exclude`` (the robot's own)."""
        from taplan.scene.fusion_kernels import insert_pixels  # numba loads on first fusion, not with taplan

        R, t = T_root_camera[:3, :3], T_root_camera[:3, 3]
        inv = 1.0 / self.resolution
        depth = np.ascontiguousarray(depth, dtype=np.float32)
        measured = int(np.count_nonzero(np.isfinite(depth)))
        steps = int(math.ceil(thickness / (self.resolution / 2) - 1e-9)) if thickness > 0 else 0
        # voxel coordinate along axis k, in voxel units: (depth * (R_k . ray) + t_k - origin_k) / h, the ray's
        # part per row and per column (float32: a voxel index needs no more)
        row_slope = np.stack([((R[k, 1] * ray_y + R[k, 2]) * inv).astype(np.float32) for k in range(3)])
        col_slope = np.stack([(R[k, 0] * ray_x * inv).astype(np.float32) for k in range(3)])
        offsets = np.array([(t[k] - self.origin[k]) * inv for k in range(3)], dtype=np.float32)
        shape = np.asarray(self.shape, dtype=np.int64)
        seen = self.seen if self.seen is not None else np.zeros(0)
        self.excluded_pixels = np.zeros(depth.shape, dtype=bool)
        if exclude is not None and len(exclude):
            self._scratch[exclude] = True
        try:
            for layer in range(steps + 1):  # the hits, then every half voxel behind them up to ``thickness``
                extra = np.float32(min(layer * self.resolution / 2, thickness))
                kept = insert_pixels(
                    depth,
                    row_slope,
                    col_slope,
                    offsets,
                    shape,
                    self._strides,
                    extra,
                    self._scratch,
                    self.occupied,
                    self.free,
                    seen,
                    float(stamp),
                    self.excluded_pixels,
                    layer == 0,
                )
                if layer == 0:
                    kept_pixels = kept
        finally:
            if exclude is not None and len(exclude):
                self._scratch[exclude] = False
        self.dropped_outside += measured - kept_pixels
        self.version += 1
        return measured, kept_pixels

    def clear_keys(self, keys: np.ndarray) -> None:
        """Free these voxels (seen through: known free)."""
        self.occupied[keys] = False
        self.free[keys] = True
        self.version += 1

    def clear(self) -> None:
        """Forget everything (every voxel of the region unknown again)."""
        self.occupied[:] = False
        self.free[:] = False
        self.viewed[:] = False
        self.shadowed[:] = False
        self.into_nothing[:] = False
        self.version += 1

    def mark_free(self, keys: np.ndarray) -> int:
        """Mark these voxels known free unless they are occupied (e.g. the space the robot's bodies fill: nothing
        else can be there). Returns how many changed."""
        keys = np.asarray(keys, dtype=np.int64)
        new = keys[~(self.occupied[keys] | self.free[keys])]
        if len(new):
            self.free[new] = True
            self.version += 1
        return len(np.unique(new))

    def mark_seen_free(
        self,
        depth: np.ndarray,
        intrinsics: tuple[float, float, float, float],
        T_root_camera: np.ndarray,
        margin: float,
        *,
        max_range: float = math.inf,
        ignore: np.ndarray | None = None,
        keep_into_nothing: bool = False,
    ) -> int:
        """Update the region's unknown voxels from a depth image (metres, NaN = no measurement). Each voxel is
        judged by the nearest valid depth of the 3x3 pixels around its centre's (a missing pixel, or a voxel wider
        than a pixel, hides nothing): known free when that depth is more than ``margin`` [m] beyond the centre (the
        whole box is in front of the surface when ``margin`` is at least half the voxel's diagonal);
        ``shadowed`` when it is not (a surface is in front of the voxel or in it); ``viewed`` when the centre
        projects into the image within ``max_range`` (a voxel viewed only through pixels without any measurement
        around them, looking into nothing, is neither). ``ignore``: a mask of pixels taken as no measurement (the
        robot's own bodies: they free nothing and, in this mode, shadow nothing). A voxel viewed into nothing (no
        valid depth and no ``ignore`` pixel around) is recorded in ``into_nothing``; with ``keep_into_nothing`` (no
        return taken as nothing within range, as for rendered images) such a voxel is not shadowed by this image.
        Returns how many became known free."""
        keys = self._region_keys
        if not len(keys):
            return 0
        fx, fy, cx, cy = intrinsics
        H, W = depth.shape
        corner = max(abs(cx), abs(W - cx)) / fx, max(abs(cy), abs(H - cy)) / fy
        half_angle = math.atan(math.hypot(*corner))  # the cone around the image's frustum
        candidates = self._region_in_view(T_root_camera[:3, 3], T_root_camera[:3, 2], half_angle, max_range)
        from taplan.scene.fusion_kernels import judge_voxels

        if ignore is None:
            ignore = np.zeros(depth.shape, dtype=bool)
        found = judge_voxels(
            keys,
            self._region_centres,
            candidates,
            self.occupied,
            self.free,
            self.viewed,
            self.shadowed,
            self.into_nothing,
            np.ascontiguousarray(depth, dtype=np.float32),
            np.ascontiguousarray(ignore, dtype=bool),
            np.ascontiguousarray(T_root_camera[:3, :3], dtype=np.float32),
            np.ascontiguousarray(T_root_camera[:3, 3], dtype=np.float32),
            np.array([fx, fy, cx, cy], dtype=np.float32),
            np.float32(margin),
            np.float32(1e-3),
            np.float32(max_range),
            bool(keep_into_nothing),
        )
        self.version += 1
        return found

    def unknown_keys(self, which: str = "all") -> np.ndarray:
        """Keys of the region's voxels neither occupied nor known free: ``"all"`` of them, or ``"occluded"``: those
        never inside an image's view or behind a surface an image saw."""
        keys = self._region_keys
        keys = keys[~(self.occupied[keys] | self.free[keys])]
        if which == "occluded":
            keys = keys[self.shadowed[keys] | ~self.viewed[keys]]
        elif which != "all":
            raise InvalidInputError("which", which, "'all' or 'occluded'")
        return keys

    def unknown_snapshot(self, which: str = "all") -> Occupancy:
        """The region's unknown voxels now (:meth:`unknown_keys`), as an obstacle shape in the root frame (what a
        conservative planner treats as occupied)."""
        return Occupancy(self.resolution, self.origin.copy(), self.indices(self.unknown_keys(which)))

    def clear_seen_through(
        self,
        depth: np.ndarray,
        intrinsics: tuple[float, float, float, float],
        T_root_camera: np.ndarray,
        margin: float,
    ) -> int:
        """Free the occupied voxels a depth image (metres, invalid pixels NaN) sees through: the voxel's centre
        projects onto a valid pixel whose depth is more than ``margin`` [m] beyond it. Returns how many."""
        keys = self.occupied_keys()
        if not len(keys):
            return 0
        fx, fy, cx, cy = intrinsics
        R, t = T_root_camera[:3, :3], T_root_camera[:3, 3]
        local = (self.centers(keys) - t) @ R  # camera frame
        z = local[:, 2]
        ahead = z > 1e-6
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.floor(fx * local[:, 0] / z + cx)
            v = np.floor(fy * local[:, 1] / z + cy)
        H, W = depth.shape
        visible = ahead & (u >= 0) & (u < W) & (v >= 0) & (v < H)
        rows = np.flatnonzero(visible)
        measured = depth[v[rows].astype(int), u[rows].astype(int)]
        free = rows[np.isfinite(measured) & (measured > z[rows] + margin)]
        self.clear_keys(keys[free])
        return len(free)

    def expire(self, now: float) -> int:
        """With ``decay``: drop voxels last seen before ``now - decay``. Returns how many."""
        if self.seen is None:
            return 0
        old = self.occupied & (self.seen < now - self.decay)
        count = int(np.count_nonzero(old))
        if count:
            self.occupied[old] = False
            self.version += 1
        return count

    def near_segments(self, starts: np.ndarray, ends: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """Keys of the voxels whose box may come within ``radii`` [m] of a segment (the robot's bodies plus
        padding): the voxel's centre is within ``radius + half diagonal``. Every point within ``radius`` of a segment
        falls in one of them."""
        from taplan.scene.fusion_kernels import voxels_near_segments

        half = self.resolution * math.sqrt(3) / 2
        starts = np.ascontiguousarray(starts, dtype=float).reshape(-1, 3)
        ends = np.ascontiguousarray(ends, dtype=float).reshape(-1, 3)
        reaches = np.asarray(radii, dtype=float).reshape(-1) + half
        return voxels_near_segments(
            starts, ends, reaches, self.origin, self.resolution, np.asarray(self.shape, dtype=np.int64), self._strides
        )

    def snapshot(self) -> Occupancy:
        """The occupied voxels now, as an obstacle shape in the root frame."""
        return Occupancy(self.resolution, self.origin.copy(), self.indices(self.occupied_keys()))

    def unshadow_seen_into_nothing(
        self,
        depth: np.ndarray,
        intrinsics: tuple[float, float, float, float],
        T_root_camera: np.ndarray,
        *,
        max_range: float,
        ignore: np.ndarray | None = None,
    ) -> int:
        """Shadowed, unknown region voxels that a depth image (metres, NaN = no return) views through pixels without
        any return around them (no valid depth among the 3x3 pixels around the centre's pixel, none of them in
        ``ignore``, the robot's own) and within ``max_range``: nothing stood in front of them or at them along those
        rays, so they are no longer shadowed (they stay unknown, viewed into nothing). Only from a camera whose own
        voxel is known free or outside the region (a camera inside an unseen object sees nothing either). Returns
        how many."""
        eye, _ = self.keys(T_root_camera[None, :3, 3])
        if len(eye) and not self.free[eye[0]] and self._region_contains(T_root_camera[:3, 3]):
            return 0
        keys = self._region_keys
        keys = keys[self.shadowed[keys] & ~(self.occupied[keys] | self.free[keys])]
        if not len(keys):
            return 0
        fx, fy, cx, cy = intrinsics
        H, W = depth.shape
        R, t = T_root_camera[:3, :3], T_root_camera[:3, 3]
        local = (self.centers(keys) - t) @ R
        z = local[:, 2]
        ahead = np.flatnonzero((z > 1e-3) & (z <= max_range))
        z = z[ahead]
        u = np.floor(fx * local[ahead, 0] / z + cx)
        v = np.floor(fy * local[ahead, 1] / z + cy)
        inside = (u >= 0) & (u < W) & (v >= 0) & (v < H)
        rows = ahead[inside]
        pixel = v[inside].astype(np.int64) * W + u[inside].astype(np.int64)
        raw = depth.astype(np.float32, copy=True)
        if ignore is not None:
            raw[ignore] = 0.0  # a window holding a robot pixel is not "nothing": the robot hides what is behind
        nothing = np.isnan(_nearest_around(raw).reshape(-1)[pixel])
        found = keys[rows[nothing]]
        self.shadowed[found] = False
        self.into_nothing[found] = True
        if len(found):
            self.version += 1
        return len(found)

    def _region_contains(self, point: np.ndarray) -> bool:
        if self.region is None:
            return False
        lo, hi = self.region
        return bool(np.all(point >= lo) and np.all(point <= hi))
