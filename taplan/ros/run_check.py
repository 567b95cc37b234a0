"""Check a recorded run (a rosbag2 file) with taplan's report: commands, their timing, heartbeats, measurements.

* **Commands** (``/api/{side}_arm/joint_cmd``, both arms): :func:`taplan.check.check` on the sequence the robot
  received, on the nominal grid of the stream's rate (the robot's inner loop takes them in order, not at their
  log times): position, velocity, acceleration and jerk limits, velocity steps, smoothness.
* **Command timing**: the log times' periods against the nominal rate (RMS jitter, gaps, repeats), reported.
* **Heartbeat**: the largest interval between ``/api/fsm/enable`` messages with data > 0; above
  ``max_heartbeat_gap`` (100 ms) the run fails. Disables are counted.
* **Measured** (``/{side}_arm/joint_states``, what a real robot's recording holds; a bag with only these is checked
  too, and then decides the verdict; with commands present the commands decide and the measured derivatives are
  marked per joint): positions against the limits, and velocity, acceleration and velocity steps of the *measured
  positions* after a documented filter: a centred moving average over ``MEASURED_WINDOW`` (30 ms, 3 samples at the
  robot's 100 Hz) on the nominal grid of the stream's rate. It absorbs encoder noise and the aliasing of a command
  rate (50-77 Hz) against the 100 Hz sampling (a joint-mode arm moves in steps of whole commands); a genuine
  velocity step is spread over the window, so a step ``Δv`` fails where ``Δv / window > a_max (1 +
  MEASURED_TOLERANCE)``: 2.5 rad/s fails on joints 3-7 of the TeleAvatar (``a_max`` 60, 17, 14 rad/s²) and passes on
  joints 1-2 (120 rad/s², reached in 21 ms: not distinguishable from a fast but legal start at 100 Hz).
  ``MEASURED_TOLERANCE`` (25 %) is the servo's tracking overshoot; jerk is reported, not judged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from taplan.check import Report, Thresholds, TimingCheck, check, stream_timing
from taplan.limits import JointLimits
from taplan.reference.replay import JointStateSamples
from taplan.ros.bag import RecordedRun

__all__ = ["RunReport", "check_run", "MAX_HEARTBEAT_GAP"]

MAX_HEARTBEAT_GAP = 0.1  # [s] the heartbeat runs at 20 Hz; the robot pauses after 1 s without
MEASURED_WINDOW = 0.03  # [s] moving average of measured positions before their derivatives are judged
MEASURED_TOLERANCE = 0.25  # allowed excess of measured velocity and acceleration over the limits (servo overshoot)


@dataclass(frozen=True)
class RunReport:
    """The checks of one recorded run."""

    commanded: Report | None
    command_timing: TimingCheck | None
    measured: Report | None
    heartbeats: int
    heartbeat_max_gap: float
    max_heartbeat_gap: float
    disables: int
    rejected: int

    @property
    def heartbeat_ok(self) -> bool:
        return self.heartbeats >= 2 and self.heartbeat_max_gap <= self.max_heartbeat_gap

    @property
    def measured_positions_ok(self) -> bool:
        return self.measured is None or all(j.position_violation <= 1e-9 for j in self.measured.joints)

    @property
    def passed(self) -> bool:
        if self.commanded is None:  # a robot's own recording: what it measured is all there is to judge
            return self.measured is not None and self.measured.passed
        # with commands, the run is judged on what taplan sent (the commands, the heartbeat) and the measured
        # positions; the measured derivatives are marked per joint but depend on the robot's servo (a simulator's
        # joint mode moves in whole command steps), so they do not decide the verdict
        return self.commanded.passed and self.heartbeat_ok and self.measured_positions_ok

    def table(self) -> str:
        t = self.command_timing
        if self.commanded is None or t is None:
            lines = ["commanded stream: none in this bag (a robot's recording): the measured stream is judged"]
        else:
            lines = [
                "commanded stream (nominal grid):",
                self.commanded.table(),
                f"command timing: {t.periods} periods, expected {t.expected_period * 1e3:.2f} ms, "
                f"{t.min_period * 1e3:.2f}..{t.max_period * 1e3:.2f} ms, RMS jitter {t.jitter_rms * 1e3:.3f} ms, "
                f"gaps {t.gaps} (reported)",
                f"heartbeat: {self.heartbeats} messages, largest gap {self.heartbeat_max_gap * 1e3:.1f} ms "
                f"(<= {self.max_heartbeat_gap * 1e3:.0f} ms): " + ("ok" if self.heartbeat_ok else "FAIL"),
            ]
        lines.append(f"disables: {self.disables}; malformed joint messages: {self.rejected}")
        if self.measured is not None:
            role = "judged" if self.commanded is None else "positions judged, derivatives marked, not deciding"
            lines += [
                f"measured stream ({role}; positions averaged over {MEASURED_WINDOW * 1e3:.0f} ms, limits "
                f"+{MEASURED_TOLERANCE:.0%}, jerk reported):",
                self.measured.table(),
            ]
        lines.append("run: " + ("PASS" if self.passed else "FAIL"))
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        t = self.command_timing
        return {
            "passed": self.passed,
            "commanded": None if self.commanded is None else self.commanded.to_dict(),
            "command_timing": None
            if t is None
            else {
                "expected_period": t.expected_period,
                "min_period": t.min_period,
                "max_period": t.max_period,
                "jitter_rms": t.jitter_rms,
                "gaps": t.gaps,
            },
            "measured": None if self.measured is None else self.measured.to_dict(),
            "heartbeats": self.heartbeats,
            "heartbeat_max_gap": self.heartbeat_max_gap,
            "disables": self.disables,
            "rejected": self.rejected,
        }


def _nominal(samples: JointStateSamples) -> JointStateSamples:
    t = np.arange(len(samples.times)) / samples.rate
    return JointStateSamples(t, samples.positions, samples.velocities, samples.rate, None, samples.joint_names)


def _moving_average(q: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average over ``window`` samples per column (the ends averaged over what exists)."""
    if window <= 1 or len(q) < window:
        return q
    kernel = np.ones(window) / window
    half = window // 2
    padded = np.vstack([np.repeat(q[:1], half, axis=0), q, np.repeat(q[-1:], window - 1 - half, axis=0)])
    return np.column_stack([np.convolve(padded[:, i], kernel, mode="valid") for i in range(q.shape[1])])


