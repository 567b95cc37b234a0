"""Pose targets: a 4x4 transform, or a position with a quaternion (x, y, z, w)."""

from __future__ import annotations

import math
import struct
from typing import Any

import numpy as np
import pinocchio as pin

from taplan.errors import InvalidInputError

__all__ = ["as_transform", "quaternion_to_matrix", "check_matrix", "pose_keys"]

_EXPECTED = "a 4x4 homogeneous transform, a (position (3,), quaternion xyzw (4,)) pair, or a (7,) [x y z qx qy qz qw]"


def quaternion_to_matrix(quaternion: np.ndarray, name: str = "quaternion") -> np.ndarray:
    """Rotation matrix (3, 3) of a quaternion (x, y, z, w); it is normalised, a zero quaternion raises."""
    norm = float(np.linalg.norm(quaternion))
    if not np.isfinite(norm) or norm < 1e-9:
        raise InvalidInputError(name, quaternion, "a finite non-zero quaternion (x, y, z, w)")
    x, y, z, w = quaternion / norm
    return pin.Quaternion(w, x, y, z).toRotationMatrix()


def as_transform(target: Any, name: str = "target") -> np.ndarray:
    """Validate a pose target and return it as a new 4x4 transform ``T_root_frame`` [m].

    Args:
        target: A 4x4 homogeneous transform; or a pair ``(position, quaternion)`` with the position [m] (3,) and the
            quaternion (4,) in (x, y, z, w) order (ROS); or a (7,) vector ``[x, y, z, qx, qy, qz, qw]``.
        name: Argument name used in error messages.

    Raises:
        InvalidInputError: wrong shape, NaN/inf, a zero quaternion or a rotation block that is not a rotation.
    """
    if isinstance(target, tuple | list) and len(target) == 2:
        position = _finite(target[0], f"{name}[0] (position)", (3,))
        quaternion = _finite(target[1], f"{name}[1] (quaternion xyzw)", (4,))
        T = np.eye(4)
        T[:3, :3] = quaternion_to_matrix(quaternion, f"{name}[1] (quaternion xyzw)")
        T[:3, 3] = position
        return T
    array = _finite(target, name, None)
    if array.shape == (7,):
        T = np.eye(4)
        T[:3, :3] = quaternion_to_matrix(array[3:], name)
        T[:3, 3] = array[:3]
        return T
    if array.shape != (4, 4):
        raise InvalidInputError(name, f"array of shape {array.shape}", _EXPECTED)
    R = array[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0.0:
        raise InvalidInputError(name, "4x4 whose rotation block is not orthonormal", "a proper rotation (R^T R = I)")
    if np.abs(array[3] - (0.0, 0.0, 0.0, 1.0)).max() > 1e-9:
        raise InvalidInputError(name, f"last row {array[3].tolist()}", "[0, 0, 0, 1]")
    return array.copy()


_ROTATION = struct.Struct("3d8x3d8x3d")  # the rotation block of a C-ordered float64 4x4, row by row
_TRANSLATION = struct.Struct("24xd24xd24xd")
_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0]).tobytes()
_ORTHONORMAL_TOL = 1e-6  # as in as_transform


def check_matrix(T: np.ndarray, known: bytes, frame: str) -> tuple[bytes, tuple[float, float, float]]:
    """Validate a float64 (4, 4) array target on the hot path; return its rotation block's bytes and its translation.

    ``known`` is what an earlier call returned: when the rotation block has the same bytes it was validated
    already and only the translation is checked (the usual case when a stream moves a target). Otherwise the
    block is checked with scalar arithmetic (rows orthonormal to 1e-6, determinant > 0, last row [0, 0, 0, 1]);
    a failing target gets :func:`as_transform`'s error message, naming the argument ``targets[frame]``.

    Raises:
        InvalidInputError: NaN/inf, a rotation block that is not a rotation, or a wrong last row.
    """
    raw = T.tobytes()
    key = raw[0:24] + raw[32:56] + raw[64:88]
    last_row = raw[96:] == _LAST_ROW
    if key != known or not last_row:
        a, b, c, d, e, f, g, h, i = _ROTATION.unpack_from(raw)
        tol = _ORTHONORMAL_TOL
        rotation = (
            abs(a * a + b * b + c * c - 1.0) <= tol
            and abs(d * d + e * e + f * f - 1.0) <= tol
            and abs(g * g + h * h + i * i - 1.0) <= tol
            and abs(a * d + b * e + c * f) <= tol
            and abs(a * g + b * h + c * i) <= tol
            and abs(d * g + e * h + f * i) <= tol
            and a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) > 0.0
        )
        if not (rotation and last_row):
            name = f"targets[{frame!r}]"
            as_transform(T, name)  # raises with the specific reason
            if not rotation:  # within as_transform's tolerance but not this one's: be strict
                raise InvalidInputError(name, "4x4 whose rotation block is not orthonormal", "a proper rotation")
    x, y, z = _TRANSLATION.unpack_from(raw)
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        raise InvalidInputError(f"targets[{frame!r}]", T, "finite values (no NaN or inf)")
    return key, (x, y, z)


def pose_keys(T: np.ndarray) -> tuple[bytes, tuple[float, float, float]]:
    """The keys :func:`check_matrix` returns, for a 4x4 target that is already validated."""
    raw = np.ascontiguousarray(T).tobytes()
    return raw[0:24] + raw[32:56] + raw[64:88], _TRANSLATION.unpack_from(raw)


def _finite(value: Any, name: str, shape: tuple[int, ...] | None) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidInputError(name, value, _EXPECTED) from None
    if shape is not None and array.shape != shape:
        raise InvalidInputError(name, f"array of shape {array.shape}", f"shape {shape}")
    if not np.all(np.isfinite(array)):
        raise InvalidInputError(name, array, "finite values (no NaN or inf)")
    return array
