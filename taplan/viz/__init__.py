"""See the plan: a 3D view in the browser of the robot, the scene and the motion (on viser).

``taplan.viz.show(plan, scene)`` serves a :class:`Viewer` on 127.0.0.1 and returns it (inside Jupyter it also
shows it in the notebook): the robot's collision bodies, the scene's obstacles (and perceived occupancy), the hand
frames and their swept paths, the closest pair with its clearance in mm, the joints' velocities and accelerations
against the limits, and a time slider with play/pause/speed. ``taplan view`` does the same from files, bags and
live joint states; :func:`write_html` writes a page that opens without a server.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from taplan.viz.motion import Motion, joint_index
from taplan.viz.viewer import DEFAULT_PORT, Viewer, check_port, motions_of

__all__ = ["Viewer", "Motion", "show", "write_html", "joint_index", "motions_of", "check_port", "DEFAULT_PORT"]


def _default_robot(robot: Any) -> Any:
    from taplan.robot import Robot

    return robot if robot is not None else Robot.teleavatar()


def show(
    *plans: Any,
    scene: Any = None,
    robot: Any = None,
    host: str = "127.0.0.1",
    port: int = 0,
    play: bool = False,
    height: int = 500,
) -> Viewer:
    """Serve a viewer of ``plans`` (MotionPlan, Trajectory or Motion) in ``scene`` and return it.

    ``show(plan, scene)`` also accepts the scene as the last positional argument. Inside Jupyter the viewer is
    displayed in the notebook (an iframe of the server's page); elsewhere open ``viewer.url``. Stop it with
    ``viewer.close()``.

    Args:
        plans: What to replay, on one clock.
        scene: A :class:`~taplan.scene.Scene` (or None).
        robot: The robot (default the bundled TeleAvatar).
        host, port: Where to serve (port 0: any free port).
        play: Start playing at once.
        height: Height of the notebook view [px].
    """
    from taplan.scene import Scene

    if plans and isinstance(plans[-1], Scene) and scene is None:
        plans, scene = plans[:-1], plans[-1]
    robot = _default_robot(robot)
    viewer = Viewer(robot, scene, motions_of(robot, plans), host=host, port=port)
    if play:
        viewer.play()
    _display_in_notebook(viewer, height)
    return viewer


def _display_in_notebook(viewer: Viewer, height: int) -> None:
    try:
        from IPython import get_ipython
        from IPython.display import IFrame, display
    except ImportError:
        print(f"taplan.viz: open {viewer.url}", flush=True)
        return
    if get_ipython() is None:
        print(f"taplan.viz: open {viewer.url}", flush=True)
        return
    display(IFrame(viewer.url, width="100%", height=height))


def write_html(
    path: str | Path,
    *plans: Any,
    scene: Any = None,
    robot: Any = None,
    rate: float = 20.0,
) -> Path:
    """Write a self-contained HTML page of ``plans`` in ``scene`` that opens from disk without a server.

    It holds viser's web client and a recording of the motion at ``rate`` [Hz]: the page's timeline plays,
    pauses and scrubs it. Parent folders are created.
    """
    robot = _default_robot(robot)
    path = Path(path)
    with Viewer(robot, scene, motions_of(robot, plans), port=0) as viewer:
        page = viewer.html(rate)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(page, encoding="utf-8")
    return path
