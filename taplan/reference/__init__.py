"""Controller models that replay a plan as the robot side would see it.

* :class:`IndustrialSimulator`: the interpolate/accelerate simulator of seed 000, ``mode="seed"`` (bug for bug,
  nanosecond-exact) or ``"intended"``.
* :class:`JointTrajectoryController`: ros2_control's trajectory controller (Humble).
* :class:`JointModeRobot`: the TeleAvatar arm following ``joint_cmd`` (position-target or velocity-feedback).

Each returns a :class:`Replay`; :func:`taplan.check.check` measures it.
"""

from __future__ import annotations

from taplan.reference.industrial_simulator import IndustrialSimulator
from taplan.reference.joint_mode import ARM_KP, JointModeRobot
from taplan.reference.jtc import JointTrajectoryController
from taplan.reference.replay import JointStateSamples, Replay

__all__ = [
    "ARM_KP",
    "IndustrialSimulator",
    "JointModeRobot",
    "JointStateSamples",
    "JointTrajectoryController",
    "Replay",
]
