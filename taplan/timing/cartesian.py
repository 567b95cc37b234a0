"""Compatibility import: Cartesian straight lines moved to :mod:`taplan.planning.cartesian` (a planner composing
IK, timing and the scene)."""

from __future__ import annotations

from taplan.planning.cartesian import *  # noqa: F403
from taplan.planning.cartesian import __all__  # noqa: F401
