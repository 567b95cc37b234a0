"""Where the viewer's motions come from besides Python objects: trajectory files, recorded bags, live DDS.

* :func:`motions_from_bag`: a rosbag2 (.mcap) of a run: the commanded (``/api/*_arm/joint_cmd``) and the measured
  (``/*_arm/joint_states``) robots, side by side on the bag's clock (read by :mod:`taplan.ros.bag`);
* :class:`LiveFollower`: the latest ``/{side}_arm/joint_states`` of a running ``taplan sim`` (or the robot) over
  DDS, shown as robot ``live``; velocities from the messages, accelerations from their differences.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from taplan.errors import InvalidInputError, UnknownNameError
from taplan.robot import Robot
from taplan.viz.motion import Motion

__all__ = ["motions_from_bag", "LiveFollower", "COMMANDED_COLOR", "MEASURED_COLOR"]

COMMANDED_COLOR = (90, 140, 220)
MEASURED_COLOR = (235, 150, 60)


def motions_from_bag(robot: Robot, path: str | Path) -> list[Motion]:
    """The commanded and measured streams of a recorded run as two motions (those present; at least one)."""
    from taplan.ros.bag import read_run

    run = read_run(path)
    motions = []
    for kind, color in (("commanded", COMMANDED_COLOR), ("measured", MEASURED_COLOR)):
        if not (run.commanded if kind == "commanded" else run.measured):
            continue
        samples = run.stream(kind)
        if len(samples) < 2:
            continue
        motions.append(Motion.from_samples(robot, samples.times, samples.positions, samples.joint_names, kind, color))
    if not motions:
        raise InvalidInputError("bag", str(path), "a bag with at least 2 joint_cmd or joint_states messages per arm")
    return motions


class LiveFollower:
    """Follow a robot's ``/{side}_arm/joint_states`` over DDS and pose live robot ``name`` of ``viewer``.

    Args:
        viewer: A :class:`~taplan.viz.Viewer` created with ``live=(name,)``.
        interface: A :class:`~taplan.ros.dds.DdsInterface` (its domain and config decide whom we hear).
        name: The live robot's name in the viewer.
        rate: Redraw rate [Hz] (messages in between only update the state).
    """

    def __init__(self, viewer: Any, interface: Any, name: str = "live", rate: float = 30.0) -> None:
        from taplan import api

        self.viewer = viewer
        self.interface = interface
        self.name = name
        self.period = 1.0 / float(rate)
        robot = viewer.robot
        self.q = robot.home.copy()
        self.v = np.zeros_like(self.q)
        self.a = np.zeros_like(self.q)
        self.received = 0
        self.rejected = 0
        self._stamp: dict[str, float] = {}
        self._index = {}
        for side in api.SIDES:
            names = api.ARM_JOINT_NAMES[side]
            if not set(names) <= set(robot.joint_names):
                continue
            self._index[side] = robot.indices(names)
            interface.create_subscription(
                api.JOINT_STATE, api.Topics.joint_states(side), lambda fields, s=side: self.on_joint_state(s, fields)
            )
        if not self._index:
            raise InvalidInputError("robot", robot.joint_names, "a robot with the TeleAvatar's l/r_joint1..7")
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def on_joint_state(self, side: str, fields: dict[str, Any]) -> None:
        """A ``/{side}_arm/joint_states`` message: update that arm's joints."""
        from taplan import api

        try:
            q = api.parse_joint_state(side, fields.get("name", []), fields.get("position", []))
        except (InvalidInputError, UnknownNameError):
            self.rejected += 1
            return
        index = self._index[side]
        now = time.monotonic()
        velocity = np.asarray(fields.get("velocity") or [], dtype=float)
        if velocity.shape == q.shape and np.all(np.isfinite(velocity)):
            last = self._stamp.get(side)
            if last is not None and now - last > 1e-4:
                self.a[index] = (velocity - self.v[index]) / (now - last)
            self.v[index] = velocity
        self._stamp[side] = now
        self.q[index] = q
        self.received += 1

    def step(self) -> None:
        """Read what arrived and redraw."""
        self.interface.spin_once()
        if self.received:
            self.viewer.set_configuration(self.name, self.q, self.v, self.a)

    def run(self, duration: float | None = None) -> None:
        """Spin and redraw at the rate until :meth:`stop`, Ctrl-C or ``duration`` [s]."""
        start = time.monotonic()
        while not self._stop.is_set() and (duration is None or time.monotonic() - start < duration):
            self.step()
            self._stop.wait(self.period)

    def start(self) -> None:
        """Run in a background thread."""
        self._thread = threading.Thread(target=self.run, name="taplan-viz-live", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
