"""The bundled URDF's collision bodies are the bodies ``models/teleavatar/make_urdf.py`` asks for.

Every capsule the generator writes (as a cylinder + origin rpy) is read back by pinocchio and taplan and compared
with the segment and radius it was built from, in the frame of the link that carries it, left and right.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

MAKE_URDF = Path(__file__).resolve().parents[1] / "models" / "teleavatar" / "make_urdf.py"
POINT_TOL = 1e-6  # [m] the file holds 10 significant digits
RADIUS_TOL = 1e-9  # [m]


def _make_urdf():
    spec = importlib.util.spec_from_file_location("make_urdf", MAKE_URDF)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _asked(make_urdf) -> list[tuple[str, str, np.ndarray, np.ndarray, float]]:
    return [(n, link, np.array(a, float), np.array(b, float), r) for n, link, a, b, r in make_urdf.asked_capsules()]


def test_rpy_round_trip_points_z_along_every_direction(rng):
    make_urdf = _make_urdf()
    axes = [np.eye(3)[i] * s for i in range(3) for s in (1.0, -1.0)]
    near_axes = [np.array([0.010, 0.200, 0.0]), np.array([1e-9, -1.0, 1e-12]), np.array([0.0, 1.0, 1e-9])]
    directions = axes + near_axes + list(rng.normal(size=(200, 3)))
    for d in directions:
        rpy = make_urdf._rpy_z_to(d)
        z = pin.rpy.rpyToMatrix(*rpy)[:, 2]
        np.testing.assert_allclose(z, d / np.linalg.norm(d), atol=1e-12, err_msg=f"direction {d}")


def test_every_generated_capsule_is_the_one_asked_for(teleavatar):
    make_urdf = _make_urdf()
    asked = _asked(make_urdf)
    model = teleavatar.model
    built = {c.name: c for c in teleavatar.capsules}
    links = {link for _, link, *_ in asked}
    assert {f"Link-{s}{k}" for s in "LR" for k in range(1, 8)} | {"base_link"} <= links  # every link, both sides
    for name, link, start, end, radius in asked:
        frame = model.frames[model.getFrameId(link)]
        # asked in the link frame; taplan's capsules are in the frame of the joint that moves the link
        want = (frame.placement.act(start), frame.placement.act(end))
        c = built[name]
        assert c.link == link
        assert c.radius == pytest.approx(radius, abs=RADIUS_TOL)
        apart = min(
            max(np.linalg.norm(c.start - want[0]), np.linalg.norm(c.end - want[1])),
            max(np.linalg.norm(c.start - want[1]), np.linalg.norm(c.end - want[0])),
        )
        assert apart < POINT_TOL, f"{name} on {link}: asked {start} -> {end}, built {c.start} -> {c.end}"
    assert len(teleavatar.capsules) == len(asked)


def test_arm_bodies_contain_wrist_centre_and_tool_point(teleavatar, rng):
    for side in ("left", "right"):
        for _ in range(5):
            q = rng.uniform(teleavatar.planning_limits.lower, teleavatar.planning_limits.upper)
            data = teleavatar.model.createData()
            pin.forwardKinematics(teleavatar.model, data, q)
            hand = [c for c in teleavatar.capsules if c.link.startswith(f"Link-{side[0].upper()}")]
            for frame in (f"{side}_ee", f"{side}_tcp"):
                p = teleavatar.frame_pose(q, frame)[:3, 3]
                inside = []
                for c in hand:
                    a, b = c.world_segment(data)
                    s = np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
                    inside.append(np.linalg.norm(p - (a + s * (b - a))) < c.radius)
                assert any(inside), (side, frame)
