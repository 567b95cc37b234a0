"""Shape and finiteness checks used once at the public boundary."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from taplan.errors import InvalidInputError


def as_vector(value: npt.ArrayLike, name: str, size: int | None = None, *, finite: bool = True) -> np.ndarray:
    """Return ``value`` as a float vector of shape (size,), or raise naming ``name``."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidInputError(name, value, "a numeric array") from None
    if array.ndim != 1 or (size is not None and array.shape[0] != size):
        expected = f"shape ({size},)" if size is not None else "a 1-D array"
        raise InvalidInputError(name, f"array of shape {array.shape}", expected)
    if finite and not np.all(np.isfinite(array)):
        raise InvalidInputError(name, array, "finite values (no NaN or inf)")
    return array


def as_matrix(value: npt.ArrayLike, name: str, shape: tuple[int | None, int | None]) -> np.ndarray:
    """Return ``value`` as a finite float array of the given 2-D shape (None = any), or raise."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidInputError(name, value, "a numeric array") from None
    if array.ndim != 2 or any(s is not None and s != a for s, a in zip(shape, array.shape, strict=True)):
        shown = tuple("n" if s is None else s for s in shape)
        raise InvalidInputError(name, f"array of shape {array.shape}", f"shape {shown}")
    if not np.all(np.isfinite(array)):
        raise InvalidInputError(name, "array with NaN or inf", "finite values")
    return array


def as_positive(value: float, name: str) -> float:
    """Return ``value`` as a finite float > 0, or raise naming ``name``."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InvalidInputError(name, value, "a positive number") from None
    if not np.isfinite(number) or number <= 0.0:
        raise InvalidInputError(name, value, "a finite number > 0")
    return number
