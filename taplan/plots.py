"""Plots of a plan or replay: position, velocity, acceleration and jerk per joint with limit bands.

matplotlib is imported inside the functions with the ``Agg`` backend, so importing taplan never needs a display.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from taplan.limits import JointLimits
from taplan.reference.replay import Replay
from taplan.trajectory import Trajectory

__all__ = ["plot_profiles", "save_profiles"]


def _series(
    subject: Replay | Trajectory, rate: float
) -> tuple[np.ndarray, list[np.ndarray], np.ndarray, tuple[str, ...]]:
    if isinstance(subject, Trajectory):
        t = np.union1d(subject.sample_times(rate), subject.times)
        return (
            t - subject.times[0],
            [subject(t, k) for k in range(4)],
            subject.times - subject.times[0],
            subject.joint_names,
        )
    t = np.concatenate([[0.0], subject.times])
    q = np.vstack([subject.initial_positions, subject.positions])
    v_rep = np.vstack([subject.initial_velocities, subject.velocities])
    keep = np.append(np.diff(t) > 0.25 / subject.rate, True)
    t, q, v_rep = t[keep], q[keep], v_rep[keep]
    h = np.maximum(np.diff(t), 1e-12)[:, None]
    v_fd = np.vstack([np.zeros((1, q.shape[1])), np.diff(q, axis=0) / h])
    v = np.where(np.isfinite(v_rep), v_rep, v_fd)
    a = np.vstack([np.zeros((1, q.shape[1])), np.diff(v, axis=0) / h])
    j = np.vstack([np.zeros((1, q.shape[1])), np.diff(a, axis=0) / h])
    return t, [q, v, a, j], subject.waypoint_times, subject.joint_names


def plot_profiles(
    subject: Replay | Trajectory,
    limits: JointLimits | None = None,
    *,
    joints: Sequence[str] | None = None,
    rate: float = 1000.0,
    samples: bool = True,
    title: str | None = None,
) -> Any:
    """A figure with four rows (q, q̇, q̈, jerk) and one line per joint; dashed limit bands; waypoint markers.

    Args:
        subject: A :class:`Trajectory` (evaluated at ``rate`` [Hz]) or a :class:`Replay` (its updates; its
            ``joint_states`` samples are overlaid as dots when ``samples``).
        limits: Limits to draw (matched by name), or None.
        joints: Names to plot (default all).
        rate: Evaluation rate for a Trajectory [Hz].
        samples: Overlay the replay's ``joint_states`` samples.
        title: Figure title.

    Returns:
        The matplotlib Figure.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    t, series, wp_times, names = _series(subject, rate)
    chosen = list(names) if joints is None else list(joints)
    idx = [names.index(n) for n in chosen]
    lim = None
    if limits is not None:
        lim = limits.subset(chosen)
    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(10, 9))
    labels = ("q [rad]", "q̇ [rad/s]", "q̈ [rad/s²]", "jerk [rad/s³]")
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for row, (ax, data, label) in enumerate(zip(axes, series, labels, strict=True)):
        for c, (name, i) in enumerate(zip(chosen, idx, strict=True)):
            color = colors[c % len(colors)]
            style = "-" if isinstance(subject, Trajectory) or row == 0 else "-"
            ax.plot(t, data[:, i], style, color=color, lw=1.0, label=name if row == 0 else None)
            if lim is not None:
                bounds = (
                    (lim.lower[c], lim.upper[c]),
                    (-lim.velocity[c], lim.velocity[c]),
                    (-lim.acceleration[c], lim.acceleration[c]),
                    (-lim.jerk[c], lim.jerk[c]),
                )[row]
                for b in bounds:
                    ax.axhline(b, color=color, ls="--", lw=0.6, alpha=0.6)
            if isinstance(subject, Replay) and samples and subject.samples is not None and row < 2:
                s = subject.samples
                data_s = s.positions if row == 0 else s.velocities
                ax.plot(s.times, data_s[:, i], "o", color=color, ms=2.5)
        for tw in wp_times:
            ax.axvline(tw, color="0.6", lw=0.4, ls=":")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    if lim is not None:
        # keep the data readable when the limits are far away
        for ax, data in zip(axes[1:], series[1:], strict=True):
            peak = np.nanmax(np.abs(data[:, idx])) if data.size else 1.0
            if np.isfinite(peak) and peak > 0:
                ax.set_ylim(-1.3 * peak, 1.3 * peak)
    axes[-1].set_xlabel("t [s]")
    axes[0].legend(loc="upper right", fontsize=7, ncol=max(1, len(chosen) // 7))
    name = title or (subject.controller if isinstance(subject, Replay) else repr(subject))
    fig.suptitle(name)
    fig.tight_layout()
    return fig


def save_profiles(
    subject: Replay | Trajectory, path: str | Path, limits: JointLimits | None = None, **kwargs: Any
) -> Path:
    """:func:`plot_profiles` saved as a PNG; returns the path."""
    import matplotlib.pyplot as plt

    fig = plot_profiles(subject, limits, **kwargs)
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
