"""What a streamer emits each control period: the commanded state and a status."""

from __future__ import annotations

from enum import Enum
from typing import NamedTuple

import numpy as np

__all__ = ["StreamStatus", "StreamState"]


class StreamStatus(str, Enum):
    """Where a streamer is in its life cycle.

    * ``IDLE``: reset, no target yet; holding the initial state at rest.
    * ``MOVING``: following the latest target.
    * ``REACHED``: at rest on the latest target (within ruckig's accuracy, 1e-8 [rad]).
    * ``STOPPING``: braking smoothly to rest (timeout, ``stop()``, a reached target with a velocity, or a fault).
    * ``STOPPED``: at rest after braking; the next target resumes motion from here.
    """

    IDLE = "idle"
    MOVING = "moving"
    REACHED = "reached"
    STOPPING = "stopping"
    STOPPED = "stopped"


class StreamState(NamedTuple):
    """One command of the stream, ``dt`` after the previous one.

    Attributes:
        time: Stream time since ``reset`` [s].
        position: Commanded position [rad]. Shape (n,).
        velocity: Commanded velocity [rad]/[s]. Shape (n,).
        acceleration: Commanded acceleration [rad]/[s]². Shape (n,).
        jerk: Jerk over the last period [rad]/[s]³. Shape (n,).
        status: See :class:`StreamStatus`.
        new_calculation: True when a new trajectory was computed this period (new target, stop, fallback, or the
            time-synchronised re-plan of ``synchronization="auto"``).
        target_adjusted: True when the current target was changed to keep the motion inside the limits (position
            clamped into the bounds, target velocity reduced or dropped); the requested values are never silently
            lost: they stay in ``JointStreamer.requested_target``.
        fault: Reason of the last fallback to braking (a ruckig failure), or None.
    """

    time: float
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray
    status: StreamStatus
    new_calculation: bool = False
    target_adjusted: bool = False
    fault: str | None = None

    @property
    def reached(self) -> bool:
        """True when at rest on the latest target."""
        return self.status is StreamStatus.REACHED

    @property
    def at_rest(self) -> bool:
        """True when the stream holds still (idle, reached or stopped)."""
        return self.status in (StreamStatus.IDLE, StreamStatus.REACHED, StreamStatus.STOPPED)
