"""A timed trajectory against a scene: its clearance at every instant, the closest pair and when, pass or fail.

What ``taplan check PLAN --scene FILE`` prints and what ``taplan run PLAN --scene FILE`` refuses on. The verdict is
the certificate of :func:`~taplan.planning.verify_trajectory` (conservative advancement: no instant closer than
``margin``, not only the samples); the closest pair and its time come from samples over the whole trajectory at
``sample_rate`` plus every configuration the certificate evaluated, so a failing plan reports its deepest point,
not only the first one the certificate stopped at.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from taplan.errors import InvalidInputError
from taplan.planning.verify import verify_trajectory
from taplan.scene.world import CollisionWorld
from taplan.trajectory import Trajectory

__all__ = ["SceneClearance", "scene_clearance"]

SAMPLE_RATE = 100.0  # [Hz]: samples locating the closest instant (the verdict does not depend on them)


@dataclass(frozen=True)
class SceneClearance:
    """The clearance of a timed trajectory in a scene.

    Attributes:
        passed: Certified to keep more than ``margin`` at every instant.
        margin: The clearance asked for [m].
        min_clearance: The smallest signed distance found [m] (negative: penetration depth).
        pair: Its pair (robot body or attached object, other body or obstacle).
        time: When [s], trajectory time.
        evaluations: Configurations evaluated (certificate and samples).
    """

    passed: bool
    margin: float
    min_clearance: float
    pair: tuple[str, str]
    time: float
    evaluations: int

    def summary(self) -> str:
        """One line: verdict, closest pair, time and margin."""
        where = f"{self.pair[0]} / {self.pair[1]} at t = {self.time:.3f} s"
        if self.min_clearance < 0:
            closest = f"{-self.min_clearance * 1e3:.1f} mm inside ({where})"
        else:
            closest = f"closest {self.min_clearance * 1e3:.1f} mm ({where})"
        verdict = "PASS" if self.passed else "FAIL"
        return f"scene clearance: {verdict}: {closest}; margin {self.margin * 1e3:.1f} mm"

    def to_dict(self) -> dict[str, Any]:
        return {
            "passed": self.passed,
            "margin": self.margin,
            "min_clearance": self.min_clearance,
            "pair": list(self.pair),
            "time": self.time,
            "evaluations": self.evaluations,
        }


def scene_clearance(
    world: CollisionWorld,
    trajectory: Trajectory,
    margin: float = 0.0,
    *,
    hold: npt.ArrayLike | None = None,
    sample_rate: float = SAMPLE_RATE,
) -> SceneClearance:
    """Check ``trajectory`` against ``world`` (its scene and, when the world has them, the robot's own pairs).

    Args:
        world: The robot and the scene.
        trajectory: Joints matched by name to the robot; the others hold ``hold``.
        margin: Clearance [m] that must be kept at every instant (0: no contact). >= 0.
        hold: Positions [rad] (nq,) of the joints the trajectory does not drive; default the robot's home.
        sample_rate: Rate [Hz] of the samples that locate the closest instant.

    Raises:
        InvalidInputError: negative or non-finite ``margin``, bad ``sample_rate`` or ``hold``, or trajectory joints
            the robot does not have.
    """
    if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not (math.isfinite(margin) and margin >= 0):
        raise InvalidInputError("margin", margin, "a clearance >= 0 [m]")
    if not (isinstance(sample_rate, (int, float)) and math.isfinite(sample_rate) and sample_rate > 0):
        raise InvalidInputError("sample_rate", sample_rate, "a positive rate [Hz]")
    robot = world.robot
    index = robot.indices(trajectory.joint_names)
    base = robot.home if hold is None else robot.check_configuration(hold, "hold")
    verdict = verify_trajectory(world, trajectory, floor=float(margin), hold=base)
    lowest, pair, when = verdict.min_clearance, verdict.pair, verdict.time
    start, end = float(trajectory.times[0]), float(trajectory.times[-1])
    count = max(2, int(math.ceil((end - start) * sample_rate)) + 1)
    times = np.linspace(start, end, count)
    configurations = np.repeat(base[None, :], count, axis=0)
    configurations[:, index] = trajectory(times)
    for t, q in zip(times, configurations, strict=True):
        d, p = world.distances(q, jacobian=False).closest()
        if d < lowest:
            lowest, pair, when = d, p, float(t)
    passed = verdict.collision_free and lowest > margin
    return SceneClearance(passed, float(margin), float(lowest), pair, when, verdict.evaluations + count)
