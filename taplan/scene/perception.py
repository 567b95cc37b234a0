"""Perceived geometry: depth images and point clouds fused into an occupancy obstacle of a :class:`Scene`.

:class:`Perception` owns an :class:`~taplan.scene.occupancy.OccupancyGrid` and keeps one obstacle (``name``,
default ``"perceived"``) of its scene equal to the grid's occupied voxels, so everything that evaluates the scene
(:class:`~taplan.scene.CollisionWorld`: the optimiser, IK dampers, planners, certificates) respects what was seen.

An image is placed by the camera's pose at its capture time: forward kinematics of the camera frame at the
configuration the robot had then (:class:`JointHistory` interpolates recorded joint states). Before its points are
inserted, the voxels the image sees through are freed, and points on the robot's own bodies (each capsule plus
``padding``, at that configuration) are dropped. The core is pure: time is a parameter, nothing runs by itself.

Unseen space is not free space. Inside ``workspace`` every voxel is occupied, known free (an image saw past it, or
the robot's own padded bodies filled it at a capture configuration or at :meth:`Perception.mark_robot_free`) or
unknown. With ``unknown="occupied"`` (the default) the unknown voxels are a second obstacle, ``<name>_unknown``, so a
plan stays in space a camera has seen (MoveIt's and cuRobo's treatment of unknown space); ``unknown="free"`` keeps
only what was hit.
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from taplan.errors import InvalidInputError
from taplan.scene.camera import TELEAVATAR_CAMERAS, CameraMount, PinholeCamera, add_camera_frames, depth_to_metres
from taplan.scene.occupancy import DEFAULT_BOUNDS, DEFAULT_RESOLUTION, Occupancy, OccupancyGrid
from taplan.scene.pointcloud import cloud_to_points
from taplan.scene.robot_bodies import robot_bodies
from taplan.scene.scene import Scene, as_pose

__all__ = ["Perception", "JointHistory", "Integration", "DEFAULT_WORKSPACE"]

# where the TeleAvatar's hands work, in front of its chest (root frame) [m]: unknown space counts there
DEFAULT_WORKSPACE = ((0.2, -0.7, -0.7), (1.0, 0.7, 0.2))
UNKNOWN = ("occupied", "occluded", "free")


class JointHistory:
    """Recent configurations by time, for the configuration at a sensor's capture time.

    Args:
        horizon: Seconds of history kept [s].
        tolerance: How far past the newest state a stamp may be and still use it [s].
    """

    def __init__(self, horizon: float = 5.0, tolerance: float = 0.05) -> None:
        self.horizon = float(horizon)
        self.tolerance = float(tolerance)
        self._stamps: deque[float] = deque()
        self._states: deque[np.ndarray] = deque()

    def __len__(self) -> int:
        return len(self._stamps)

    def add(self, stamp: float, q: npt.ArrayLike) -> None:
        """Record configuration ``q`` at ``stamp`` [s] (stamps must not go back)."""
        if not math.isfinite(stamp) or (self._stamps and stamp < self._stamps[-1]):
            raise InvalidInputError("stamp", stamp, "a finite time not before the previous joint state")
        self._stamps.append(float(stamp))
        self._states.append(np.array(q, dtype=float))
        while self._stamps and self._stamps[0] < stamp - self.horizon:
            self._stamps.popleft()
            self._states.popleft()

    @property
    def latest_stamp(self) -> float:
        """Stamp of the newest state [s] (-inf when empty)."""
        return self._stamps[-1] if self._stamps else -math.inf

    def at(self, stamp: float) -> np.ndarray:
        """The configuration at ``stamp`` [s], linearly interpolated between the recorded ones."""
        if not self._stamps:
            raise InvalidInputError("stamp", stamp, "a time after a joint state was received (none yet)")
        first, last = self._stamps[0], self._stamps[-1]
        if not (first <= stamp <= last + self.tolerance):
            raise InvalidInputError("stamp", stamp, f"a time within the joint states' [{first:.3f}, {last:.3f}] s")
        if stamp >= last:
            return self._states[-1].copy()
        k = bisect.bisect_right(self._stamps, stamp)  # deque supports indexing; stamps are sorted
        t0, t1 = self._stamps[k - 1], self._stamps[k]
        s = 0.0 if t1 <= t0 else (stamp - t0) / (t1 - t0)
        return (1 - s) * self._states[k - 1] + s * self._states[k]


@dataclass(frozen=True)
class Integration:
    """What one image or cloud did: points it measured, points kept after the robot and the bounds, voxels it
    freed, and the camera (or cloud frame) pose used (4x4)."""

    measured: int
    kept: int
    cleared: int
    pose: np.ndarray


class Perception:
    """Fuse depth images and point clouds into ``scene`` (a new one when None).

    Args:
        robot: The robot (camera frames are added to its model).
        scene: The scene that gets the occupancy obstacle ``name``.
        resolution: Voxel edge [m]; bounds: the mapped box of the root frame [m]; decay: see
            :class:`~taplan.scene.occupancy.OccupancyGrid`.
        padding: Points within a robot body's radius plus this [m] are the robot's own and dropped.
        min_range, max_range: Depths outside are no measurement [m].
        clear_margin: A voxel is freed when an image sees at least this much beyond its centre [m] (default two
            voxels: depth noise and the voxel's own extent).
        thickness: Depth [m] behind each depth-image hit that is occupied too (surfaces taken as solids at least
            that thick; 0: the hit's voxel only).
        cameras: Mounts to add as frames (default: the TeleAvatar's wrist cameras when the model is the
            TeleAvatar's, else none).
        unknown: ``"occupied"``: the voxels of ``workspace`` no image has seen past (and the robot never filled)
            are obstacle ``<name>_unknown`` of the scene; ``"free"``: unseen space is free (only hits block).
        workspace: The box [m, root frame] where unknown space counts (default :data:`DEFAULT_WORKSPACE`).
        free_margin: A voxel is known free when an image sees at least this much beyond its centre [m] (default
            half its diagonal: its whole box is in front of the surface).
    """

    def __init__(
        self,
        robot: Any,
        scene: Scene | None = None,
        *,
        name: str = "perceived",
        resolution: float = DEFAULT_RESOLUTION,
        bounds: Any = DEFAULT_BOUNDS,
        padding: float = 0.02,
        min_range: float = 0.05,
        max_range: float = 3.0,
        clear_margin: float | None = None,
        decay: float | None = None,
        thickness: float = 0.0,
        cameras: dict[str, CameraMount] | None = None,
        unknown: str = "occluded",
        workspace: Any = DEFAULT_WORKSPACE,
        free_margin: float | None = None,
    ) -> None:
        if unknown not in UNKNOWN:
            raise InvalidInputError("unknown", unknown, f"one of {UNKNOWN}")
        if not (isinstance(padding, (int, float)) and math.isfinite(padding) and padding >= 0):
            raise InvalidInputError("padding", padding, "a distance >= 0 [m]")
        if not (0 <= min_range < max_range) or not math.isfinite(min_range):
            raise InvalidInputError("min_range/max_range", (min_range, max_range), "0 <= min_range < max_range [m]")
        self.robot = robot
        self.scene = scene if scene is not None else Scene()
        self.name = name
        self.unknown = unknown
        self.grid = OccupancyGrid(resolution, bounds, decay=decay, region=workspace if unknown != "free" else None)
        self.padding = float(padding)
        if not (isinstance(thickness, (int, float)) and 0 <= thickness <= 1):
            raise InvalidInputError("thickness", thickness, "a depth in [0, 1] m")
        self.thickness = float(thickness)
        self.min_range, self.max_range = float(min_range), float(max_range)
        self.clear_margin = 2 * self.grid.resolution if clear_margin is None else float(clear_margin)
        half_diagonal = self.grid.resolution * math.sqrt(3) / 2
        self.free_margin = half_diagonal if free_margin is None else float(free_margin)
        if not (math.isfinite(self.free_margin) and self.free_margin >= 0):
            raise InvalidInputError("free_margin", free_margin, "a distance >= 0 [m]")
        if cameras is None:
            cameras = TELEAVATAR_CAMERAS if {"Link-L7", "Link-R7"} <= set(robot.frame_names) else {}
        self.cameras = add_camera_frames(robot, cameras)
        self.bodies = robot_bodies(robot)
        self.history = JointHistory()
        self._data = robot.model.createData()
        self._published = -1
        self._fixed_keys: np.ndarray | None = None

    # -------------------------------------------------------------------------------------------- geometry
    def _configuration(self, q: npt.ArrayLike | None, stamp: float | None) -> np.ndarray:
        if q is None:
            if stamp is None:
                raise InvalidInputError("q", None, "a configuration, or a stamp with joint states in the history")
            return self.history.at(stamp)
        return self.robot.check_configuration(q)

    def frame_pose(self, frame: str, q: npt.ArrayLike) -> np.ndarray:
        """``T_root_frame`` of a robot frame (e.g. a camera's) at ``q``."""
        frame_id = self.robot.frame_id(frame)
        pin.framesForwardKinematics(self.robot.model, self._data, np.asarray(q, dtype=float))
        return self._data.oMf[frame_id].homogeneous.copy()

    def robot_segments(self, q: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The robot's bodies at ``q``: segment starts, ends (B, 3) [m, root frame] and radii (B,)."""
        pin.forwardKinematics(self.robot.model, self._data, np.asarray(q, dtype=float))
        starts = np.array([self._data.oMi[b.joint].act(b.start) for b in self.bodies]).reshape(-1, 3)
        ends = np.array([self._data.oMi[b.joint].act(b.end) for b in self.bodies]).reshape(-1, 3)
        return starts, ends, np.array([b.radius for b in self.bodies])

    def _own_voxels(self, q: np.ndarray) -> np.ndarray:
        """Keys of the voxels within padding of the robot's bodies at ``q`` (bodies fixed to the root: once)."""
        starts, ends, radii = self.robot_segments(q)
        fixed = np.array([b.joint == 0 for b in self.bodies], dtype=bool)
        if self._fixed_keys is None:
            self._fixed_keys = self.grid.near_segments(starts[fixed], ends[fixed], radii[fixed] + self.padding)
        moving = self.grid.near_segments(starts[~fixed], ends[~fixed], radii[~fixed] + self.padding)
        return np.concatenate([self._fixed_keys, moving])

    def mark_robot_free(self, q: npt.ArrayLike) -> int:
        """Mark known free the space of the robot's bodies (plus ``padding``) at ``q``: the robot stands there, so
        nothing else does (the configuration a plan starts from). Returns how many voxels were unknown."""
        return self.grid.mark_free(self._own_voxels(self.robot.check_configuration(q)))

    def _pose(self, frame: str | None, T: Any, q: np.ndarray, what: str) -> np.ndarray:
        if T is not None:
            return as_pose(T, what)
        if frame is None:
            raise InvalidInputError("frame", None, f"the {what} frame (a robot frame such as a camera's) or {what}")
        return self.frame_pose(frame, q)

    # ------------------------------------------------------------------------------------------ integration
    def integrate_depth(
        self,
        image: Any,
        camera: PinholeCamera | dict[str, Any],
        *,
        frame: str | None = None,
        q: npt.ArrayLike | None = None,
        stamp: float | None = None,
        encoding: str | None = None,
        T_root_camera: Any = None,
        step: int | None = None,
        big_endian: bool = False,
        robot_there: bool = True,
        nothing_unshadows: bool = False,
    ) -> Integration:
        """Fuse one depth image.

        Args:
            image: An array (height, width): float metres (``32FC1``) or uint16 millimetres (``16UC1``), or an
                Image message's ``bytes`` with ``encoding``, ``step`` and ``big_endian``.
            camera: Its intrinsics (a :class:`PinholeCamera` or CameraInfo fields).
            frame: The camera's frame in the robot model (e.g. ``"left_depth_camera"``), posed by FK at the
                capture configuration; or give ``T_root_camera`` (4x4) directly.
            q: The configuration at capture time; None: from :attr:`history` at ``stamp``.
            stamp: Capture time [s] (also the voxels' "seen" time for ``decay``).
            robot_there: The robot stood at the capture configuration, so its padded bodies' space is marked known
                free; False (an image rendered at a configuration the robot did not move to): only the image
                marks space known free (the bodies still filter their own points).
            nothing_unshadows: With ``unknown="occluded"``: shadowed voxels this image views into nothing (no
                return around their pixel; see :meth:`OccupancyGrid.unshadow_seen_into_nothing`) no longer count,
                and voxels an image viewed into nothing are not shadowed again by this one.
                Right for rendered images; a real camera also returns nothing from dark or too-close surfaces.
        """
        camera = camera if isinstance(camera, PinholeCamera) else PinholeCamera.from_camera_info(camera)
        if encoding is None:
            dtype = getattr(image, "dtype", None)
            if dtype is None or dtype.kind not in "uf":
                raise InvalidInputError("encoding", None, "16UC1 or 32FC1 for raw image bytes")
            encoding = "16UC1" if dtype.kind == "u" else "32FC1"
        depth = depth_to_metres(
            image,
            encoding,
            camera,
            min_range=self.min_range,
            max_range=self.max_range,
            big_endian=big_endian,
            step=step,
        )
        q_capture = self._configuration(q, stamp)
        T = self._pose(frame, T_root_camera, q_capture, "T_root_camera")
        cleared = self.grid.clear_seen_through(depth, camera.intrinsics, T, self.clear_margin)
        ray_x, ray_y = camera.ray_components()
        own = self._own_voxels(q_capture)
        measured, kept = self.grid.insert_image(
            depth,
            ray_x,
            ray_y,
            T,
            0.0 if stamp is None else stamp,
            exclude=own,
            thickness=self.thickness,
        )
        if self.unknown != "free":
            # "occluded": what the robot's own bodies hide counts as viewed, not as hidden (the wrist camera's own
            # gripper fills a quarter of every image); "occupied" counts only what was seen past
            ignore = self.grid.excluded_pixels if self.unknown == "occluded" else None
            unshadow = nothing_unshadows and self.unknown == "occluded"
            self.grid.mark_seen_free(
                depth,
                camera.intrinsics,
                T,
                self.free_margin,
                max_range=self.max_range,
                ignore=ignore,
                keep_into_nothing=unshadow,  # what an image viewed into nothing is not shadowed again
            )
            if nothing_unshadows and self.unknown == "occluded":
                self.grid.unshadow_seen_into_nothing(
                    depth, camera.intrinsics, T, max_range=self.max_range, ignore=self.grid.excluded_pixels
                )
        if robot_there:
            self.grid.mark_free(own)  # the robot filled its own space when the image was taken
        return Integration(measured, kept, cleared, T)

    def integrate_points(
        self,
        points: npt.ArrayLike,
        *,
        frame: str | None = None,
        q: npt.ArrayLike | None = None,
        stamp: float | None = None,
        T_root_frame: Any = None,
    ) -> Integration:
        """Fuse a point cloud (N, 3) [m] given in ``frame`` (a robot frame posed by FK at the capture configuration;
        the root frame when neither ``frame`` nor ``T_root_frame`` is given). NaN points are skipped. Clouds add
        occupancy only (a cloud has no rays: it marks no space known free, except the robot's own); use ``decay``
        to forget what is no longer there."""
        P = np.asarray(points, dtype=float)
        if P.ndim != 2 or P.shape[1] != 3:
            raise InvalidInputError("points", f"shape {P.shape}", "(N, 3) positions [m]")
        q_capture = self._configuration(q, stamp)
        T = (
            np.eye(4)
            if frame is None and T_root_frame is None
            else self._pose(frame, T_root_frame, q_capture, "T_root_frame")
        )
        world = P @ T[:3, :3].T + T[:3, 3]
        own = self._own_voxels(q_capture)
        kept = self.grid.insert(world, 0.0 if stamp is None else stamp, exclude=own)
        self.grid.mark_free(own)
        return Integration(len(P), kept, 0, T)

    def integrate_image(
        self,
        image: dict[str, Any],
        camera_info: dict[str, Any] | PinholeCamera,
        *,
        frame: str | None = None,
        q: npt.ArrayLike | None = None,
        stamp: float | None = None,
    ) -> Integration:
        """Fuse a ``sensor_msgs/Image`` (its fields: ``height``, ``width``, ``encoding``, ``step``, ``is_bigendian``,
        ``data``, ``stamp``, ``frame_id``) with its ``CameraInfo``. The camera is ``frame`` (default the image's
        ``frame_id``), posed at the configuration of ``q`` or, by default, of :attr:`history` at the image's stamp.

        Raises:
            InvalidInputError: Wrong encoding, a size that differs from the camera info, NaN intrinsics, a data
                length that does not fit (the message names the field). UnknownNameError: the frame is not the
                robot's.
        """
        camera = camera_info if isinstance(camera_info, PinholeCamera) else PinholeCamera.from_camera_info(camera_info)
        if not isinstance(image, dict):
            raise InvalidInputError("image", type(image).__name__, "an Image's fields as a mapping")
        for name in ("height", "width"):
            if image.get(name) != getattr(camera, name):
                raise InvalidInputError(f"image.{name}", image.get(name), f"{getattr(camera, name)} as the camera info")
        data = image.get("data")
        if not isinstance(data, (bytes, bytearray, memoryview)):
            raise InvalidInputError("image.data", type(data).__name__, "bytes")
        return self.integrate_depth(
            data,
            camera,
            frame=frame if frame is not None else (image.get("frame_id") or None),
            q=q,
            stamp=image.get("stamp") if stamp is None and q is None else stamp,
            encoding=str(image.get("encoding", "")),
            step=image.get("step"),
            big_endian=bool(image.get("is_bigendian", False)),
        )

    def integrate_cloud(
        self,
        cloud: dict[str, Any],
        *,
        frame: str | None = None,
        q: npt.ArrayLike | None = None,
        stamp: float | None = None,
    ) -> Integration:
        """Fuse a ``sensor_msgs/PointCloud2`` (its fields, :func:`~taplan.scene.pointcloud.cloud_to_points`), given
        in ``frame`` (default its ``frame_id``; empty: the root frame) at the configuration of ``q`` or of
        :attr:`history` at its stamp."""
        points = cloud_to_points(cloud)
        frame = frame if frame is not None else (cloud.get("frame_id") or None)
        if frame is not None:
            self.robot.frame_id(frame)  # an unknown frame is an error before anything is inserted
        if q is None and stamp is None:
            stamp = cloud.get("stamp")
        return self.integrate_points(points, frame=frame, q=q, stamp=stamp)

    def expire(self, now: float) -> int:
        """Drop voxels older than the grid's ``decay`` at time ``now`` [s]."""
        return self.grid.expire(now)

    def occupancy(self) -> Occupancy:
        return self.grid.snapshot()

    @property
    def unknown_name(self) -> str:
        """The scene obstacle of the workspace's unknown voxels (with ``unknown="occupied"``)."""
        return self.name + "_unknown"

    def update_scene(self) -> Occupancy | None:
        """Put the occupied voxels into the scene as obstacle ``name`` and, with ``unknown="occupied"``, the
        workspace's unknown voxels as obstacle :attr:`unknown_name` (only when the grid changed). Returns the new
        occupied shape, or None when nothing changed."""
        if self.grid.version == self._published:
            return None
        shape = self.grid.snapshot()
        self.scene.put(self.name, shape)
        if self.unknown != "free":
            which = "all" if self.unknown == "occupied" else "occluded"
            self.scene.put(self.unknown_name, self.grid.unknown_snapshot(which))
        self._published = self.grid.version
        return shape
