"""The browser viewer: a viser server showing robots, the scene, hand frames, swept paths and the closest pair.

Scene graph (names are part of the API; tests and users find nodes by them):

* ``/robots/<motion>/<joint>``: one frame per model joint (``universe`` for the root), posed in the world by
  forward kinematics; the robot's collision bodies (``.../<joint>/<body>``), its hand frames
  (``.../<joint>/hand_<frame>``) and attached objects hang under the joint that carries them;
* ``/scene/<obstacle>``: the obstacles, perceived occupancy (an ``Occupancy`` obstacle) as one box per voxel,
  drawn again whenever the scene changes;
* ``/paths/<motion>/<frame>``: the swept path of each hand frame over the motion;
* ``/closest/<motion>``: a segment between the closest pair's witness points, with its clearance [mm] as a label.

Playback runs on a server thread at ``rate`` [Hz]; the GUI has the time slider, play/pause, speed and, per robot,
the closest pair and the joints' velocities and accelerations against the robot's limits.
"""

from __future__ import annotations

import contextlib
import io
import logging
import math
import socket
import threading
import time
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from taplan.errors import ConfigError, InvalidInputError
from taplan.robot import Robot
from taplan.scene import CollisionWorld, Scene
from taplan.scene.shapes import Box, Capsule, Cylinder, HalfSpace, Mesh, Shape, Sphere
from taplan.viz.geometry import box_mesh, capsule_mesh, cylinder_mesh, half_space_slab, segment_pose, wxyz
from taplan.viz.motion import Motion
from taplan.viz.visuals import VisualMesh, visual_meshes

__all__ = ["Viewer", "DEFAULT_PORT", "check_port"]

logger = logging.getLogger(__name__)

DEFAULT_PORT = 8080
_OBSTACLE_COLOR = (200, 170, 120)
_VISUAL_COLOR = (190, 190, 195)
_OCCUPANCY_COLOR = (140, 140, 150)
_HIGHLIGHT = (230, 40, 40)
_PATH_COLORS = ((30, 160, 90), (150, 60, 200))
_PATH_SAMPLES = 200  # points per swept path: 5 cm apart at most for a 10 m/s... far more than a hand moves
_CLEARANCE_CUTOFF = 0.5  # [m] beyond this the closest pair is not drawn (nothing near)


def check_port(host: str, port: Any) -> int:
    """``port`` as an int if ``host:port`` can be bound now (0: any free port); InvalidInputError otherwise."""
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise InvalidInputError("port", port, "a TCP port 0..65535 (0: any free port)")
    if port == 0:
        return 0
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM) as probe:
        # like viser's server: a port left in TIME_WAIT by a viewer just stopped is free; a listening one is not
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError as exc:
            reason = "in use" if exc.errno == 98 else exc.strerror
            raise InvalidInputError("port", port, f"a free port on {host} ({port} is {reason}; try --port 0)") from None
    return port


