"""The viewer in a real browser: headless Chromium (Debian's ``chromium``; ``.ci/run`` installs it) renders the
page served on 127.0.0.1 with WebGL on the CPU; we assert on the screenshots' pixels.

No golden images (Chromium and SwiftShader change with updates): each assertion compares two renders of the same
page that differ in one thing (an object hidden, the time slider moved) and checks *where* the pixels changed
against where the objects project through the viewer's camera. The GUI panel and the software-WebGL notice are
left out of every comparison. One browser and one server for the module.
"""

from __future__ import annotations

import contextlib
import io
import os
import time

import numpy as np
import pinocchio as pin
import pytest

from benchmarks._browser import Browser, find_chromium, project
from taplan import viz
from taplan.scene import Box, Scene
from taplan.trajectory import Trajectory

WIDTH, HEIGHT = 960, 640  # [px]
PANEL_X = 610  # [px] the GUI panel floats right of this
NOTICE = (330, 200)  # [px] the software-WebGL notice's corner (top left)
MARGIN = 12  # [px] projected outlines vs rendered edges (antialiasing, the capsules' tessellation)
CHANGED = 30  # a pixel "changed" when a channel moved by more than this (0..255): not antialiasing noise

if find_chromium() is None:
    message = "chromium is not installed (apt-get install -y --no-install-recommends chromium; .ci/run does)"
    if os.environ.get("CI"):
        pytest.fail(message, pytrace=False)
    pytest.skip(message, allow_module_level=True)


def _motion(robot) -> Trajectory:
    """The right arm swings its hand from beside the body to ahead of it (2 s, quintic)."""
    t = np.linspace(0.0, 2.0, 21)
    s = 0.5 - 0.5 * np.cos(np.pi * t / 2.0)
    q = np.repeat(robot.home[None], len(t), axis=0)
    right = robot.group("right").indices
    q[:, right] += s[:, None] * np.array([-0.9, -0.9, 0.4, -1.2, 0.0, 0.3, 0.0])
    return Trajectory(t, q, joint_names=robot.joint_names).resample(50.0)


def _scene() -> Scene:
    scene = Scene()
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    scene.add("box", Box((0.12, 0.2, 0.16)), ([0.5, 0.1, -0.32], [0, 0, 0, 1]))
    return scene


@pytest.fixture(scope="module")
def browser():
    with Browser(WIDTH, HEIGHT) as b:
        yield b


@pytest.fixture(scope="module")
def viewer(teleavatar, browser):
    with contextlib.redirect_stdout(io.StringIO()):
        v = viz.Viewer(teleavatar, _scene(), viz.motions_of(teleavatar, [_motion(teleavatar)]), port=0)
    v.set_show_closest(False)  # its label and highlight move with time: kept out of the pixel comparisons
    browser.open(f"{v.url}/?fixedDpr=1")
    browser.settled()
    yield v
    with contextlib.redirect_stdout(io.StringIO()):
        v.close()


