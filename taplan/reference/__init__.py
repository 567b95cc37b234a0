"""Controller models that replay a plan as the robot side would see it (see each module's docstring)."""

from __future__ import annotations

from taplan.reference.industrial_simulator import IndustrialSimulator
from taplan.reference.replay import JointStateSamples, Replay

__all__ = ["IndustrialSimulator", "JointStateSamples", "Replay"]
