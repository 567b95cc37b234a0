"""osqp's settings under the name its installed version uses."""

from __future__ import annotations

from functools import cache
from importlib.metadata import PackageNotFoundError, version

__all__ = ["polish_setting"]


@cache
def polish_setting() -> str:
    """The name of osqp's solution-polishing setting: ``"polishing"`` from osqp 1.0 on (where ``"polish"`` still
    works but warns that it is deprecated), ``"polish"`` before (the project accepts osqp >= 0.6)."""
    try:
        major = int(version("osqp").split(".")[0])
    except (PackageNotFoundError, ValueError):
        return "polishing"
    return "polishing" if major >= 1 else "polish"
