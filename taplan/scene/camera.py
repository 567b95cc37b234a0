"""Depth cameras: pinhole intrinsics (``sensor_msgs/CameraInfo``), depth-image decoding, and where they are mounted.

Images follow the ROS optical convention: z forward, x right, y down; a depth pixel holds the z-depth (not the range)
along its ray. ``16UC1`` images are millimetres, ``32FC1`` images metres; zero, NaN, and depths outside
``[min_range, max_range]`` mean "no measurement".

Mountings are named frames added to the robot model (:func:`add_camera_frames`) so forward kinematics gives a
camera's pose at any configuration. :data:`TELEAVATAR_CAMERAS` are the wrist depth cameras' defaults: the developer
guide names the streams (``/{left,right}/depth/image_raw``, ``/{left,right}/depth/camera_info``) but neither it nor
the vendor URDF gives the mounting, so every number there is an **estimate** (documented per mount), meant to be
replaced by a calibration through a YAML file (:func:`load_camera_mounts`)::

    cameras:
      left_depth_camera: {parent: Link-L7, xyz: [0.0, 0.05, 0.06], xyzw: [...], source: "hand-eye calibration"}
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from taplan.errors import InvalidInputError
from taplan.scene.camera_mounts import TELEAVATAR_CAMERA_FRAMES
from taplan.scene.scene import as_pose

__all__ = [
    "PinholeCamera",
    "CameraMount",
    "TELEAVATAR_CAMERAS",
    "TELEAVATAR_DEPTH_TOPICS",
    "add_camera_frames",
    "load_camera_mounts",
    "depth_to_metres",
    "look_at",
    "DEPTH_ENCODINGS",
    "WRIST_DEPTH_CAMERA",
]

DEPTH_ENCODINGS = ("16UC1", "mono16", "32FC1")


@dataclass(frozen=True)
class PinholeCamera:
    """A pinhole camera: image ``width`` x ``height`` [px], focal lengths ``fx``, ``fy`` and principal point
    ``cx``, ``cy`` [px] (the ``K`` matrix of ``sensor_msgs/CameraInfo``). Images are taken as rectified; the
    distortion coefficients of a CameraInfo are not applied."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    _rays: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 < value <= 16384:
                raise InvalidInputError(name, value, "an image size in [1, 16384] pixels")
            object.__setattr__(self, name, int(value))
        for name in ("fx", "fy", "cx", "cy"):
            value = getattr(self, name)
            ok = isinstance(value, (int, float, np.floating)) and not isinstance(value, bool) and math.isfinite(value)
            if not ok or (name in ("fx", "fy") and value <= 0):
                what = "a positive finite focal length [px]" if name in ("fx", "fy") else "a finite coordinate [px]"
                raise InvalidInputError(name, value, what)
            object.__setattr__(self, name, float(value))

    @classmethod
    def from_camera_info(cls, info: dict[str, Any]) -> PinholeCamera:
        """From a ``CameraInfo``'s fields: ``width``, ``height`` and ``k`` (row-major 3x3, ``K`` also accepted)."""
        if not isinstance(info, dict):
            raise InvalidInputError("camera_info", info, "a mapping with width, height and k")
        k = info.get("k", info.get("K"))
        try:
            K = np.asarray(k, dtype=float).reshape(3, 3)
        except (TypeError, ValueError):
            raise InvalidInputError("camera_info.k", k, "9 numbers (row-major 3x3 intrinsics)") from None
        if not np.all(np.isfinite(K)):
            raise InvalidInputError("camera_info.k", K.ravel().tolist(), "finite intrinsics")
        try:
            return cls(info.get("width"), info.get("height"), K[0, 0], K[1, 1], K[0, 2], K[1, 2])  # type: ignore[arg-type]
        except InvalidInputError as exc:
            raise InvalidInputError(f"camera_info.{exc.argument}", exc.received, exc.expected) from exc

    def to_camera_info(self) -> dict[str, Any]:
        """The ``CameraInfo`` fields (plumb_bob, no distortion, identity rectification, P = [K | 0])."""
        k = [self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0]
        return {
            "width": self.width,
            "height": self.height,
            "distortion_model": "plumb_bob",
            "d": [0.0] * 5,
            "k": k,
            "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            "p": [self.fx, 0.0, self.cx, 0.0, 0.0, self.fy, self.cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        }

    @property
    def intrinsics(self) -> tuple[float, float, float, float]:
        return self.fx, self.fy, self.cx, self.cy

    def rays(self) -> np.ndarray:
        """Per pixel the ray through its centre with z = 1 (camera frame). Shape (height, width, 3), float32."""
        if "rays" not in self._rays:
            u, v = self.ray_components()
            rays = np.empty((self.height, self.width, 3), dtype=np.float32)
            rays[:, :, 0] = u[None, :]
            rays[:, :, 1] = v[:, None]
            rays[:, :, 2] = 1.0
            self._rays["rays"] = rays
        return self._rays["rays"]

    def ray_components(self) -> tuple[np.ndarray, np.ndarray]:
        """The rays' x per column (width,) and y per row (height,) (z = 1): ray (row, col) = (x[col], y[row], 1)."""
        u = (np.arange(self.width, dtype=np.float64) + 0.5 - self.cx) / self.fx
        v = (np.arange(self.height, dtype=np.float64) + 0.5 - self.cy) / self.fy
        return u, v

    def points(self, depth: np.ndarray) -> np.ndarray:
        """The camera-frame points (N, 3) [m] of the valid (finite) pixels of a depth image in metres."""
        if depth.shape != (self.height, self.width):
            raise InvalidInputError("depth", f"shape {depth.shape}", f"({self.height}, {self.width}) as the camera")
        valid = np.isfinite(depth)
        return self.rays()[valid] * depth[valid][:, None]


def look_at(eye: Any, target: Any, up: Any = (0.0, 0.0, 1.0)) -> np.ndarray:
    """``T_root_camera`` (optical frame: z forward, y down) of a camera at ``eye`` looking at ``target`` [m], its
    image's up as close to ``up`` as possible."""
    eye, target, up = (np.asarray(v, dtype=float).reshape(3) for v in (eye, target, up))
    z = target - eye
    if not np.all(np.isfinite(z)) or np.linalg.norm(z) < 1e-9:
        raise InvalidInputError("target", target.tolist(), "a finite point away from the eye")
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = eye
    return T


def depth_to_metres(
    data: Any,
    encoding: str,
    camera: PinholeCamera,
    *,
    min_range: float = 0.0,
    max_range: float = math.inf,
    big_endian: bool = False,
    step: int | None = None,
) -> np.ndarray:
    """A depth image in metres (float32, NaN where there is no measurement) from raw bytes or an array.

    Args:
        data: ``bytes`` (an Image message's data, rows ``step`` bytes apart) or an array (height, width).
        encoding: ``16UC1``/``mono16`` (millimetres) or ``32FC1`` (metres).
        camera: Gives the expected size.
        min_range, max_range: Depths outside are no measurement [m].
    """
    if encoding not in DEPTH_ENCODINGS:
        raise InvalidInputError("encoding", encoding, f"a depth encoding, one of {list(DEPTH_ENCODINGS)}")
    H, W = camera.height, camera.width
    dtype = np.dtype(np.uint16 if encoding in ("16UC1", "mono16") else np.float32)
    dtype = dtype.newbyteorder(">" if big_endian else "<")
    if isinstance(data, (bytes, bytearray, memoryview)):
        raw = np.frombuffer(data, dtype=np.uint8)
        row = W * dtype.itemsize
        step = row if step is None else int(step)
        if step < row or len(raw) != step * H:
            raise InvalidInputError(
                "data", f"{len(raw)} bytes (step {step})", f"{H} rows of {row} bytes or more ({W}x{H} {encoding})"
            )
        image = raw.reshape(H, step)[:, :row].copy().view(dtype).reshape(H, W)
    else:
        image = np.asarray(data)
        if image.shape != (H, W):
            raise InvalidInputError("data", f"shape {image.shape}", f"({H}, {W}) as the camera info")
    metres = image.astype(np.float32)
    if dtype.kind == "u":
        metres *= np.float32(0.001)
    invalid = ~((metres > max(min_range, 0.0)) & (metres <= max_range) & np.isfinite(metres))
    metres[invalid] = np.nan
    return metres


@dataclass(frozen=True)
class CameraMount:
    """A camera's optical frame ``name`` fixed to robot frame ``parent`` at ``T_parent_camera`` (4x4)."""

    name: str
    parent: str
    T_parent_camera: np.ndarray = field(repr=False)
    source: str = ""

    def to_dict(self) -> dict[str, Any]:
        import pinocchio as pin

        quat = pin.Quaternion(self.T_parent_camera[:3, :3])
        return {
            "parent": self.parent,
            "xyz": self.T_parent_camera[:3, 3].tolist(),
            "xyzw": [quat.x, quat.y, quat.z, quat.w],
            "source": self.source,
        }


_MOUNT_SOURCE = (
    "estimate: on the wrist housing 6 cm above the gripper axis, 5 cm along the tool axis, looking along the tool axis "
    "tilted 20 deg toward the fingers (guide: a depth camera per wrist; no mounting published)"
)
# the numbers: taplan.scene.camera_mounts (the TeleAvatar's model has these frames from the start)
TELEAVATAR_CAMERAS: dict[str, CameraMount] = {
    name: CameraMount(name, parent, T, _MOUNT_SOURCE) for name, (parent, T) in TELEAVATAR_CAMERA_FRAMES.items()
}
TELEAVATAR_DEPTH_TOPICS = {
    "left_depth_camera": ("/left/depth/image_raw", "/left/depth/camera_info"),
    "right_depth_camera": ("/right/depth/image_raw", "/right/depth/camera_info"),
}
# an estimate of a wrist depth camera's intrinsics (640x480, 87 deg horizontal field of view), for the simulator
WRIST_DEPTH_CAMERA = PinholeCamera(640, 480, 337.0, 337.0, 320.0, 240.0)


def add_camera_frames(robot: Any, mounts: dict[str, CameraMount] | None = None) -> dict[str, CameraMount]:
    """Make each mount a frame of ``robot`` (default: the TeleAvatar's wrist cameras): a frame already there (the
    TeleAvatar's model has its wrist cameras from :meth:`taplan.Robot.teleavatar`) is moved to the mount in place; a
    new name is added. Returns the mounts.

    Adding a frame changes the model's size: pinocchio ``Data`` made from the model before (a ``CollisionWorld``'s,
    an IK's) is then too small for it, and using it writes past its end. Moving a frame does not; so add new camera
    frames before anything else is built on the robot."""
    import pinocchio as pin

    mounts = TELEAVATAR_CAMERAS if mounts is None else mounts
    for mount in mounts.values():
        if mount.name not in robot.frame_names:
            robot.add_frame(mount.name, mount.parent, mount.T_parent_camera)
            continue
        parent = robot.model.frames[robot.frame_id(mount.parent)]
        placement = parent.placement * pin.SE3(np.asarray(mount.T_parent_camera, dtype=float))
        frame = pin.Frame(
            mount.name, parent.parentJoint, robot.frame_id(mount.parent), placement, pin.FrameType.OP_FRAME
        )
        robot.model.frames[robot.frame_id(mount.name)] = frame
    return dict(mounts)


def load_camera_mounts(path: str | Path, defaults: dict[str, CameraMount] | None = None) -> dict[str, CameraMount]:
    """Camera mounts from YAML (``cameras: {name: {parent, xyz, xyzw, source}}``), over ``defaults`` (the
    TeleAvatar's): a named camera replaces its default, a new name adds a camera."""
    import yaml

    path = Path(path)
    if not path.is_file():
        raise InvalidInputError("camera file", str(path), "an existing YAML file")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise InvalidInputError("camera file", str(path), f"valid YAML ({exc})") from exc
    if not isinstance(data, dict) or not isinstance(data.get("cameras"), dict):
        raise InvalidInputError("cameras", data, "a mapping 'cameras: {name: {parent, xyz, xyzw}}'")
    mounts = dict(TELEAVATAR_CAMERAS if defaults is None else defaults)
    for name, entry in data["cameras"].items():
        where = f"cameras.{name}"
        if not isinstance(entry, dict) or not isinstance(entry.get("parent"), str):
            raise InvalidInputError(where, entry, "a mapping with parent (a frame), xyz [m] and xyzw")
        unknown = set(entry) - {"parent", "xyz", "xyzw", "source"}
        if unknown:
            raise InvalidInputError(where, sorted(unknown), "only the keys parent, xyz, xyzw, source")
        T = as_pose((entry.get("xyz", [0, 0, 0]), entry.get("xyzw", [0, 0, 0, 1])), f"{where}.xyz/xyzw")
        mounts[str(name)] = CameraMount(str(name), entry["parent"], T, str(entry.get("source", str(path))))
    return mounts
