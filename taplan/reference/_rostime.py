"""ROS 1 time arithmetic (``genpy.rostime`` semantics) on integer nanoseconds, vectorised.

``genpy.Duration(float_secs)`` and ``Duration.from_sec`` build ``secs = int(x)`` then
``nsecs = int((x - secs) * 1000000000)``: both ``int`` calls truncate toward zero, so a float duration loses whatever
lies below one nanosecond *after* the float product, e.g. ``Duration(2.3)`` is 2 s + 299 999 999 ns. ``_canon`` moves
``nsecs`` into [0, 1e9) without changing the total. ``to_sec()`` is ``float(secs) + float(nsecs) / 1e9``.
The helpers below apply exactly these IEEE-754 operations to numpy arrays, so the results match rospy bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

NSEC_PER_SEC = 1_000_000_000


def duration_ns(seconds: npt.ArrayLike) -> np.ndarray:
    """``genpy.Duration(seconds).to_nsec()`` for float seconds (truncation toward zero). Returns int64."""
    x = np.asarray(seconds, dtype=float)
    secs = np.trunc(x)
    nsecs = np.trunc((x - secs) * 1e9)
    return secs.astype(np.int64) * NSEC_PER_SEC + nsecs.astype(np.int64)


def duration_ns_scalar(seconds: float) -> int:
    """Scalar :func:`duration_ns`, the literal genpy expression."""
    secs = int(seconds)
    return secs * NSEC_PER_SEC + int((seconds - secs) * 1000000000)


def to_sec(ns: npt.ArrayLike) -> np.ndarray:
    """``Duration.to_sec()`` of canonical (secs, nsecs) for integer nanoseconds. Returns float64."""
    n = np.asarray(ns, dtype=np.int64)
    secs = np.floor_divide(n, NSEC_PER_SEC)
    nsecs = n - secs * NSEC_PER_SEC
    return secs.astype(float) + nsecs.astype(float) / 1e9


def to_sec_scalar(ns: int) -> float:
    secs, nsecs = divmod(int(ns), NSEC_PER_SEC)
    return float(secs) + float(nsecs) / 1e9


_POW = np.frompyfunc(math.pow, 2, 1)


def py_pow(x: np.ndarray, exponent: float) -> np.ndarray:
    """``pow(x, exponent)`` as CPython computes it (libm ``pow``), element-wise; numpy's power can differ by 1 ulp."""
    if x.size == 0:
        return np.asarray(x, dtype=float)
    return np.asarray(_POW(x, float(exponent)), dtype=float)
