"""Live targets for ``taplan run --targets``: JSON lines from a file or standard input, parsed at the edge.

One JSON object per line, either joint targets or pose targets, with an optional time ``"t"`` [s] from the start
of the stream (a file replays on that schedule; lines without ``"t"`` apply as soon as they are read):

* ``{"t": 0.5, "q": [14 positions, rad, l_joint1..7 then r_joint1..7]}``, or ``{"l_joint1": 0.1, ...}`` by name
  (unnamed joints keep their last target);
* ``{"t": 0.5, "left_ee": [x, y, z, qx, qy, qz, qw], "right_ee": [...]}``: poses in the root frame [m], quaternion
  ``xyzw``.

A line that does not parse is logged and skipped: it never reaches the robot, wherever it is in the stream (the
first line included). :class:`TargetStreamer` picks the joint or the pose streamer from the first target that
arrives, so a file and standard input behave alike, and counts what it accepted, rejected and clamped.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
from collections.abc import Iterable, Mapping
from typing import Any, TextIO

import numpy as np

from taplan.errors import InvalidInputError, TaplanError
from taplan.limits import JointLimits
from taplan.robot import Robot

__all__ = ["TargetFeed", "TargetStreamer", "parse_target"]

logger = logging.getLogger(__name__)

POSE_FRAMES = ("left_ee", "right_ee", "left_tcp", "right_tcp")


def parse_target(line: str, robot: Robot, last: np.ndarray) -> tuple[float | None, str, Any]:
    """``(time or None, "joint" | "pose", target)`` of one JSON line.

    Raises:
        InvalidInputError: not JSON, unknown keys, wrong lengths, non-finite values.
    """
    try:
        item = json.loads(line)
    except json.JSONDecodeError as exc:
        raise InvalidInputError("target line", line[:80], f"one JSON object ({exc})") from exc
    if not isinstance(item, dict):
        raise InvalidInputError("target line", line[:80], "a JSON object")
    t = item.pop("t", None)
    if t is not None and not (isinstance(t, (int, float)) and np.isfinite(t) and t >= 0):
        raise InvalidInputError("t", t, "a time >= 0 [s]")
    poses = {k: item[k] for k in POSE_FRAMES if k in item}
    if poses:
        import pinocchio as pin

        out = {}
        for frame, value in poses.items():
            v = np.asarray(value, dtype=float)
            if v.shape != (7,) or not np.all(np.isfinite(v)):
                raise InvalidInputError(frame, value, "[x, y, z, qx, qy, qz, qw], finite")
            if abs(np.linalg.norm(v[3:]) - 1.0) > 1e-3:
                raise InvalidInputError(frame, value, "a unit quaternion (xyzw)")
            T = np.eye(4)
            T[:3, :3] = pin.Quaternion(v[6], v[3], v[4], v[5]).normalized().toRotationMatrix()
            T[:3, 3] = v[:3]
            out[frame] = T
        return t, "pose", out
    if "q" in item:
        q = np.asarray(item["q"], dtype=float)
        if q.shape != (robot.nq,) or not np.all(np.isfinite(q)):
            raise InvalidInputError("q", item["q"], f"{robot.nq} finite joint positions [rad]")
        return t, "joint", q
    q = last.copy()
    for name, value in item.items():
        q[robot.indices([name])[0]] = float(value)
    if not np.all(np.isfinite(q)):
        raise InvalidInputError("target", item, "finite joint positions [rad]")
    return t, "joint", q


class TargetFeed:
    """Targets from ``lines`` (read on a background thread), handed out by time: ``feed(t)`` -> newest due target.

    Args:
        lines: A file or standard input.
        robot: The model (joint names, sizes).
        start: Initial joint target (the measured position).
    """

    def __init__(self, lines: TextIO | Iterable[str], robot: Robot, start: np.ndarray) -> None:
        self.robot = robot
        self.kind: str | None = None
        self.skipped = 0
        self._last = np.asarray(start, dtype=float).copy()
        self._queue: queue.Queue[tuple[float | None, str, Any]] = queue.Queue()
        self._pending: list[tuple[float | None, str, Any]] = []
        self._thread = threading.Thread(target=self._read, args=(lines,), daemon=True)
        self._thread.start()

    def _read(self, lines: Iterable[str]) -> None:
        for line in lines:
            if not line.strip():
                continue
            try:
                t, kind, target = parse_target(line, self.robot, self._last)
            except Exception as exc:  # noqa: BLE001 (any bad line is skipped, never sent)
                self.skipped += 1
                logger.warning("skipping target line: %s", exc)
                continue
            if kind == "joint":
                self._last = target
            self._queue.put((t, kind, target))

    def __call__(self, t: float) -> Any:
        while not self._queue.empty():
            self._pending.append(self._queue.get_nowait())
        due = None
        while self._pending and (self._pending[0][0] is None or self._pending[0][0] <= t):
            _, kind, target = self._pending.pop(0)
            if self.kind is None:
                self.kind = kind
            if kind != self.kind:
                self.skipped += 1
                logger.warning("skipping a %s target in a %s stream", kind, self.kind)
                continue
            due = target
        return due


class TargetStreamer:
    """A streamer for :meth:`taplan.ros.Runner.stream` that becomes a joint or a pose streamer with its first target.

    Until a target arrives it holds the start (a :class:`~taplan.stream.JointStreamer` at rest); the first target
    decides: joint positions keep the joint streamer, a ``{frame: pose}`` mapping switches to a
    :class:`~taplan.stream.PoseStreamer` started from the held configuration. Later targets of the other kind are
    rejected by the streamer in use (:class:`TargetFeed` already skips them).

    Args:
        robot: The model.
        limits: Joint limits of the joint streamer (the runner's).
        dt: Arm period [s].
        **pose_options: Passed to the :class:`~taplan.stream.PoseStreamer` (``scene=``, ``frames=`` ...).

    Attributes:
        kind: ``None`` until the first target, then ``"joint"`` or ``"pose"``.
        accepted: Targets the streamer took.
        rejected: Targets it refused (NaN, wrong shape, a frame it does not stream).
        clamped: Joint targets admitted after clamping into the joint limits.
    """

    def __init__(self, robot: Robot, limits: JointLimits, dt: float, **pose_options: Any) -> None:
        from taplan.stream import JointStreamer, PoseStreamer

        self.robot = robot
        self.dt = dt
        self._joint = JointStreamer(limits, dt, timeout=None)
        # built now, not at the first pose target: building the IK inside the arm loop would stall the commands
        self._pose = PoseStreamer(robot, dt, **{"timeout": None, **pose_options})
        self._active: Any = self._joint
        self._last: Any = None
        self.kind: str | None = None
        self.accepted = 0
        self.rejected = 0
        self.clamped = 0

    def reset(self, position: np.ndarray) -> Any:
        """Start holding ``position`` [rad] (clamped into the limits, as the runner does for its joint streamer)."""
        self._last = self._joint.reset(position, clamp=True)
        self._active, self.kind = self._joint, None
        return self._last

    def set_target(self, target: Any) -> None:
        """Pass ``target`` on; the first one picks the streamer. Raises the streamer's error for a bad target."""
        if self.kind is None:
            if isinstance(target, Mapping):
                self._pose.reset(self._last.position, self._last.velocity)
                self._active, self.kind = self._pose, "pose"
            else:
                self.kind = "joint"
        try:
            adjusted = self._active.set_target(target)
        except TaplanError:
            self.rejected += 1
            raise
        self.accepted += 1
        self.clamped += bool(adjusted)  # the joint streamer says when it clamped; the pose streamer's IK stays inside

    def step(self) -> Any:
        self._last = self._active.step()
        return self._last

    def summary(self, skipped: int = 0) -> str:
        """What happened to the targets, e.g. ``"12 pose targets streamed, 1 line skipped"``."""
        count = (
            f"{self.accepted} {self.kind} target{'' if self.accepted == 1 else 's'}" if self.accepted else "no target"
        )
        parts = [f"{count} streamed"]
        if self.clamped:
            parts.append(f"{self.clamped} clamped into the joint limits")
        bad = skipped + self.rejected
        if bad:
            parts.append(f"{bad} rejected (malformed or out of place; never sent)")
        return ", ".join(parts)
