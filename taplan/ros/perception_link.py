"""Live perception over a :class:`~taplan.ros.RosInterface`: depth images, camera infos and point clouds in, the
scene's perceived occupancy kept current.

:class:`PerceptionLink` subscribes, on the interface a :class:`~taplan.ros.Runner` (or any loop) spins:

* ``/{side}_arm/joint_states`` of both arms: the :class:`~taplan.scene.perception.JointHistory` that places each
  image at the configuration the robot had at its stamp;
* per wrist camera its ``CameraInfo`` and depth ``Image`` topics (default the guide's ``/{left,right}/depth/...``);
* optional ``PointCloud2`` topics.

Each image or cloud is fused into the :class:`~taplan.scene.Perception` and the scene's ``perceived`` obstacle is
replaced, so a :class:`~taplan.scene.CollisionWorld` over that scene (the IK's dampers, a PoseStreamer, the next
plan) sees it on its next query. A message that cannot be used (wrong encoding, a size that differs from the camera
info, NaN intrinsics, a frame the model does not have, a stamp outside the joint history) is logged with its reason
and counted in :attr:`PerceptionLink.rejected`; it never raises into the loop.

A camera stream that stops is a reason to stop moving when the motion relies on it: :meth:`PerceptionLink.monitor`
returns that reason once no image has arrived for ``stale_after`` seconds (after a first one), and a Runner given it
as a monitor brakes smoothly and reports it.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from taplan import api
from taplan.errors import InvalidInputError, TaplanError, UnknownNameError
from taplan.ros.sensor_fields import CAMERA_INFO, IMAGE, POINT_CLOUD2
from taplan.scene.camera import TELEAVATAR_DEPTH_TOPICS, PinholeCamera
from taplan.scene.perception import Perception

__all__ = ["PerceptionLink", "IMAGE", "CAMERA_INFO", "POINT_CLOUD2"]

logger = logging.getLogger(__name__)


class PerceptionLink:
    """Keep ``perception``'s scene current from the topics of ``interface``.

    Args:
        interface: The transport (subscriptions are called from its ``spin_once``).
        perception: What the images and clouds are fused into.
        cameras: ``{camera frame in the model: (image topic, camera_info topic)}``; default the TeleAvatar's wrist
            cameras.
        clouds: ``{PointCloud2 topic: frame in the model, or None for the message's frame_id}``.
        stale_after: Seconds without an image after which :meth:`monitor` reports the stream broken [s].
        clock: Monotonic time [s] (injected for tests).
    """

    def __init__(
        self,
        interface: Any,
        perception: Perception,
        *,
        cameras: Mapping[str, tuple[str, str]] | None = None,
        clouds: Mapping[str, str | None] | None = None,
        stale_after: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not (isinstance(stale_after, (int, float)) and np.isfinite(stale_after) and stale_after > 0):
            raise InvalidInputError("stale_after", stale_after, "a time > 0 [s]")
        self.perception = perception
        self.stale_after = float(stale_after)
        self.clock = clock
        self.cameras = dict(TELEAVATAR_DEPTH_TOPICS if cameras is None else cameras)
        robot = perception.robot
        for frame in self.cameras:
            robot.frame_id(frame)  # UnknownNameError now, not per message
        self.infos: dict[str, PinholeCamera] = {}
        self.integrated = 0
        self.rejected: dict[str, int] = {}
        self.last_image: float | None = None
        self._latest: dict[str, np.ndarray] = {}
        self._indices = {side: robot.indices(api.ARM_JOINT_NAMES[side]) for side in api.SIDES}
        for side in api.SIDES:
            interface.create_subscription(api.JOINT_STATE, api.Topics.joint_states(side), self._on_state(side))
        for frame, (image_topic, info_topic) in self.cameras.items():
            interface.create_subscription(CAMERA_INFO, info_topic, self._on_info(frame))
            interface.create_subscription(IMAGE, image_topic, self._on_image(frame))
        for topic, frame in (clouds or {}).items():
            if frame is not None:
                robot.frame_id(frame)
            interface.create_subscription(POINT_CLOUD2, topic, self._on_cloud(topic, frame))

    # ------------------------------------------------------------------------------------------------ inputs
    def _reject(self, reason: str, what: str, exc: Exception) -> None:
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
        logger.warning("perception: ignoring %s: %s", what, exc)

    def _on_state(self, side: str) -> Callable[[dict[str, Any]], None]:
        def callback(fields: dict[str, Any]) -> None:
            try:
                q_side = api.parse_joint_state(side, fields.get("name", []), fields.get("position", []))
            except (InvalidInputError, UnknownNameError):
                return  # the runner logs malformed joint states
            self._latest[side] = q_side
            stamp = fields.get("stamp")
            if stamp is None or len(self._latest) < len(api.SIDES):
                return
            q = self.perception.robot.home.copy()
            for s, values in self._latest.items():
                q[self._indices[s]] = values
            history = self.perception.history
            if len(history) and stamp < history.latest_stamp:
                return  # the other arm's state of the same instant, or one out of order
            history.add(float(stamp), q)

        return callback

    def _on_info(self, frame: str) -> Callable[[dict[str, Any]], None]:
        def callback(fields: dict[str, Any]) -> None:
            try:
                self.infos[frame] = PinholeCamera.from_camera_info(fields)
            except TaplanError as exc:
                self._reject("camera_info", f"a camera_info of {frame}", exc)

        return callback

    def _on_image(self, frame: str) -> Callable[[dict[str, Any]], None]:
        def callback(fields: dict[str, Any]) -> None:
            camera = self.infos.get(frame)
            if camera is None:
                self.rejected["no_camera_info"] = self.rejected.get("no_camera_info", 0) + 1
                logger.info("perception: an image of %s before its camera_info: skipped", frame)
                return
            try:
                self.perception.integrate_image(fields, camera, frame=frame)
            except TaplanError as exc:
                self._reject(type(exc).__name__, f"an image of {frame}", exc)
                return
            self.last_image = self.clock()
            self.integrated += 1
            self.perception.update_scene()

        return callback

    def _on_cloud(self, topic: str, frame: str | None) -> Callable[[dict[str, Any]], None]:
        def callback(fields: dict[str, Any]) -> None:
            try:
                self.perception.integrate_cloud(fields, frame=frame)
            except TaplanError as exc:
                self._reject(type(exc).__name__, f"a point cloud on {topic}", exc)
                return
            self.integrated += 1
            self.perception.update_scene()

        return callback

    # ------------------------------------------------------------------------------------------------ health
    def monitor(self) -> str | None:
        """None while the camera stream is healthy (or has not started); else why motion should stop."""
        if self.last_image is None:
            return None
        age = self.clock() - self.last_image
        if age > self.stale_after:
            return f"no depth image for {age:.2f} s (> {self.stale_after:g} s): the perceived scene is stale"
        return None
