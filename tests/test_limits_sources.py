"""The limits rule: the more restrictive source wins unless explicitly overridden; `taplan info` shows every
disagreement (position, velocity, acceleration, jerk)."""

from __future__ import annotations

import numpy as np

from taplan.cli import main
from taplan.robot import TELEAVATAR_ARM_CONFIG, Robot


def test_urdf_velocity_placeholder_is_an_explicit_recorded_override(teleavatar) -> None:  # noqa: ANN001
    velocity = [d for d in teleavatar.limits.differences if d.bound == "velocity"]
    assert len(velocity) == 14
    assert all(d.model == 5.0 and d.used == d.config and "placeholder" in d.reason for d in velocity)


def test_without_the_override_the_more_restrictive_source_wins() -> None:
    strict = Robot.teleavatar(urdf_velocity=True)
    np.testing.assert_array_equal(strict.limits.velocity, np.full(14, 5.0))  # URDF 5.0 < arm_config 15..44 rad/s
    assert np.all(strict.planning_limits.velocity <= strict.limits.velocity)
    assert all(not d.reason for d in strict.limits.differences)


def test_position_bounds_take_the_tighter_source(teleavatar) -> None:  # noqa: ANN001
    for d in teleavatar.limits.differences:
        if d.bound == "lower":
            assert d.used == max(d.config, d.model)
        elif d.bound == "upper":
            assert d.used == min(d.config, d.model)
    assert TELEAVATAR_ARM_CONFIG.exists()


def test_info_shows_every_quantity(capsys) -> None:  # noqa: ANN001
    assert main(["info"]) == 0
    out = capsys.readouterr().out
    for quantity in ("position: 8 disagreement", "velocity: 14 disagreement", "acceleration:", "jerk:"):
        assert quantity in out
    assert "l_joint5  velocity arm_config +44.000, URDF +5.000 -> +44.000  (overridden)" in out
