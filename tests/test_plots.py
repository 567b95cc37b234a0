"""Profile plots a person can read: titled, 14 joints told apart, labelled limits on every panel, light knots."""

from __future__ import annotations

import numpy as np
import pytest

from taplan.plots import plot_profiles
from taplan.reference import JointTrajectoryController
from taplan.timing import jerk_limited

matplotlib = pytest.importorskip("matplotlib")


@pytest.fixture(scope="module")
def plan(teleavatar):  # noqa: ANN001, ANN201
    q0 = teleavatar.home
    wp = np.array([q0, q0 + 0.2, q0 + np.r_[[0.3, 0.1, -0.2, 0.2, 0.0, 0.1, 0.0] * 2]])
    return jerk_limited(wp, teleavatar.planning_limits).trajectory


def test_fourteen_joints_are_told_apart_and_the_title_is_given(plan, teleavatar) -> None:  # noqa: ANN001
    fig = plot_profiles(plan, teleavatar.limits, title="reach: the plan")
    try:
        assert fig._suptitle.get_text() == "reach: the plan"
        lines = {line.get_label(): line for line in fig.axes[0].get_lines() if line.get_label() in plan.joint_names}
        assert len(lines) == 14
        styles = {(matplotlib.colors.to_hex(line.get_color()), line.get_linestyle()) for line in lines.values()}
        assert len(styles) == 14  # no two joints look alike
        assert {lines[f"l_joint{k}"].get_linestyle() for k in range(1, 8)} == {"-"}
        assert {lines[f"r_joint{k}"].get_linestyle() for k in range(1, 8)} == {"--"}
        for k in range(1, 8):  # the same joint of both arms shares a colour
            assert lines[f"l_joint{k}"].get_color() == lines[f"r_joint{k}"].get_color()
    finally:
        matplotlib.pyplot.close(fig)


def test_every_panel_has_labelled_limit_lines(plan, teleavatar) -> None:  # noqa: ANN001
    fig = plot_profiles(plan, teleavatar.limits, title="x")
    try:
        lim = teleavatar.limits
        for row, ax in enumerate(fig.axes[:4]):
            texts = [t.get_text() for t in ax.texts]
            assert texts, row
            low, high = ax.get_ylim()
            if row == 0:
                assert any(t.startswith("1.8 ") and "l1" in t for t in texts)  # l_joint1 upper [rad]
                assert low <= lim.lower.min() and high >= lim.upper.max()
            else:
                bound = (lim.velocity, lim.acceleration, lim.jerk)[row - 1]
                assert any(t.startswith(f"±{bound.min():g} ") for t in texts)  # the tightest limit, on the panel
                assert high >= bound.min()
    finally:
        matplotlib.pyplot.close(fig)


def test_many_knots_are_ticks_not_lines_across_the_plot(plan, teleavatar) -> None:  # noqa: ANN001
    assert len(plan.times) > 40
    fig = plot_profiles(plan, teleavatar.limits)
    try:
        ax = fig.axes[0]
        vertical = [line for line in ax.get_lines() if len(set(line.get_xdata())) == 1 and len(line.get_xdata()) == 2]
        assert not vertical  # no axvline per knot
        ticks = [line for line in ax.get_lines() if line.get_marker() == "|"]
        assert len(ticks) == 1 and len(ticks[0].get_xdata()) == len(plan.times)
        assert fig._suptitle.get_text() == "trajectory"  # not a Python repr
    finally:
        matplotlib.pyplot.close(fig)


def test_a_replay_is_titled_by_its_controller(plan, teleavatar) -> None:  # noqa: ANN001
    replay = JointTrajectoryController().replay(plan.resample(100.0).waypoints(), joint_names=plan.joint_names)
    fig = plot_profiles(replay, teleavatar.limits)
    try:
        assert fig._suptitle.get_text() == replay.controller
    finally:
        matplotlib.pyplot.close(fig)
