"""A perceived scene from a recorded bag: the depth images (and point clouds) of a run, each placed by the joint
states recorded around its stamp.

:func:`perceive_bag` reads both arms' ``joint_states`` into one :class:`~taplan.scene.perception.JointHistory`
(the whole run), then fuses every depth ``Image`` with the latest ``CameraInfo`` of its camera before it, and every
``PointCloud2``, in log order, as :class:`~taplan.ros.perception_link.PerceptionLink` does live. Messages that
cannot be used are counted per reason in the result, not fatal; a bag without a usable image or cloud is an error.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from taplan import api
from taplan.errors import InvalidInputError, TaplanError, UnknownNameError
from taplan.ros.bag import read_messages
from taplan.ros.sensor_fields import CAMERA_INFO, IMAGE, POINT_CLOUD2, sensor_fields
from taplan.scene.camera import TELEAVATAR_DEPTH_TOPICS, PinholeCamera
from taplan.scene.perception import JointHistory, Perception

__all__ = ["perceive_bag", "BagPerception"]


@dataclass
class BagPerception:
    """What :func:`perceive_bag` did: the perception (its ``scene`` holds the ``perceived`` obstacle), images and
    clouds fused, and messages skipped per reason."""

    perception: Perception
    images: int = 0
    clouds: int = 0
    skipped: dict[str, int] = field(default_factory=dict)


def perceive_bag(
    robot: Any,
    path: str | Path,
    *,
    cameras: Mapping[str, tuple[str, str]] | None = None,
    clouds: Mapping[str, str | None] | None = None,
    **options: Any,
) -> BagPerception:
    """Fuse a bag's depth images and point clouds into a new :class:`~taplan.scene.Perception` of ``robot``.

    Args:
        path: A rosbag2 ``.mcap`` file with ``/{side}_arm/joint_states`` and camera topics.
        cameras: ``{camera frame: (image topic, camera_info topic)}``; default the TeleAvatar's wrist cameras.
        clouds: ``{PointCloud2 topic: frame, or None for its frame_id}``.
        options: Passed to :class:`~taplan.scene.Perception` (``resolution``, ``padding``, ...).
    """
    cameras = dict(TELEAVATAR_DEPTH_TOPICS if cameras is None else cameras)
    clouds = dict(clouds or {})
    perception = Perception(robot, **options)
    for frame in cameras:
        robot.frame_id(frame)
    perception.history = JointHistory(horizon=math.inf)
    state_topics = {api.Topics.joint_states(side): side for side in api.SIDES}
    images = {image: frame for frame, (image, _) in cameras.items()}
    infos = {info: frame for frame, (_, info) in cameras.items()}
    topics = [*state_topics, *images, *infos, *clouds]
    messages = read_messages(path, topics)
    result = BagPerception(perception)

    def skip(reason: str) -> None:
        result.skipped[reason] = result.skipped.get(reason, 0) + 1

    latest: dict[str, np.ndarray] = {}
    indices = {side: robot.indices(api.ARM_JOINT_NAMES[side]) for side in api.SIDES}
    for topic, _, msg in messages:  # pass 1: the joint history of the whole run
        side = state_topics.get(topic)
        if side is None:
            continue
        try:
            latest[side] = api.parse_joint_state(side, list(msg.name), list(msg.position))
        except (InvalidInputError, UnknownNameError):
            skip("joint_state")
            continue
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        if len(latest) == len(api.SIDES) and stamp >= perception.history.latest_stamp:
            q = robot.home.copy()
            for s, values in latest.items():
                q[indices[s]] = values
            perception.history.add(stamp, q)
    known: dict[str, PinholeCamera] = {}
    for topic, _, msg in messages:  # pass 2: images and clouds in log order
        try:
            if topic in infos:
                known[infos[topic]] = PinholeCamera.from_camera_info(sensor_fields(CAMERA_INFO, msg))
            elif topic in images:
                frame = images[topic]
                if frame not in known:
                    skip("no_camera_info")
                    continue
                perception.integrate_image(sensor_fields(IMAGE, msg), known[frame], frame=frame)
                result.images += 1
            elif topic in clouds:
                perception.integrate_cloud(sensor_fields(POINT_CLOUD2, msg), frame=clouds[topic])
                result.clouds += 1
        except TaplanError as exc:
            skip(exc.argument if isinstance(exc, InvalidInputError) else type(exc).__name__)
    if not result.images and not result.clouds:
        raise InvalidInputError(
            "bag",
            f"{path} ({result.skipped or 'no camera messages'})",
            f"depth images on {sorted(images)} with their camera_info, or point clouds, and both arms' joint states",
        )
    perception.update_scene()
    return result
