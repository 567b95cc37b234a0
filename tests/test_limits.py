"""JointLimits: the vendor YAML read as it is, intersection with the URDF, scaling, validation."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

import taplan
from taplan.limits import DEFAULT_JERK_PER_ACCELERATION, JointLimits
from taplan.robot import TELEAVATAR_ARM_CONFIG

RIGHT_UPPER = [1.8, 0.0, 2.6, -0.25, 1.8, 1.4, 0.6]
RIGHT_LOWER = [-1.8, -1.9, -1.3, -1.9, -1.8, -1.4, -0.6]
VEL = [15, 15, 20, 20, 44, 33, 33]
ACC = [120, 120, 60, 60, 17, 14, 14]


def test_arm_config_read_as_is():
    limits = JointLimits.from_arm_config(TELEAVATAR_ARM_CONFIG)
    assert limits.names[:7] == tuple(f"l_joint{i}" for i in range(1, 8))
    np.testing.assert_array_equal(limits.upper[7:], RIGHT_UPPER)
    np.testing.assert_array_equal(limits.lower[7:], RIGHT_LOWER)
    np.testing.assert_array_equal(limits.upper[:7], [1.8, 1.9, 1.3, 1.9, 1.8, 1.4, 0.6])
    np.testing.assert_array_equal(limits.lower[:7], -np.array(RIGHT_UPPER))  # the left arm mirrors the right
    np.testing.assert_array_equal(limits.velocity, VEL + VEL)
    np.testing.assert_array_equal(limits.acceleration, ACC + ACC)
    np.testing.assert_array_equal(limits.jerk, DEFAULT_JERK_PER_ACCELERATION * np.array(ACC + ACC))
    assert limits.differences == ()


def test_intersection_with_urdf_reports_differences(teleavatar):
    limits = teleavatar.limits
    assert np.all(limits.lower >= teleavatar.model.lowerPositionLimit)
    assert np.all(limits.upper <= teleavatar.model.upperPositionLimit)
    changed = {(d.joint, d.bound): d for d in limits.differences if d.bound in ("lower", "upper")}
    assert set(changed) == {
        ("l_joint2", "upper"), ("r_joint2", "lower"), ("l_joint4", "upper"), ("r_joint4", "lower"),
        ("l_joint7", "lower"), ("l_joint7", "upper"), ("r_joint7", "lower"), ("r_joint7", "upper"),
    }  # fmt: skip
    assert changed[("l_joint2", "upper")].used == 1.8  # URDF tighter
    assert changed[("r_joint4", "lower")].used == -1.9  # YAML tighter
    assert changed[("r_joint7", "upper")].used == 0.6


def test_scaled_planning_limits(teleavatar):
    planning = teleavatar.planning_limits
    np.testing.assert_allclose(planning.velocity, 0.3 * teleavatar.limits.velocity)
    np.testing.assert_allclose(planning.acceleration, 0.3 * teleavatar.limits.acceleration)
    np.testing.assert_allclose(planning.jerk, 0.3 * teleavatar.limits.jerk)
    np.testing.assert_allclose(planning.lower, teleavatar.limits.lower + 0.02)
    custom = teleavatar.limits.scaled(velocity=1.0, acceleration=0.5, jerk=0.1, position_margin=0.0)
    np.testing.assert_allclose(custom.velocity, teleavatar.limits.velocity)
    with pytest.raises(taplan.InvalidInputError, match="velocity"):
        teleavatar.limits.scaled(velocity=1.5)
    with pytest.raises(taplan.InvalidInputError, match="position_margin"):
        teleavatar.limits.scaled(position_margin=1.0)  # wider than half of the 1.2 rad joint-7 range


def test_limits_are_frozen_and_read_only(teleavatar):
    with pytest.raises(AttributeError):
        teleavatar.limits.velocity = np.ones(14)  # type: ignore[misc]
    with pytest.raises(ValueError):
        teleavatar.limits.velocity[0] = 1.0


def test_subset_replace_indices(teleavatar):
    right = teleavatar.limits.subset([f"r_joint{i}" for i in range(1, 8)])
    np.testing.assert_array_equal(right.upper, RIGHT_UPPER)
    faster = right.replace(velocity=np.full(7, 2.0))
    np.testing.assert_array_equal(faster.velocity, 2.0)
    with pytest.raises(taplan.UnknownNameError):
        right.subset(["l_joint1"])
    with pytest.raises(taplan.InvalidInputError, match="fields"):
        right.replace(speed=np.ones(7))


def _good(**override):
    fields = dict(
        names=("a", "b"), lower=[-1.0, -1.0], upper=[1.0, 1.0], velocity=[1.0, 1.0], acceleration=[2.0, 2.0],
        jerk=[10.0, 10.0],
    )  # fmt: skip
    fields.update(override)
    return fields


@pytest.mark.parametrize(
    "override,match",
    [
        ({"lower": [-1.0, np.nan]}, r"lower\[b\]: expected a finite number"),
        ({"upper": [np.inf, 1.0]}, r"upper\[a\]"),
        ({"lower": [1.0, -1.0]}, r"lower\[a\].*lower < upper"),
        ({"velocity": [1.0, 0.0]}, r"velocity\[b\]: expected a number > 0"),
        ({"acceleration": [-2.0, 2.0]}, r"acceleration\[a\]"),
        ({"jerk": [10.0, -1.0]}, r"jerk\[b\]"),
        ({"velocity": [1.0, 1.0, 1.0]}, r"velocity: expected shape \(2,\)"),
        ({"names": ("a", "a")}, "unique"),
        ({"lower": ["x", 0.0]}, "lower"),
    ],
)
def test_bad_limits_name_field_and_joint(override, match):
    with pytest.raises(taplan.InvalidLimitsError, match=match):
        JointLimits(**_good(**override))


def test_bad_arm_config_files(tmp_path):
    with pytest.raises(taplan.ConfigError, match="cannot read"):
        JointLimits.from_arm_config(tmp_path / "missing.yml")
    config = yaml.safe_load(TELEAVATAR_ARM_CONFIG.read_text())
    del config["arms"]["acc_limit"]
    path = tmp_path / "no_acc.yml"
    path.write_text(yaml.safe_dump(config))
    with pytest.raises(taplan.ConfigError, match="acc_limit"):
        JointLimits.from_arm_config(path)
    config = yaml.safe_load(TELEAVATAR_ARM_CONFIG.read_text())
    config["arms"]["vel_limit"] = [1.0, 2.0]
    path.write_text(yaml.safe_dump(config))
    with pytest.raises(taplan.ConfigError, match="vel_limit must be a list of 7"):
        JointLimits.from_arm_config(path)
    config = yaml.safe_load(TELEAVATAR_ARM_CONFIG.read_text())
    config["arms"]["vel_limit"][2] = -1.0
    path.write_text(yaml.safe_dump(config))
    with pytest.raises(taplan.InvalidLimitsError, match=r"velocity\[l_joint3\]"):
        JointLimits.from_arm_config(path)


def test_robot_rejects_limits_in_another_order(teleavatar):
    reordered = teleavatar.limits.subset(tuple(reversed(teleavatar.joint_names)))
    with pytest.raises(taplan.InvalidInputError, match="limits.names"):
        taplan.Robot(teleavatar.urdf_path, limits=reordered)
