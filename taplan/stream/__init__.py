"""Online motion generation at the robot's command rate: joint streaming (ruckig) and pose streaming (IK + ruckig).

* :class:`JointStreamer`: joint targets at any time -> jerk-limited commands every ``dt``, inside every limit, with a
  smooth stop when targets stop arriving.
* :class:`PoseStreamer`: end-effector pose targets for one or both arms -> differential IK -> :class:`JointStreamer`.
"""

from __future__ import annotations

from taplan.stream.joint_streamer import POSITION_TOLERANCE, JointStreamer
from taplan.stream.pose_streamer import PoseStreamer, PoseStreamState
from taplan.stream.safety import Watchdog, braking_distance, max_safe_velocity, stopping_range
from taplan.stream.state import StreamState, StreamStatus

__all__ = [
    "JointStreamer",
    "PoseStreamer",
    "PoseStreamState",
    "POSITION_TOLERANCE",
    "StreamState",
    "StreamStatus",
    "Watchdog",
    "braking_distance",
    "max_safe_velocity",
    "stopping_range",
]
