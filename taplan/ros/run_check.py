"""Check a recorded run (a rosbag2 file) with taplan's report: commands, their timing, heartbeats, measurements.

* **Commands** (``/api/{side}_arm/joint_cmd``, both arms): :func:`taplan.check.check` on the sequence the robot
  received, on the nominal grid of the stream's rate (the robot's inner loop takes them in order, not at their
  log times): position, velocity, acceleration and jerk limits, velocity steps, smoothness.
* **Command timing**: the log times' periods against the nominal rate (RMS jitter, gaps, repeats), reported.
* **Heartbeat**: the largest interval between ``/api/fsm/enable`` messages with data > 0; above
  ``max_heartbeat_gap`` (100 ms) the run fails. Disables are counted.
* **Measured** (``/{side}_arm/joint_states``): positions against the limits (velocities of a measured stream are
  reported, not judged).
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


@dataclass(frozen=True)
class RunReport:
    """The checks of one recorded run."""

    commanded: Report
    command_timing: TimingCheck
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
    def passed(self) -> bool:
        measured_ok = self.measured is None or all(j.position_violation <= 1e-9 for j in self.measured.joints)
        return self.commanded.passed and self.heartbeat_ok and measured_ok

    def table(self) -> str:
        t = self.command_timing
        lines = [
            "commanded stream (nominal grid):",
            self.commanded.table(),
            f"command timing: {t.periods} periods, expected {t.expected_period * 1e3:.2f} ms, "
            f"{t.min_period * 1e3:.2f}..{t.max_period * 1e3:.2f} ms, RMS jitter {t.jitter_rms * 1e3:.3f} ms, "
            f"gaps {t.gaps} (reported)",
            f"heartbeat: {self.heartbeats} messages, largest gap {self.heartbeat_max_gap * 1e3:.1f} ms "
            f"(<= {self.max_heartbeat_gap * 1e3:.0f} ms): " + ("ok" if self.heartbeat_ok else "FAIL"),
            f"disables: {self.disables}; malformed joint messages: {self.rejected}",
        ]
        if self.measured is not None:
            lines += ["measured stream (positions judged, derivatives reported):", self.measured.table()]
        lines.append("run: " + ("PASS" if self.passed else "FAIL"))
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        t = self.command_timing
        return {
            "passed": self.passed,
            "commanded": self.commanded.to_dict(),
            "command_timing": {
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


def check_run(
    run: RecordedRun,
    limits: JointLimits,
    thresholds: Thresholds | None = None,
    *,
    max_heartbeat_gap: float = MAX_HEARTBEAT_GAP,
    name: str = "run",
) -> RunReport:
    """Check the recorded streams of ``run`` against ``limits`` (matched by joint name)."""
    commanded = run.stream("commanded")
    lim = limits.subset(commanded.joint_names or ())
    report = check(_nominal(commanded), lim, thresholds=thresholds, name=f"{name} joint_cmd")
    timing = stream_timing(commanded.times, commanded.rate, thresholds)
    measured_report = None
    if run.measured:
        measured = run.stream("measured")
        lenient = Thresholds(
            velocity_tolerance=math.inf,
            acceleration_tolerance=math.inf,
            jerk_tolerance=math.inf,
            check_jerk=False,
            velocity_step=math.inf,
            gap_factor=math.inf,
            jitter_tolerance=math.inf,
        )
        measured_lim = limits.subset(measured.joint_names or ())
        measured_report = check(_nominal(measured), measured_lim, thresholds=lenient, name=f"{name} joint_states")
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
