"""The TeleAvatar arm in joint mode, following a ``/api/<arm>/joint_cmd`` stream (``API_NOTES.md`` §4).

Commands (``sensor_msgs/JointState`` positions) arrive at any rate (50-77 Hz in practice, with jitter); the arm's
loop runs at ``rate`` (100 Hz) and at each tick uses the latest command received at or before it. Two conventions:

* ``"position"`` (TeleAvatar 2): ``position`` is the joint target. The robot clips the target to its position
  limits and tracks it with its own inner loop; modelled as reaching the target within one tick unless that needs
  more than the velocity limit (``|Δq| <= vel_limit · dt``), optionally also limiting ``|Δv| <= acc_limit · dt``
  (``acceleration_limit=True``). **[inference]**: the vendor does not document the inner loop.
* ``"velocity"`` (TeleAvatar 1 relay, ``arm_pd_controller.py``): ``v = clip(kp · (q_des - q), ±0.3 · vel_limit)``
  with ``kp = [7, 7, 10, 10, 10, 8, 8]`` per arm; the joint integrates ``v`` (ideal velocity tracking) and stops at
  its position limits; ``q_des`` is clipped to the limits first.

Both hold still before the first command and when the latest command is older than ``command_timeout`` (0.5 s in
the relay: "no command means no motion").
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np
import numpy.typing as npt

from taplan._validation import as_matrix, as_positive, as_vector
from taplan.errors import InvalidInputError
from taplan.limits import JointLimits
from taplan.reference.replay import Replay
from taplan.trajectory import Trajectory

__all__ = ["ARM_KP", "JointModeRobot"]

_SAME_INSTANT = 1e-9  # [s]: command and tick times closer than this coincide (float rounding of k / rate)
ARM_KP = (7.0, 7.0, 10.0, 10.0, 10.0, 8.0, 8.0)  # [1/s], joints 1..7 of each arm (arm_config.yml fb_kp)


class JointModeRobot:
    """Model of the arm following ``joint_cmd``.

    Args:
        limits: Joint limits (hardware ceilings); default the bundled TeleAvatar's, matched by name at replay.
        convention: ``"position"`` or ``"velocity"`` (also accepted as ``"velocity_feedback"``, as in
            :func:`taplan.api.joint_cmd`).
        rate: Loop rate [Hz].
        kp: Velocity-convention gains [1/s], shape (n,); default ``ARM_KP`` per arm.
        velocity_fraction: Velocity-convention cap as a fraction of the velocity limit.
        command_timeout: Commands older than this are ignored [s].
        acceleration_limit: Position convention: also limit the change of velocity per tick.
    """

    def __init__(
        self,
        limits: JointLimits | None = None,
        convention: Literal["position", "velocity", "velocity_feedback"] = "position",
        rate: float = 100.0,
        kp: npt.ArrayLike | None = None,
        velocity_fraction: float = 0.3,
        command_timeout: float = 0.5,
        acceleration_limit: bool = False,
    ) -> None:
        if convention == "velocity_feedback":  # the name taplan.api.joint_cmd uses for the same convention
            convention = "velocity"
        if convention not in ("position", "velocity"):
            raise InvalidInputError("convention", convention, "'position' or 'velocity' ('velocity_feedback')")
        self.limits = limits
        self.convention = convention
        self.rate = as_positive(rate, "rate")
        self.kp = None if kp is None else as_vector(kp, "kp")
        self.velocity_fraction = as_positive(velocity_fraction, "velocity_fraction")
        self.command_timeout = as_positive(command_timeout, "command_timeout")
        self.acceleration_limit = bool(acceleration_limit)

    def __repr__(self) -> str:
        return f"JointModeRobot(convention={self.convention!r}, rate={self.rate})"

    def replay(
        self,
        command_times: npt.ArrayLike,
        command_positions: npt.ArrayLike,
        initial_positions: npt.ArrayLike | None = None,
        *,
        joint_names: Sequence[str] | None = None,
        duration: float | None = None,
    ) -> Replay:
        """Motion of the arm for a command stream.

        Args:
            command_times: Arrival times [s], non-decreasing, shape (m,).
            command_positions: Targets [rad], shape (m, n).
            initial_positions: Arm state at t = 0 [rad]; default the first command.
            joint_names: n names (default the TeleAvatar's first n when n is 7 or 14).
            duration: Simulated time [s]; default the last command time + 0.5 s.
        """
        t_cmd = as_vector(command_times, "command_times")
        q_cmd = as_matrix(command_positions, "command_positions", (t_cmd.size, None))
        if t_cmd.size == 0:
            raise InvalidInputError("command_times", t_cmd, "at least one command")
        if np.any(np.diff(t_cmd) < 0):
            raise InvalidInputError("command_times", "decreasing times", "non-decreasing arrival times")
        n = q_cmd.shape[1]
        names = _names(joint_names, n)
        lim = _limits(self.limits, names)
        q0 = q_cmd[0].copy() if initial_positions is None else as_vector(initial_positions, "initial_positions", n)
        q = q0.copy()
        dt = 1.0 / self.rate
        end = t_cmd[-1] + 0.5 if duration is None else as_positive(duration, "duration")
        ticks = np.arange(1, int(np.floor(end * self.rate + 1e-9)) + 1) * dt
        # a command that arrives at a tick (to rounding) is used at that tick
        latest = np.searchsorted(t_cmd, ticks + _SAME_INSTANT, side="right") - 1
        fresh = (latest >= 0) & (ticks - t_cmd[np.maximum(latest, 0)] <= self.command_timeout)
        targets = np.clip(q_cmd[np.maximum(latest, 0)], lim.lower, lim.upper)
        out_q = np.empty((ticks.size, n))
        out_v = np.empty((ticks.size, n))
        v = np.zeros(n)
        if self.convention == "velocity":
            kp = self._kp(n)
            cap = self.velocity_fraction * lim.velocity
            for k in range(ticks.size):
                v = np.clip(kp * (targets[k] - q), -cap, cap) if fresh[k] else np.zeros(n)
                q = np.clip(q + v * dt, lim.lower, lim.upper)
                out_q[k], out_v[k] = q, v
        else:
            step = lim.velocity * dt
            dstep = lim.acceleration * dt
            for k in range(ticks.size):
                want = np.clip((targets[k] - q) / dt, -lim.velocity, lim.velocity) if fresh[k] else np.zeros(n)
                if self.acceleration_limit:
                    want = np.clip(want, v - dstep, v + dstep)
                v = want
                q = np.clip(q + np.clip(v * dt, -step, step), lim.lower, lim.upper)
                out_q[k], out_v[k] = q, v
        return Replay(
            controller=f"joint_mode[{self.convention}]",
            joint_names=names,
            times=ticks,
            positions=out_q,
            velocities=out_v,
            accelerations=None,
            rate=self.rate,
            initial_positions=q0,
            initial_velocities=np.zeros(n),
        )

    def replay_trajectory(
        self,
        trajectory: Trajectory,
        command_rate: float = 60.0,
        *,
        jitter: float = 0.0,
        seed: int | None = 0,
        initial_positions: npt.ArrayLike | None = None,
    ) -> Replay:
        """Stream ``trajectory`` as ``joint_cmd`` at ``command_rate`` [Hz] (periods perturbed uniformly by
        ±``jitter`` as a fraction of the period, seeded) and replay the arm's motion."""
        command_rate = as_positive(command_rate, "command_rate")
        if not (0.0 <= jitter < 1.0):
            raise InvalidInputError("jitter", jitter, "a fraction in [0, 1)")
        period = 1.0 / command_rate
        count = int(np.floor(trajectory.duration * command_rate)) + 1
        rng = np.random.default_rng(seed)
        periods = period * (1 + jitter * rng.uniform(-1, 1, count - 1))
        t = np.concatenate([[0.0], np.cumsum(periods)])
        t = t[t <= trajectory.duration + 1e-12]
        if t[-1] < trajectory.duration - 1e-12:
            t = np.append(t, trajectory.duration)
        q = trajectory(trajectory.times[0] + t)
        return self.replay(t, q, initial_positions, joint_names=trajectory.joint_names)

    def _kp(self, n: int) -> np.ndarray:
        if self.kp is not None:
            if self.kp.size != n:
                raise InvalidInputError("kp", self.kp, f"{n} gains")
            return self.kp
        if n % 7:
            raise InvalidInputError("kp", None, f"gains for {n} joints (the default covers 7 per arm)")
        return np.tile(ARM_KP, n // 7)


def _names(joint_names: Sequence[str] | None, n: int) -> tuple[str, ...]:
    if joint_names is not None:
        names = tuple(joint_names)
        if len(names) != n:
            raise InvalidInputError("joint_names", names, f"{n} names")
        return names
    left = tuple(f"l_joint{i}" for i in range(1, 8))
    right = tuple(f"r_joint{i}" for i in range(1, 8))
    if n == 7:
        return left
    if n == 14:
        return left + right
    return tuple(f"joint{i}" for i in range(n))


def _limits(limits: JointLimits | None, names: tuple[str, ...]) -> JointLimits:
    if limits is None:
        from taplan.robot import teleavatar_limits

        limits = teleavatar_limits()
    return limits if tuple(limits.names) == names else limits.subset(names)