def _changed(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pixels that changed, outside the GUI panel and the notice."""
    mask = np.abs(a.astype(int) - b.astype(int)).max(axis=2) > CHANGED
    mask[:, PANEL_X:] = False
    mask[: NOTICE[1], : NOTICE[0]] = False
    return mask


def _inside(mask: np.ndarray, pixels: np.ndarray, margin: float = MARGIN) -> float:
    """Fraction of the changed pixels inside the bounding rectangle of ``pixels`` (N, 2) widened by ``margin``."""
    rows, cols = np.nonzero(mask)
    lo, hi = pixels.min(axis=0) - margin, pixels.max(axis=0) + margin
    inside = (cols >= lo[0]) & (cols <= hi[0]) & (rows >= lo[1]) & (rows <= hi[1])
    return float(inside.mean())


def _box_corners(center: np.ndarray, size: tuple[float, float, float]) -> np.ndarray:
    return center + np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * np.asarray(size) / 2


def _body_outline(viewer, q: np.ndarray, names: set[str] | None = None) -> np.ndarray:
    """World points on the silhouettes of the robot's bodies at ``q``: segment ends pushed out by the radius."""
    model, data = viewer.robot.model, viewer.robot.model.createData()
    pin.forwardKinematics(model, data, q)
    points = []
    for body in viewer.world.bodies:
        if names is not None and body.name not in names:
            continue
        M = data.oMi[body.joint]
        for p in (M.act(body.start), M.act(body.end)):
            points += [p + body.radius * d for d in np.vstack([np.eye(3), -np.eye(3)])]
    return np.asarray(points)


def _shot(browser) -> np.ndarray:
    return browser.settled(timeout=60.0)[0]


def _pixels(viewer, points: np.ndarray) -> np.ndarray:
    return project(points, viewer.server.initial_camera, WIDTH, HEIGHT)


def test_obstacle_appears_where_it_projects(viewer, browser) -> None:
    viewer.set_time(0.0)
    shown = _shot(browser)
    viewer.obstacles["box"].visible = False
    try:
        hidden = _shot(browser)
    finally:
        viewer.obstacles["box"].visible = True
    mask = _changed(shown, hidden)
    outline = _pixels(viewer, _box_corners(np.array([0.5, 0.1, -0.32]), (0.12, 0.2, 0.16)))
    area = np.ptp(outline[:, 0]) * np.ptp(outline[:, 1])
    assert mask.sum() > 0.3 * area  # the box covered a good part of its projected rectangle
    assert _inside(mask, outline) > 0.97  # and nothing else changed


def test_robot_appears_where_it_projects(viewer, browser) -> None:
    viewer.set_time(0.0)
    shown = _shot(browser)
    root = viewer.nodes()["/robots/plan"]
    root.visible = False
    try:
        hidden = _shot(browser)
    finally:
        root.visible = True
    mask = _changed(shown, hidden)
    q0 = viewer.motions[0].joints(0.0)[0]
    outline = _pixels(viewer, _body_outline(viewer, q0))
    assert _inside(mask, outline) > 0.97
    head = _pixels(viewer, _body_outline(viewer, q0, {"head"})).mean(axis=0).astype(int)
    assert mask[head[1] - 3 : head[1] + 4, head[0] - 3 : head[0] + 4].all()  # the head's centre is the robot's


def test_moving_the_slider_changes_the_picture_where_the_arm_moves(viewer, browser) -> None:
    viewer.set_time(0.0)
    before = _shot(browser)
    # a person's input: focus the time slider's thumb and press End (the slider's maximum)
    assert browser.evaluate("(() => { const s = document.querySelector('[role=slider]'); s.focus(); "
                            "return document.activeElement === s; })()")  # fmt: skip
    browser.key("End", "End", 35)
    deadline = time.monotonic() + 10.0
    while viewer.time < viewer.end - 1e-9 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert viewer.time == pytest.approx(viewer.end)  # the browser's slider drove the server
    after = _shot(browser)
    mask = _changed(before, after)
    motion = viewer.motions[0]
    arm = {b.name for b in viewer.world.bodies if b.group == "right"}
    moved = np.vstack([_body_outline(viewer, motion.joints(t)[0], arm) for t in (0.0, viewer.end)])
    assert mask.sum() > 500
    assert _inside(mask, _pixels(viewer, moved)) > 0.97  # only where the right arm was or is
    hand_then, hand_now = (
        _pixels(viewer, viewer.robot.frame_pose(motion.joints(t)[0], "right_ee")[:3, 3]).astype(int)[0]
        for t in (0.0, viewer.end)
    )
    for x, y in (hand_then, hand_now):
        if x < PANEL_X:
            assert mask[y - 6 : y + 7, x - 6 : x + 7].any()  # the hand left its old place and reached the new one
    left = _pixels(viewer, _body_outline(viewer, motion.joints(0.0)[0], {b.name for b in viewer.world.bodies
                                                                          if b.group == "left"}))  # fmt: skip
    cx, cy = left.mean(axis=0).astype(int)
    assert not mask[cy - 4 : cy + 5, cx - 4 : cx + 5].any()  # the left arm did not move


def test_the_self_contained_page_opens_from_disk(viewer, browser, tmp_path, teleavatar) -> None:
    with contextlib.redirect_stdout(io.StringIO()):
        path = viz.write_html(tmp_path / "plan.html", _motion(teleavatar), scene=_scene())
    browser.open(path.resolve().as_uri() + "?fixedDpr=1")
    deadline = time.monotonic() + 60.0
    first = browser.screenshot()
    while time.monotonic() < deadline and not _changed(first, browser.screenshot()).any():
        time.sleep(0.25)  # loading, then the recording plays by itself: frames differ
    assert _changed(first, browser.screenshot()).any()
    browser.key(" ", "Space", 32)  # the page's own pause (a person's spacebar)
    image = _shot(browser)
    background = np.median(image[HEIGHT - 40 :, PANEL_X - 100 : PANEL_X], axis=(0, 1))
    q0 = viewer.motions[0].joints(0.0)[0]
    head = _pixels(viewer, _body_outline(viewer, q0, {"head"})).mean(axis=0).astype(int)
    patch = image[head[1] - 3 : head[1] + 4, head[0] - 3 : head[0] + 4].reshape(-1, 3).astype(int)
    assert np.abs(patch - background).max(axis=1).min() > CHANGED  # the robot's head is drawn where it projects
    box = _pixels(viewer, np.array([[0.5, 0.1, -0.24]])).astype(int)[0]  # the box's top face
    assert np.abs(image[box[1], box[0]].astype(int) - background).max() > CHANGED
