"""The collision world: obstacles, the robot's own bodies, signed distances with gradients.

Layer order: robot -> scene -> ik / timing / stream -> planning. Shapes (:mod:`~taplan.scene.shapes`) are posed in
the robot's root frame in a :class:`Scene` (run-time add/move/remove, objects attached to a hand), loaded from
YAML/JSON (:mod:`~taplan.scene.io`); :class:`CollisionWorld` evaluates distances, witness points and Jacobians
against the robot (:mod:`~taplan.scene.robot_bodies`: its capsules and allowed pairs). Perceived geometry
(:mod:`~taplan.scene.perception`): depth images and point clouds fused into an :class:`Occupancy` obstacle.
"""

from __future__ import annotations

from taplan.scene.camera import CameraMount, PinholeCamera
from taplan.scene.io import TELEAVATAR_SCENES, load_scene, save_scene, scene_from_dict, scene_to_dict
from taplan.scene.occupancy import Occupancy, OccupancyGrid
from taplan.scene.perception import Perception
from taplan.scene.robot_bodies import Body, allowed_pairs, robot_bodies
from taplan.scene.scene import AttachedObject, Obstacle, Scene, as_pose
from taplan.scene.shapes import Box, Capsule, Cylinder, HalfSpace, Mesh, Shape, Sphere
from taplan.scene.world import CollisionWorld, Distances

__all__ = [
    "Shape",
    "Box",
    "Sphere",
    "Capsule",
    "Cylinder",
    "HalfSpace",
    "Mesh",
    "Scene",
    "Obstacle",
    "AttachedObject",
    "as_pose",
    "load_scene",
    "TELEAVATAR_SCENES",
    "save_scene",
    "scene_from_dict",
    "scene_to_dict",
    "CollisionWorld",
    "Distances",
    "Body",
    "robot_bodies",
    "allowed_pairs",
    "Occupancy",
    "OccupancyGrid",
    "Perception",
    "PinholeCamera",
    "CameraMount",
]
