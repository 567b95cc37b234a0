"""The planner's compiled (numba) kernels, loaded before a plan's time budget starts.

numba compiles a kernel on its first call in a process, or loads the machine code it cached beside the module:
~0.2 s per process, and once after installing several seconds of compilation (the distance engine's pairs, the
sampler's clearance test). Inside :func:`~taplan.planning.plan_motion` that first call would come out of the
caller's ``max_time`` (a 1 s plan failing for want of time on a fresh install, or overrunning its budget).
:func:`load_compiled_kernels` makes those first calls on a small scene of every closed-form shape, the way a plan
makes them (the same functions and argument types), before the budget's clock starts.
"""

from __future__ import annotations

import threading

import numpy as np

from taplan.robot import Robot

__all__ = ["load_compiled_kernels"]

_LOCK = threading.Lock()
_LOADED = False


def load_compiled_kernels(robot: Robot) -> None:
    """Make the first calls of the engine's and the sampler's compiled kernels in this process (a no-op after the
    first), with ``robot``'s bodies among a box, a sphere, a capsule, a cylinder and a half-space out of reach."""
    global _LOADED
    with _LOCK:
        if _LOADED:
            return
        from taplan.planning.compiled_check import ClearanceCheck
        from taplan.scene import Box, Capsule, CollisionWorld, Cylinder, HalfSpace, Scene, Sphere

        scene = Scene()
        far = 5.0  # [m] every obstacle out of the robot's reach: the kernels run their full (clear) paths
        scene.add("box", Box((0.2, 0.2, 0.2)), ([far, 0.0, 0.0], [0, 0, 0, 1]))
        scene.add("sphere", Sphere(0.1), ([far, far, 0.0], [0, 0, 0, 1]))
        scene.add("capsule", Capsule(0.05, 0.2), ([0.0, far, 0.0], [0, 0, 0, 1]))
        scene.add("cylinder", Cylinder(0.05, 0.2), ([-far, 0.0, 0.0], [0, 0, 0, 1]))
        scene.add("floor", HalfSpace(), ([0.0, 0.0, -far], [0, 0, 0, 1]))
        world = CollisionWorld(robot, scene)
        engine = world.engine()
        Q = np.repeat(robot.home[None], 2, axis=0)
        if engine is not None:
            engine.evaluate(Q, jacobian=True, jacobian_within=0.1, bound_beyond=0.1)
            engine.evaluate(Q, jacobian=False)
            engine.distances_of(Q, np.arange(len(engine.pair_columns()[0])))
        check = ClearanceCheck(world, 0.01)
        check(robot.home)
        check.motion(robot.home, robot.home + 0.01, 0.02)
        _LOADED = True