def _pose_parts(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return wxyz(T[:3, :3]), np.asarray(T[:3, 3], dtype=float)


def _add_shape(server: Any, name: str, shape: Shape, T: np.ndarray, color: tuple[int, int, int], opacity=None) -> Any:
    """Draw a taplan shape at pose ``T`` (relative to the node's parent)."""
    q, p = _pose_parts(T)
    scene = server.scene
    if isinstance(shape, Box):
        return scene.add_box(name, color=color, dimensions=shape.size, wxyz=q, position=p, opacity=opacity)
    if isinstance(shape, Sphere):
        return scene.add_icosphere(name, radius=shape.radius, color=color, wxyz=q, position=p, opacity=opacity)
    if shape.kind == "occupancy":  # perceived voxels: one box instance per occupied voxel
        centers = np.asarray(shape.centers(), dtype=np.float32).reshape(-1, 3)  # type: ignore[attr-defined]
        if not len(centers):
            return scene.add_frame(name, show_axes=False, wxyz=q, position=p)
        vertices, faces = box_mesh(np.full(3, shape.resolution))  # type: ignore[attr-defined]
        rotations = np.tile(np.array([1.0, 0.0, 0.0, 0.0], dtype=np.float32), (len(centers), 1))
        return scene.add_batched_meshes_simple(
            name, vertices, faces, rotations, centers, batched_colors=color, wxyz=q, position=p, lod="off"
        )
    if isinstance(shape, Capsule):
        vertices, faces = capsule_mesh(shape.radius, shape.length)
    elif isinstance(shape, Cylinder):
        vertices, faces = cylinder_mesh(shape.radius, shape.length)
    elif isinstance(shape, HalfSpace):
        vertices, faces = half_space_slab()
        opacity = 0.5 if opacity is None else opacity
    elif isinstance(shape, Mesh):
        vertices, faces = shape.vertices.astype(np.float32), shape.faces.astype(np.uint32)
    else:
        raise InvalidInputError(
            name, type(shape).__name__, "a Box, Sphere, Capsule, Cylinder, HalfSpace, Mesh, Occupancy"
        )
    return scene.add_mesh_simple(
        name, vertices, faces, color=color, wxyz=q, position=p, opacity=opacity, flat_shading=False, side="double"
    )


def _body_shape(body: Any) -> tuple[Shape, np.ndarray]:
    """A robot body as a shape and its pose in the joint frame: capsules (spheres when start == end) from the
    segment model; bodies that carry their own ``shape`` and ``pose`` (boxes, meshes) as they are."""
    shape = getattr(body, "shape", None)
    if isinstance(shape, Shape):
        return shape, np.asarray(getattr(body, "pose", np.eye(4)), dtype=float)
    start, end = np.asarray(body.start, dtype=float), np.asarray(body.end, dtype=float)
    length = float(np.linalg.norm(end - start))
    pose = segment_pose(start, end)
    if length < 1e-9:
        return Sphere(float(body.radius)), pose
    return Capsule(float(body.radius), length), pose


class _RobotDrawing:
    """One robot in the scene graph: joint frames posed by FK, bodies, hand frames and attached objects."""

    def __init__(
        self,
        server: Any,
        world: CollisionWorld,
        prefix: str,
        color: tuple[int, int, int],
        hands: bool,
        visuals: Sequence[VisualMesh] = (),
    ):
        robot = world.robot
        self.model = robot.model
        self.data = robot.model.createData()
        self.prefix = prefix
        self.color = color
        self.joints = []
        for j in range(self.model.njoints):
            self.joints.append(server.scene.add_frame(f"{prefix}/{self.model.names[j]}", show_axes=False))
        self.bodies: dict[str, Any] = {}
        for body in world.bodies:
            shape, pose = _body_shape(body)
            node = f"{prefix}/{self.model.names[body.joint]}/{body.name}"
            self.bodies[body.name] = _add_shape(server, node, shape, pose, color)
        self.visuals: list[Any] = []
        for k, mesh in enumerate(visuals):
            if not self.model.existFrame(mesh.link):
                continue
            f = self.model.frames[self.model.getFrameId(mesh.link)]
            q, p = _pose_parts(f.placement.homogeneous @ mesh.pose)
            self.visuals.append(
                server.scene.add_mesh_simple(
                    f"{prefix}/{self.model.names[f.parentJoint]}/visual_{mesh.link}_{k}",
                    mesh.vertices.astype(np.float32),
                    mesh.faces.astype(np.uint32),
                    color=_VISUAL_COLOR,
                    wxyz=q,
                    position=p,
                )
            )
        self.hands: dict[str, Any] = {}
        frames = [g.ee_frame for g in robot.groups.values()] if hands else []
        for frame in frames:
            f = self.model.frames[robot.frame_id(frame)]
            node = f"{prefix}/{self.model.names[f.parentJoint]}/hand_{frame}"
            q, p = _pose_parts(f.placement.homogeneous)
            self.hands[frame] = server.scene.add_frame(node, axes_length=0.08, axes_radius=0.004, wxyz=q, position=p)
        for item in world.scene.attached.values():
            f = self.model.frames[robot.frame_id(item.frame)]
            node = f"{prefix}/{self.model.names[f.parentJoint]}/{item.name}"
            self.bodies[item.name] = _add_shape(server, node, item.shape, f.placement.homogeneous @ item.pose, color)

    def update(self, q: np.ndarray) -> None:
        pin.forwardKinematics(self.model, self.data, q)
        for j in range(1, self.model.njoints):
            M = self.data.oMi[j]
            handle = self.joints[j]
            handle.wxyz = wxyz(M.rotation)
            handle.position = M.translation


class Viewer:
    """A viser server showing ``robot`` following ``motions`` (replayed on a time slider) in ``scene``.

    Args:
        robot: The robot (its collision bodies as :class:`~taplan.scene.CollisionWorld` reports them).
        scene: Obstacles and attached objects (None: none).
        motions: Motions replayed together on one clock (a plan; a bag's commanded and measured streams).
        host: Interface to serve on (default 127.0.0.1: this machine only).
        port: TCP port (0: any free port). A port in use raises :class:`~taplan.errors.InvalidInputError`.
        rate: Playback update rate [Hz] (60: a browser's frame rate; at least 30 under load).
        live: Names of robots posed from outside (:meth:`set_configuration`), e.g. ``("live",)``.
        hands: Draw the groups' end-effector frames.

    Raises:
        InvalidInputError: a bad argument or a port in use. ConfigError: viser is not installed.
    """

    def __init__(
        self,
        robot: Robot,
        scene: Scene | None = None,
        motions: Sequence[Motion] = (),
        *,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        rate: float = 60.0,
        live: Sequence[str] = (),
        hands: bool = True,
    ) -> None:
        try:
            import viser
        except ImportError as exc:  # pragma: no cover - viser is a dependency
            raise ConfigError("taplan.viz needs viser: pip install viser") from exc
        if not isinstance(robot, Robot):
            raise InvalidInputError("robot", type(robot).__name__, "a taplan Robot")
        if scene is not None and not isinstance(scene, Scene):
            raise InvalidInputError("scene", type(scene).__name__, "a taplan.scene.Scene or None")
        if not (isinstance(rate, (int, float)) and math.isfinite(rate) and 1.0 <= rate <= 240.0):
            raise InvalidInputError("rate", rate, "a playback rate in [1, 240] Hz")
        self.motions = list(motions)
        names = [m.name for m in self.motions] + list(live)
        if len(set(names)) != len(names) or not names:
            raise InvalidInputError("motions", names, "at least one motion or live robot, with distinct names")
        port = check_port(host, port)
        self.robot = robot
        self.world = CollisionWorld(robot, scene)
        self.rate = float(rate)
        with contextlib.redirect_stdout(io.StringIO()):  # viser's banner: we print our own URL
            self.server = viser.ViserServer(host=host, port=port, verbose=False)
        if port and self.server.get_port() != port:  # taken between our check and viser's bind
            self.server.stop()
            raise InvalidInputError("port", port, f"a free port on {host} (it is in use)")
        self.host = host
        self.port = int(self.server.get_port())
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self.playing = False
        self.show_closest = True
        self.speed = 1.0
        self.loop = True
        self.start = min((m.start for m in self.motions), default=0.0)
        self.end = max((m.end for m in self.motions), default=0.0)
        self.time = self.start
        self._limits = robot.limits
        try:
            self._build(live, hands)
        except Exception:
            self.server.stop()
            raise
        self.set_time(self.start)
        self._thread = threading.Thread(target=self._playback, name="taplan-viz-playback", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------------------------------------ building
    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}"

    def _build(self, live: Sequence[str], hands: bool) -> None:
        server = self.server
        scene = server.scene
        scene.set_up_direction("+z")
        scene.configure_environment_map(hdri=None)  # the HDRI's preprocessing costs 10+ s on a CPU renderer
        scene.configure_default_lights(enabled=True, cast_shadow=False)
        self._camera_defaults()
        self.obstacles: dict[str, Any] = {}
        self._scene_version = -1
        self._sync_scene()
        meshes, self.skipped_visuals = visual_meshes(self.robot.urdf_path)
        palette = [(90, 140, 220), (235, 150, 60), (120, 190, 120)]
        self.robots: dict[str, _RobotDrawing] = {}
        self._live_state: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        for motion in self.motions:
            self.robots[motion.name] = _RobotDrawing(
                server, self.world, f"/robots/{motion.name}", motion.color, hands, meshes
            )
        for k, name in enumerate(live):
            color = palette[(len(self.motions) + k) % len(palette)]
            self.robots[name] = _RobotDrawing(server, self.world, f"/robots/{name}", color, hands, meshes)
            home = self.robot.home.copy()
            self._live_state[name] = (home, np.zeros_like(home), np.zeros_like(home))
        self._closest: dict[str, tuple[Any, Any]] = {}
        for name in self.robots:
            segment = scene.add_line_segments(
                f"/closest/{name}", np.zeros((1, 2, 3)), _HIGHLIGHT, thickness=4.0, thickness_units="screen"
            )
            label = scene.add_label(f"/closest/{name}/clearance", "", font_screen_scale=0.8)
            self._closest[name] = (segment, label)
        self._highlighted: dict[str, list[tuple[Any, tuple[int, int, int]]]] = {name: [] for name in self.robots}
        self._draw_paths()
        self._build_gui()

    def _sync_scene(self) -> None:
        """Draw the scene's obstacles again when it changed (perception replacing its occupancy, moved objects)."""
        scene = self.world.scene
        if scene.version == self._scene_version:
            return
        for handle in self.obstacles.values():
            handle.remove()
        self.obstacles = {}
        for obstacle in scene.obstacles.values():
            color = _OCCUPANCY_COLOR if obstacle.shape.kind == "occupancy" else _OBSTACLE_COLOR
            self.obstacles[obstacle.name] = _add_shape(
                self.server, f"/scene/{obstacle.name}", obstacle.shape, obstacle.pose, color
            )
        self._scene_version = scene.version

    def _camera_defaults(self) -> None:
        camera = self.server.initial_camera
        # the robot's front-right from above, framed left of the GUI panel: the arms' workspace ahead of the chest
        centre = np.array([0.3, -0.25, -0.15])
        camera.look_at = centre
        camera.position = centre + np.array([1.5, -1.5, 0.9])
        camera.up = (0.0, 0.0, 1.0)
        camera.fov = math.radians(50.0)

    def _draw_paths(self) -> None:
        model = self.robot.model
        data = model.createData()
        frames = [g.ee_frame for g in self.robot.groups.values()]
        for motion in self.motions:
            times = np.linspace(motion.start, motion.end, _PATH_SAMPLES)
            points = {frame: [] for frame in frames}
            for q in motion.positions(times):
                pin.framesForwardKinematics(model, data, q)
                for frame in frames:
                    points[frame].append(data.oMf[self.robot.frame_id(frame)].translation.copy())
            for k, frame in enumerate(frames):
                path = np.asarray(points[frame])
                segments = np.stack([path[:-1], path[1:]], axis=1)
                self.server.scene.add_line_segments(
                    f"/paths/{motion.name}/{frame}",
                    segments,
                    _PATH_COLORS[k % len(_PATH_COLORS)],
                    thickness=3.0,
                    thickness_units="screen",
                )

    def _build_gui(self) -> None:
        gui = self.server.gui
        self.gui: dict[str, Any] = {}
        if self.motions:
            span = max(self.end - self.start, 1e-3)
            step = 10 ** math.floor(math.log10(span / 1000)) if span > 1e-3 else 1e-3
            self.gui["time"] = gui.add_slider("time [s]", self.start, self.start + span, step, self.start)
            self.gui["playback"] = gui.add_button_group("playback", ("Play", "Pause"))
            self.gui["speed"] = gui.add_slider("speed", 0.1, 4.0, 0.1, 1.0)
            self.gui["loop"] = gui.add_checkbox("loop", True)

            @self.gui["time"].on_update
            def _(event: Any) -> None:
                if event.client is not None:  # a person moved it (our own assignments come with no client)
                    self.set_time(float(self.gui["time"].value))

            @self.gui["playback"].on_click
            def _(event: Any) -> None:
                self.play() if self.gui["playback"].value == "Play" else self.pause()

            @self.gui["speed"].on_update
            def _(event: Any) -> None:
                self.speed = float(self.gui["speed"].value)

            @self.gui["loop"].on_update
            def _(event: Any) -> None:
                self.loop = bool(self.gui["loop"].value)

        self.gui["closest"] = gui.add_checkbox("closest pair", True)
        self.gui["bodies"] = gui.add_checkbox("collision bodies", True)

        @self.gui["bodies"].on_update
        def _(event: Any) -> None:
            for drawing in self.robots.values():
                for handle in drawing.bodies.values():
                    handle.visible = bool(self.gui["bodies"].value)

        if any(drawing.visuals for drawing in self.robots.values()):
            self.gui["visuals"] = gui.add_checkbox("visual meshes", True)

            @self.gui["visuals"].on_update
            def _(event: Any) -> None:
                for drawing in self.robots.values():
                    for handle in drawing.visuals:
                        handle.visible = bool(self.gui["visuals"].value)

        @self.gui["closest"].on_update
        def _(event: Any) -> None:
            if event.client is not None:
                self.set_show_closest(bool(self.gui["closest"].value))

        for name in self.robots:
            with gui.add_folder(name):
                self.gui[f"{name}/closest"] = gui.add_markdown("")
                self.gui[f"{name}/limits"] = gui.add_markdown("")

    # --------------------------------------------------------------------------------------------- updating
    def set_time(self, t: float) -> None:
        """Pose every replayed robot at time ``t`` [s] (clamped to the motions' span) and update the GUI."""
        if not (isinstance(t, (int, float)) and math.isfinite(t)):
            raise InvalidInputError("t", t, "a finite time [s]")
        with self._lock, self.server.atomic():
            self._sync_scene()
            self.time = min(max(float(t), self.start), self.end)
            for motion in self.motions:
                self._pose(motion.name, *motion.joints(self.time))
            if "time" in self.gui:
                self.gui["time"].value = self.time

    def set_configuration(
        self, name: str, q: np.ndarray, v: np.ndarray | None = None, a: np.ndarray | None = None
    ) -> None:
        """Pose live robot ``name`` at ``q`` [rad] (all model joints), with velocities/accelerations if known."""
        if name not in self._live_state:
            raise InvalidInputError("name", name, f"a live robot of this viewer {list(self._live_state)}")
        q = self.robot.check_configuration(q, "q")
        zero = np.zeros_like(q)
        v = zero if v is None else np.asarray(v, dtype=float)
        a = zero if a is None else np.asarray(a, dtype=float)
        with self._lock, self.server.atomic():
            self._sync_scene()
            self._live_state[name] = (q, v, a)
            self._pose(name, q, v, a)

    def _pose(self, name: str, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> None:
        self.robots[name].update(q)
        self._show_closest(name, q)
        self._show_limits(name, v, a)

    def closest(self, q: np.ndarray) -> tuple[float, tuple[str, str], np.ndarray, np.ndarray] | None:
        """The closest active pair at ``q`` within the cutoff: (clearance [m], names, witness a, witness b)."""
        self._distances = d = self.world.distances(q, cutoff=_CLEARANCE_CUTOFF, jacobian=False)
        if not len(d):
            return None
        k = int(np.argmin(d.distance))
        return float(d.distance[k]), d.pairs[k], d.point_a[k], d.point_b[k]

    def _closest_to_scene(self) -> str:
        """The closest robot-obstacle pair of the last evaluation, as a GUI line ("" when none)."""
        d = self._distances
        scene = [k for k, (_, b) in enumerate(d.pairs) if b in self.obstacles]
        if not scene:
            return ""
        k = min(scene, key=lambda i: d.distance[i])
        return f"\n\nto the scene: {d.pairs[k][0]} / {d.pairs[k][1]}: {d.distance[k] * 1e3:.1f} mm"

    def _node_of(self, name: str, member: str) -> Any:
        return self.robots[name].bodies.get(member, self.obstacles.get(member))

    def set_show_closest(self, show: bool) -> None:
        """Show or hide the closest pair (segment, label, highlight) and redraw."""
        with self._lock:
            self.show_closest = bool(show)
            if "closest" in self.gui:
                self.gui["closest"].value = self.show_closest
            for name in self._live_state:
                self._pose(name, *self._live_state[name])
            self.set_time(self.time)

    def _show_closest(self, name: str, q: np.ndarray) -> None:
        segment, label = self._closest[name]
        for handle, color in self._highlighted[name]:
            handle.color = color
        self._highlighted[name] = []
        box = self.gui.get(f"{name}/closest")
        if not self.show_closest:
            segment.visible = label.visible = False
            if box is not None:
                box.content = "**closest pair**: hidden"
            return
        found = self.closest(q)
        if found is None:
            segment.visible = label.visible = False
            if box is not None:
                box.content = f"**closest pair**: nothing within {_CLEARANCE_CUTOFF * 1e3:.0f} mm"
            return
        clearance, pair, pa, pb = found
        segment.points = np.array([[pa, pb]], dtype=np.float32)
        segment.visible = label.visible = True
        label.position = (pa + pb) / 2
        label.text = f"{clearance * 1e3:.1f} mm"
        for member in pair:
            node = self._node_of(name, member)
            if node is not None and hasattr(node, "color"):
                self._highlighted[name].append((node, tuple(node.color)))
                node.color = _HIGHLIGHT
        if box is not None:
            box.content = f"**closest pair**: {pair[0]} / {pair[1]}: **{clearance * 1e3:.1f} mm**" + (
                self._closest_to_scene()
            )

    def _show_limits(self, name: str, v: np.ndarray, a: np.ndarray) -> None:
        box = self.gui.get(f"{name}/limits")
        if box is None:
            return
        limits = self._limits
        rows = ["| joint | v/v_max | a/a_max |", "|:--|--:|--:|"]
        for i, joint in enumerate(self.robot.joint_names):
            rv = abs(v[i]) / limits.velocity[i]
            ra = abs(a[i]) / limits.acceleration[i]
            mark = " ⚠" if max(rv, ra) > 1.0 + 1e-9 else ""
            rows.append(f"| {joint}{mark} | {100 * rv:.0f} % | {100 * ra:.0f} % |")
        box.content = "\n".join(rows)

    # -------------------------------------------------------------------------------------------- playback
    def play(self) -> None:
        """Start (or resume) playback at ``speed``; from the start when at the end."""
        if self.time >= self.end:
            self.set_time(self.start)
        self.playing = True

    def pause(self) -> None:
        self.playing = False

    def advance(self, dt: float) -> None:
        """Move the clock ``dt`` [s] of wall time at ``speed`` (looping or stopping at the end) and redraw."""
        t = self.time + dt * self.speed
        if t > self.end:
            if self.loop and self.end > self.start:
                t = self.start + (t - self.end) % (self.end - self.start)
            else:
                t = self.end
                self.playing = False
        self.set_time(t)

    def _playback(self) -> None:
        period = 1.0 / self.rate
        last = deadline = time.monotonic()
        while not self._stop.wait(max(0.0, deadline - time.monotonic())):
            now = time.monotonic()
            # a fixed grid of wake-ups: late wake-ups do not lower the rate; after a stall, start a new grid
            deadline = deadline + period if now - deadline < period else now + period
            dt, last = now - last, now
            if self.playing and self.motions:
                try:
                    self.advance(dt)
                except Exception:  # keep the server up: a bad frame is logged, playback stops
                    logger.exception("taplan.viz playback stopped")
                    self.playing = False

    # ---------------------------------------------------------------------------------------------- output
    def html(self, rate: float = 20.0) -> str:
        """A self-contained HTML page (viser's client with this motion recorded at ``rate`` [Hz] inside): opens
        from disk in a browser, no server; its timeline plays the motion."""
        if not (isinstance(rate, (int, float)) and math.isfinite(rate) and 0 < rate <= 120):
            raise InvalidInputError("rate", rate, "a recording rate in (0, 120] Hz")
        with self._lock:
            playing, self.playing = self.playing, False
            self.set_time(self.start)
            self.server._websock_server._record_handles.clear()  # a previous, unfinished recording
            recorder = self.server.get_scene_serializer()
            times = np.arange(self.start, self.end + 0.5 / rate, 1.0 / rate) if self.motions else np.zeros(1)
            for t in times[1:]:
                recorder.insert_sleep(1.0 / rate)
                self.set_time(min(float(t), self.end))
            page = recorder.as_html()
            self.playing = playing
        return page

    def nodes(self) -> dict[str, Any]:
        """Scene-graph handles by node name."""
        return dict(self.server.scene._handle_from_node_name)

    def world_pose(self, node: str) -> np.ndarray:
        """The 4x4 world pose of scene node ``node``, composed along its parents."""
        handles = self.nodes()
        if node not in handles:
            raise InvalidInputError("node", node, "a scene node name (see Viewer.nodes())")
        T = np.eye(4)
        parts = node.strip("/").split("/")
        for k in range(1, len(parts) + 1):
            handle = handles.get("/" + "/".join(parts[:k]))
            if handle is None:
                continue
            w, x, y, z = handle.wxyz
            local = np.eye(4)
            local[:3, :3] = pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()
            local[:3, 3] = handle.position
            T = T @ local
        return T

    def serve_forever(self, poll: float = 0.2) -> None:
        """Block until Ctrl-C (or :meth:`close`), then stop the server."""
        try:
            while not self._stop.wait(poll):
                pass
        except KeyboardInterrupt:
            pass
        finally:
            self.close()

    def close(self) -> None:
        """Stop playback and the server (idempotent)."""
        if self._stop.is_set():
            return
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=2.0)
        with contextlib.suppress(Exception), contextlib.redirect_stdout(io.StringIO()):
            self.server.stop()

    def __enter__(self) -> Viewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Viewer({self.url}, robots={list(self.robots)}, t={self.time:.3f} s of [{self.start}, {self.end}])"


def motions_of(robot: Robot, sources: Iterable[Any]) -> list[Motion]:
    """Motions from trajectories, motion plans or motions (named ``plan``, ``plan2``, ...)."""
    out: list[Motion] = []
    for k, source in enumerate(sources):
        name = "plan" if k == 0 else f"plan{k + 1}"
        if isinstance(source, Motion):
            out.append(source)
            continue
        trajectory = getattr(source, "trajectory", source)  # a MotionPlan carries its trajectory
        out.append(Motion.from_trajectory(robot, trajectory, name))
    return out
