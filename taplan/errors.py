"""Exceptions raised by taplan.

Every failure is a :class:`TaplanError`. Subclasses say which part failed and carry the offending values, so a
caller can catch narrowly and a log line can say what to change.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "TaplanError",
    "InvalidInputError",
    "InvalidLimitsError",
    "UnknownNameError",
    "ConfigError",
    "InfeasibleError",
    "SolverError",
    "TimingError",
    "StreamError",
    "CollisionError",
    "PlanningError",
    "UnseenSpaceError",
]


class TaplanError(Exception):
    """Base class of every error taplan raises."""


class InvalidInputError(TaplanError, ValueError):
    """An argument has the wrong shape, type or value.

    Attributes:
        argument: Name of the offending argument.
        received: What was received (possibly abbreviated).
    """

    def __init__(self, argument: str, received: Any, expected: str) -> None:
        self.argument = argument
        self.received = received
        self.expected = expected
        super().__init__(f"{argument}: expected {expected}, received {_abbreviate(received)}")


class InvalidLimitsError(InvalidInputError):
    """A joint limit is malformed; the message names the field and the joint."""

    def __init__(self, field: str, joint: str | None, received: Any, expected: str) -> None:
        self.field = field
        self.joint = joint
        where = f"{field}[{joint}]" if joint is not None else field
        super().__init__(where, received, expected)


class UnknownNameError(TaplanError, KeyError):
    """A joint, frame, group or option name is not known; the message lists the valid names."""

    def __init__(self, kind: str, name: Any, valid: list[str] | tuple[str, ...]) -> None:
        self.kind = kind
        self.name = name
        self.valid = tuple(valid)
        shown = ", ".join(map(str, self.valid[:40])) + (", ..." if len(self.valid) > 40 else "")
        super().__init__(f"unknown {kind} {name!r}; valid: {shown}")

    def __str__(self) -> str:  # KeyError would quote the whole message
        return str(self.args[0])


class ConfigError(TaplanError):
    """A configuration file is missing, unreadable or does not follow its schema."""


class InfeasibleError(TaplanError):
    """A problem has no solution that satisfies its hard constraints (e.g. an unreachable pose)."""


class SolverError(TaplanError):
    """A numerical solver failed. ``problem`` holds what was sent to it, for inspection."""

    def __init__(self, message: str, problem: Any = None) -> None:
        self.problem = problem
        super().__init__(message)


class TimingError(TaplanError):
    """Time parameterisation failed (TOPP-RA, ruckig or the trajectory optimiser)."""


class StreamError(TaplanError):
    """A streaming target was rejected; the stream keeps its last good motion."""


def _abbreviate(value: Any, limit: int = 120) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


class CollisionError(TaplanError):
    """A configuration (or a path) is in collision; names the pair and the penetration depth.

    Attributes:
        argument: What was checked (``"start"``, ``"goal"``, ...).
        pair: The colliding bodies ``(robot body, other body or obstacle)``.
        depth: Penetration depth [m] (> 0), or minus the distance when the bodies are apart but closer than
            ``clearance``.
        clearance: The clearance that was required [m].
    """

    def __init__(self, argument: str, pair: tuple[str, str], depth: float, clearance: float = 0.0) -> None:
        self.argument = argument
        self.pair = tuple(pair)
        self.depth = float(depth)
        self.clearance = float(clearance)
        if self.depth >= 0.0:
            text = f"{pair[0]} collides with {pair[1]} (penetration {self.depth * 1e3:.1f} mm)"
        else:
            text = (
                f"{pair[0]} is {-self.depth * 1e3:.1f} mm from {pair[1]}, inside the required clearance of "
                f"{self.clearance * 1e3:.1f} mm"
            )
        super().__init__(f"{argument}: {text}")


class PlanningError(TaplanError):
    """No collision-free motion was found; the message says which stage failed and why."""


class UnseenSpaceError(PlanningError):
    """A motion in a perceived scene needs space no camera view has seen free (and views could not see it).

    Attributes:
        unseen: Centres (N, 3) [m, root frame] of the unseen voxels the motion needed.
    """

    def __init__(self, message: str, unseen: object = ()) -> None:
        super().__init__(message)
        self.unseen = unseen
