"""Synthetic wrist depth cameras for ``taplan sim``: images of a scene file rendered through the camera model.

:class:`DepthCameraSim` watches a :class:`~taplan.ros.sim.SimulatedRobot`'s configuration and, at ``rate``,
renders each wrist camera (pose by forward kinematics of its mount frame; the scene's primitives and the robot's own
bodies, :func:`taplan.scene.raycast.render_depth`, with optional noise and missing pixels) and publishes a
``16UC1`` ``sensor_msgs/Image`` (millimetres, 0 = no measurement, as the robot's depth driver) and its
``CameraInfo`` on the guide's topics, stamped with the wall clock of the configuration rendered. The whole
perception loop then runs without a robot: ``taplan sim --scene table.yaml --depth`` and a
:class:`~taplan.ros.perception_link.PerceptionLink` on the other end.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from taplan.errors import InvalidInputError
from taplan.ros.sensor_fields import CAMERA_INFO, IMAGE
from taplan.scene.camera import TELEAVATAR_CAMERAS, TELEAVATAR_DEPTH_TOPICS, PinholeCamera, add_camera_frames
from taplan.scene.raycast import depth_to_16uc1, render_depth
from taplan.scene.robot_bodies import robot_bodies
from taplan.scene.scene import Scene

__all__ = ["DepthCameraSim", "SIM_DEPTH_CAMERA"]

# the wrist camera's 87 deg field of view at a quarter of its 640x480 pixels: rendering stays well within a
# 5 Hz budget on a loaded machine (the full size is an option)
SIM_DEPTH_CAMERA = PinholeCamera(160, 120, 84.25, 84.25, 80.0, 60.0)


class DepthCameraSim:
    """Publish rendered depth images of ``scene`` from the wrist cameras of ``sim``'s robot.

    Args:
        interface: Transport.
        sim: The simulated robot (its ``q`` and ``robot``).
        scene: What the cameras see (its primitives; occupancy obstacles are not rendered).
        camera: Intrinsics of every camera.
        rate: Images per second per camera [Hz].
        noise: Gaussian depth noise [m]; missing: fraction of pixels dropped; seed: their generator's seed.
        max_range: Depths beyond are no measurement [m].
        clock: Wall clock for the stamps [s].
    """

    def __init__(
        self,
        interface: Any,
        sim: Any,
        scene: Scene,
        *,
        camera: PinholeCamera = SIM_DEPTH_CAMERA,
        rate: float = 5.0,
        noise: float = 0.002,
        missing: float = 0.01,
        seed: int = 0,
        max_range: float = 3.0,
        clock: Callable[[], float] = time.time,
    ) -> None:
        if not (isinstance(rate, (int, float)) and math.isfinite(rate) and 0 < rate <= 60):
            raise InvalidInputError("depth rate", rate, "a rate in (0, 60] Hz")
        self.sim = sim
        self.scene = scene
        self.camera = camera
        self.period = 1.0 / float(rate)
        self.noise, self.missing, self.max_range = float(noise), float(missing), float(max_range)
        self.rng = np.random.default_rng(seed)
        self.clock = clock
        robot = sim.robot
        self.mounts = add_camera_frames(robot, dict(TELEAVATAR_CAMERAS))
        self._bodies = robot_bodies(robot)
        self._data = robot.model.createData()
        self._next: float | None = None
        self._turn = 0
        self.published = 0
        self._publishers = {}
        for frame in self.mounts:
            image_topic, info_topic = TELEAVATAR_DEPTH_TOPICS[frame]
            self._publishers[frame] = (
                interface.create_publisher(IMAGE, image_topic),
                interface.create_publisher(CAMERA_INFO, info_topic),
            )

    def _capsules(self, q: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, float]]:
        import pinocchio as pin

        pin.forwardKinematics(self.sim.robot.model, self._data, q)
        return [
            (self._data.oMi[b.joint].act(b.start), self._data.oMi[b.joint].act(b.end), b.radius) for b in self._bodies
        ]

    def render(self, q: np.ndarray, frame: str) -> np.ndarray:
        """The depth image [m] (NaN: no measurement) camera ``frame`` takes at configuration ``q``."""
        T = self.sim.robot.frame_pose(q, frame)
        return render_depth(
            self.camera,
            T,
            self.scene,
            capsules=self._capsules(q),
            max_range=self.max_range,
            noise=self.noise,
            missing=self.missing,
            rng=self.rng,
        )

    def step(self, now: float | None = None) -> int:
        """Publish the next camera's image when due at monotonic time ``now`` [s]; returns how many were published.

        The cameras take turns (each at ``rate``), so one call renders one image: the simulated robot's loop, which
        also publishes the joint states, is held up by one render at a time.
        """
        now = time.monotonic() if now is None else float(now)
        if self._next is None:
            self._next = now
        if now + 1e-9 < self._next:
            return 0
        frames = list(self._publishers)
        self._next = max(self._next + self.period / len(frames), now - self.period / 2)
        frame = frames[self._turn % len(frames)]
        self._turn += 1
        q = np.array(self.sim.q, dtype=float)
        stamp = self.clock()
        image_publisher, info_publisher = self._publishers[frame]
        millimetres = depth_to_16uc1(self.render(q, frame))
        info_publisher.publish(dict(self.camera.to_camera_info(), stamp=stamp, frame_id=frame))
        image_publisher.publish(
            {
                "stamp": stamp,
                "frame_id": frame,
                "height": self.camera.height,
                "width": self.camera.width,
                "encoding": "16UC1",
                "is_bigendian": 0,
                "step": 2 * self.camera.width,
                "data": millimetres.astype("<u2").tobytes(),
            }
        )
        self.published += 1
        return 1
