"""Compatibility: the capsule geometry moved to :mod:`taplan.scene.capsules` (the collision world's layer)."""

from __future__ import annotations

from taplan.scene.capsules import Capsule, capsule_distance, capsules_from_urdf, segment_closest_points

__all__ = ["Capsule", "capsules_from_urdf", "segment_closest_points", "capsule_distance"]