def check_run(
    run: RecordedRun,
    limits: JointLimits,
    thresholds: Thresholds | None = None,
    *,
    max_heartbeat_gap: float = MAX_HEARTBEAT_GAP,
    name: str = "run",
) -> RunReport:
    """Check the recorded streams of ``run`` against ``limits`` (matched by joint name).

    A bag without commands (a robot's own recording of ``joint_states``) is judged on its measured stream alone.
    """
    report = timing = None
    if run.commanded:
        commanded = run.stream("commanded")
        lim = limits.subset(commanded.joint_names or ())
        report = check(_nominal(commanded), lim, thresholds=thresholds, name=f"{name} joint_cmd")
        timing = stream_timing(commanded.times, commanded.rate, thresholds)
    elif not run.measured:
        from taplan.errors import InvalidInputError

        raise InvalidInputError("bag", name, "a bag with /api/*_arm/joint_cmd or /*_arm/joint_states")
    measured_report = None
    if run.measured:
        measured = _nominal(run.stream("measured"))
        window = max(1, round(MEASURED_WINDOW * measured.rate))
        smoothed = _moving_average(measured.positions, window)
        judged = Thresholds(
            velocity_tolerance=MEASURED_TOLERANCE,
            acceleration_tolerance=MEASURED_TOLERANCE,
            check_jerk=False,
            gap_factor=math.inf,
            jitter_tolerance=math.inf,
        )
        measured_lim = limits.subset(measured.joint_names or ())
        samples = JointStateSamples(
            measured.times, smoothed, measured.velocities, measured.rate, None, measured.joint_names
        )
        measured_report = check(samples, measured_lim, thresholds=judged, name=f"{name} joint_states")
    gaps = run.heartbeat_gaps
    return RunReport(
        report,
        timing,
        measured_report,
        int(run.heartbeats.size),
        float(gaps.max()) if gaps.size else math.inf,
        float(max_heartbeat_gap),
        int(run.disables.size),
        run.rejected,
    )
