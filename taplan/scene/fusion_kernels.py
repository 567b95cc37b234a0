"""Compiled loops of depth-image fusion (numba): one pass over the pixels or voxels instead of a dozen numpy passes.

Fusing one 640x480 image touched every pixel ~30 times in numpy (a temporary per operation and axis: ~10 ms CPU);
each kernel here visits a pixel or voxel once. They repeat the numpy code's arithmetic operation by operation in the
same precision (float32 where it was float32, float64 where it was float64, no fused multiply-add: numba does not
contract without ``fastmath``), so the voxel states they produce are the ones the numpy code produced; the tests
compare both on rendered images. Compiled once per machine (``cache=True`` keeps the machine code beside this
file); the first call of a fresh install pays the compilation (~1-2 s).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["insert_pixels", "judge_voxels", "voxels_near_segments"]


@njit(cache=True, nogil=True)
def insert_pixels(
    depth: np.ndarray,
    row_slope: np.ndarray,
    col_slope: np.ndarray,
    offsets: np.ndarray,
    shape: np.ndarray,
    strides: np.ndarray,
    extra: np.float32,
    exclude: np.ndarray,
    occupied: np.ndarray,
    free: np.ndarray,
    seen: np.ndarray,
    stamp: float,
    excluded_pixels: np.ndarray,
    first: bool,
) -> int:
    """Mark the voxels a depth image hits (see :meth:`OccupancyGrid.insert_image`) with ``extra`` [m] added to
    every depth (0 for the hits themselves, more for the layers behind them); returns the pixels that land inside
    the grid.

    ``row_slope`` (3, H) and ``col_slope`` (3, W) float32: the voxel coordinate along axis k of pixel (r, c) at depth
    d is ``d * (row_slope[k, r] + col_slope[k, c]) + offsets[k]``, in float32 as the numpy code computed it.
    ``exclude``: per voxel, True for the robot's own: their hits are dropped and, when ``first``, the pixel is set
    in ``excluded_pixels``. ``seen`` has length 0 when the grid keeps no stamps.
    """
    H, W = depth.shape
    # every constant in a local: the stores into the grid's arrays would otherwise make the compiler reload them
    n0, n1, n2 = np.float32(shape[0]), np.float32(shape[1]), np.float32(shape[2])
    o0, o1, o2 = offsets[0], offsets[1], offsets[2]
    s0, s1 = strides[0], strides[1]
    zero = np.float32(0.0)
    shifted = extra != 0
    keep_stamps = seen.shape[0] > 0
    kept = 0
    for r in range(H):
        r0, r1, r2 = row_slope[0, r], row_slope[1, r], row_slope[2, r]
        for c in range(W):
            d = depth[r, c]
            if shifted:
                d = d + extra
            # NaN (no measurement) fails every comparison
            f0 = d * (r0 + col_slope[0, c]) + o0
            if not (f0 >= zero and f0 < n0):
                continue
            f1 = d * (r1 + col_slope[1, c]) + o1
            if not (f1 >= zero and f1 < n1):
                continue
            f2 = d * (r2 + col_slope[2, c]) + o2
            if not (f2 >= zero and f2 < n2):
                continue
            key = np.int64(np.int32(f0)) * s0 + np.int64(np.int32(f1)) * s1 + np.int64(np.int32(f2))
            kept += 1
            if exclude[key]:
                if first:
                    excluded_pixels[r, c] = True
                continue
            occupied[key] = True
            free[key] = False
            if keep_stamps:
                seen[key] = stamp
    return kept


@njit(cache=True, nogil=True)
def judge_voxels(
    keys: np.ndarray,
    centres: np.ndarray,
    candidates: np.ndarray,
    occupied: np.ndarray,
    free: np.ndarray,
    viewed: np.ndarray,
    shadowed: np.ndarray,
    into_nothing: np.ndarray,
    depth: np.ndarray,
    ignore: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    intrinsics: np.ndarray,
    margin: np.float32,
    near: np.float32,
    max_range: np.float32,
    keep_into_nothing: bool,
) -> int:
    """The region voxels' known-free / viewed / shadowed update of one depth image (see
    :meth:`OccupancyGrid.mark_seen_free`): each unknown candidate voxel's centre (float32, camera at ``R``, ``t``)
    is projected; the nearest valid depth of the 3x3 pixels around it (``ignore``d pixels excluded) decides.
    Returns how many became known free."""
    H, W = depth.shape
    # every constant in a local (the stores into the grid's arrays would otherwise make the compiler reload them)
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    t0, t1, t2 = t[0], t[1], t[2]
    r00, r01, r02 = R[0, 0], R[0, 1], R[0, 2]
    r10, r11, r12 = R[1, 0], R[1, 1], R[1, 2]
    r20, r21, r22 = R[2, 0], R[2, 1], R[2, 2]
    found = 0
    for i in range(keys.shape[0]):
        if not candidates[i]:
            continue
        key = keys[i]
        if occupied[key] or free[key]:
            continue
        # camera-frame coordinates: (centre - t) @ R, float32 as numpy did it
        a0 = centres[i, 0] - t0
        a1 = centres[i, 1] - t1
        a2 = centres[i, 2] - t2
        z = a0 * r02 + a1 * r12 + a2 * r22
        if not (z > near and z <= max_range):
            continue
        x = a0 * r00 + a1 * r10 + a2 * r20
        y = a0 * r01 + a1 * r11 + a2 * r21
        u = np.floor(fx * x / z + cx)
        v = np.floor(fy * y / z + cy)
        if not (u >= 0 and u < W and v >= 0 and v < H):
            continue
        row, col = int(v), int(u)
        measured = np.float32(np.inf)
        own = False
        for rr in range(max(row - 1, 0), min(row + 2, H)):
            for cc in range(max(col - 1, 0), min(col + 2, W)):
                value = depth[rr, cc]
                if ignore[rr, cc]:
                    own = True
                elif value == value and value < measured:
                    measured = value
        viewed[key] = True
        if measured == np.inf:
            if not own:
                into_nothing[key] = True  # no return around and none of the robot's pixels: nothing in front
            continue
        if measured > z + margin:
            free[key] = True
            found += 1
        elif not (keep_into_nothing and into_nothing[key]):
            # (kept: a surface in front of a voxel an earlier image viewed into nothing hides it from this camera
            # only; else views from other sides would hide again, round after round, what was looked at)
            shadowed[key] = True
    return found


@njit(cache=True, nogil=True)
def voxels_near_segments(
    starts: np.ndarray,
    ends: np.ndarray,
    reaches: np.ndarray,
    origin: np.ndarray,
    h: float,
    shape: np.ndarray,
    strides: np.ndarray,
) -> np.ndarray:
    """Keys of the voxels whose centre lies within ``reaches`` [m] of a segment, segment by segment, each in
    (i, j, k) order (see :meth:`OccupancyGrid.near_segments`, whose numpy arithmetic this repeats)."""
    count = 0
    boxes = np.zeros((starts.shape[0], 6), dtype=np.int64)
    for s in range(starts.shape[0]):
        for k in range(3):
            low = min(starts[s, k], ends[s, k]) - reaches[s]
            high = max(starts[s, k], ends[s, k]) + reaches[s]
            boxes[s, k] = max(np.int64(np.floor((low - origin[k]) / h)), 0)
            boxes[s, 3 + k] = min(np.int64(np.floor((high - origin[k]) / h)) + 1, shape[k])
        volume = 1
        for k in range(3):
            volume *= max(boxes[s, 3 + k] - boxes[s, k], 0)
        count += volume
    out = np.empty(count, dtype=np.int64)
    n = 0
    for s in range(starts.shape[0]):
        lo0, lo1, lo2, hi0, hi1, hi2 = boxes[s]
        if hi0 <= lo0 or hi1 <= lo1 or hi2 <= lo2:
            continue
        u0 = ends[s, 0] - starts[s, 0]
        u1 = ends[s, 1] - starts[s, 1]
        u2 = ends[s, 2] - starts[s, 2]
        length2 = u0 * u0 + u1 * u1 + u2 * u2
        reach2 = reaches[s] * reaches[s]
        for i in range(lo0, hi0):
            x = origin[0] + (i + 0.5) * h - starts[s, 0]
            for j in range(lo1, hi1):
                y = origin[1] + (j + 0.5) * h - starts[s, 1]
                for k in range(lo2, hi2):
                    z = origin[2] + (k + 0.5) * h - starts[s, 2]
                    tt = 0.0
                    if length2 > 1e-18:
                        tt = (x * u0 + y * u1 + z * u2) / length2
                        tt = min(max(tt, 0.0), 1.0)
                    dx = x - tt * u0
                    dy = y - tt * u1
                    dz = z - tt * u2
                    if dx * dx + dy * dy + dz * dz <= reach2:
                        out[n] = i * strides[0] + j * strides[1] + k
                        n += 1
    return out[:n]
