"""Plots of a plan or replay: position, velocity, acceleration and jerk per joint with limit bands.

matplotlib is imported inside the functions (with the ``Agg`` backend unless pyplot is already in use, e.g. inline
in a notebook), so importing taplan never needs a display.
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


_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#17becf")  # joint 1..7 of an arm
_QUANTITIES = (("q [rad]", "position"), ("q̇ [rad/s]", "velocity"), ("q̈ [rad/s²]", "acceleration"))
_QUANTITIES += (("jerk [rad/s³]", "jerk"),)
_MAX_KNOT_LINES = 40  # more knots than this are drawn as ticks along the time axis, not lines across the plot


def _joint_style(name: str, index: int) -> tuple[str, str]:
    """(colour, line style): the colour by the joint's number in its arm, solid for the left arm, dashed for the
    right (``l_``/``r_`` prefix; otherwise the first seven joints solid)."""
    digits = "".join(ch for ch in name.rsplit("_", 1)[-1] if ch.isdigit())
    number = int(digits) - 1 if digits else index % 7
    right = name.startswith("r_") if name[:2] in ("l_", "r_") else index >= 7
    return _COLOURS[number % len(_COLOURS)], "--" if right else "-"


def _short(name: str) -> str:
    return name.replace("_joint", "")  # l_joint5 -> l5


def _limit_lines(ax: Any, row: int, lim: JointLimits, chosen: Sequence[str], data: np.ndarray) -> None:
    """One dotted line per distinct limit value on this panel, labelled at its right end with the joints it
    bounds (``±15 l1 l2 r1 r2``), so that a panel of 14 joints shows each limit once. Derivative panels span the
    data and at least the tightest limit; limits farther out are listed in the panel's corner instead of squashing
    the curves."""
    import matplotlib.transforms as mtransforms

    groups: dict[float, list[str]] = {}
    for c, name in enumerate(chosen):
        if row == 0:
            bounds = [float(lim.lower[c]), float(lim.upper[c])]
        else:
            bound = float((lim.velocity, lim.acceleration, lim.jerk)[row - 1][c])
            bounds = [bound]
        for value in bounds:
            groups.setdefault(round(value, 9), []).append(_short(name))
    finite = data[np.isfinite(data)]
    peak = float(np.max(np.abs(finite))) if finite.size else 0.0
    if row == 0:
        low, high = min(groups), max(groups)
        low, high = min(low, float(finite.min(initial=low))), max(high, float(finite.max(initial=high)))
        pad = 0.05 * (high - low or 1.0)
        low, high = low - pad, high + pad
        shown = sorted(groups)
    else:
        high = max(1.25 * peak, 1.1 * min(groups))
        low = -high
        shown = sorted(v for v in groups if v <= high)
        off = [v for v in sorted(groups) if v > high]
        if off:
            note = "off scale: " + ", ".join(f"±{v:g} {' '.join(groups[v])}" for v in off)
            ax.text(0.005, 0.97, note, transform=ax.transAxes, fontsize=6, va="top", color="0.3")
    ax.set_ylim(low, high)
    blend = mtransforms.blended_transform_factory(ax.transAxes, ax.transData)
    gap = min(0.07, 0.95 / max(len(shown), 1)) * (high - low)  # labels at least this far apart, pushed upward
    signs = (1.0,) if row == 0 else (1.0, -1.0)
    for sign in signs:
        last = -np.inf
        values = shown if sign > 0 else shown
        for value in values:
            y = sign * value
            ax.axhline(y, color="0.25", ls=":", lw=0.9, zorder=1)
            if sign < 0:
                continue  # one label per limit: at its positive line
            label_y = max(y, last + gap)
            last = label_y
            names = groups[value]
            who = " ".join(names) if len(names) <= 6 else " ".join(names[:5]) + f" +{len(names) - 5}"
            text = f"{value:g} {who}" if row == 0 else f"±{value:g} {who}"
            ax.text(1.005, label_y, text, transform=blend, fontsize=6, va="center", ha="left", color="0.25")


def plot_profiles(
    subject: Replay | Trajectory,
    limits: JointLimits | None = None,
    *,
    joints: Sequence[str] | None = None,
    rate: float = 1000.0,
    samples: bool = True,
    title: str | None = None,
) -> Any:
    """A figure with four rows (q, q̇, q̈, jerk), one line per joint, labelled limit lines and knot ticks.

    Joints are told apart by colour (their number in the arm, 7 colours) and line style (left arm solid, right arm
    dashed). Each distinct limit value is one dotted line labelled with the joints it bounds; every panel's range
    includes its limits. Knots (waypoints, polynomial breaks, reached points) are light ticks along the time axis
    (light lines across the panel when there are few).

    Args:
        subject: A :class:`Trajectory` (evaluated at ``rate`` [Hz]) or a :class:`Replay` (its updates; its
            ``joint_states`` samples are overlaid as dots when ``samples``).
        limits: Limits to draw (matched by name), or None.
        joints: Names to plot (default all).
        rate: Evaluation rate for a Trajectory [Hz].
        samples: Overlay the replay's ``joint_states`` samples.
        title: Figure title, e.g. ``"reach through jtc"`` (default: "trajectory" or the replay's controller).

    Returns:
        The matplotlib Figure.
    """
    import sys

    import matplotlib

    if "matplotlib.pyplot" not in sys.modules:  # a script saving PNGs: no window; a notebook keeps its backend
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.transforms as mtransforms

    t, series, wp_times, names = _series(subject, rate)
    chosen = list(names) if joints is None else list(joints)
    idx = [names.index(n) for n in chosen]
    lim = None if limits is None else limits.subset(chosen)
    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(11, 9.5))
    for row, (ax, data) in enumerate(zip(axes, series, strict=True)):
        for c, (name, i) in enumerate(zip(chosen, idx, strict=True)):
            colour, style = _joint_style(name, c)
            ax.plot(t, data[:, i], style, color=colour, lw=1.1, label=name if row == 0 else None)
            if isinstance(subject, Replay) and samples and subject.samples is not None and row < 2:
                s = subject.samples
                data_s = s.positions if row == 0 else s.velocities
                ax.plot(s.times, data_s[:, i], "o", color=colour, ms=2.0, alpha=0.7)
        if lim is not None:
            _limit_lines(ax, row, lim, chosen, data[:, idx])
        blend = mtransforms.blended_transform_factory(ax.transData, ax.transAxes)
        if 0 < len(wp_times) <= _MAX_KNOT_LINES:
            for tw in wp_times:
                ax.axvline(tw, color="0.75", lw=0.5, zorder=0)
        elif len(wp_times):
            ax.plot(wp_times, np.zeros(len(wp_times)), "|", color="0.55", ms=5, alpha=0.6, transform=blend)
        ax.set_ylabel(_QUANTITIES[row][0])
        ax.grid(alpha=0.25)
    axes[-1].set_xlabel("t [s]")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="center right", fontsize=7, ncol=2 if len(chosen) > 7 else 1, frameon=False)
    kind = "trajectory" if isinstance(subject, Trajectory) else subject.controller
    fig.suptitle(title or kind)
    fig.tight_layout(rect=(0.0, 0.0, 0.80 if len(chosen) > 7 else 0.86, 1.0))
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
