"""Live targets for ``taplan run --targets``: JSON lines from a file or standard input, parsed at the edge.

One JSON object per line, either joint targets or pose targets, with an optional time ``"t"`` [s] from the start
of the stream (a file replays on that schedule; lines without ``"t"`` apply as soon as they are read):

* ``{"t": 0.5, "q": [14 positions, rad, l_joint1..7 then r_joint1..7]}``, or ``{"l_joint1": 0.1, ...}`` by name
  (unnamed joints keep their last target);
* ``{"t": 0.5, "left_ee": [x, y, z, qx, qy, qz, qw], "right_ee": [...]}``: poses in the root frame [m], quaternion
  ``xyzw``.

A line that does not parse is logged and skipped: it never reaches the robot.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
from collections.abc import Iterable
from typing import Any, TextIO

import numpy as np

from taplan.errors import InvalidInputError
from taplan.robot import Robot

__all__ = ["TargetFeed", "parse_target"]

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
