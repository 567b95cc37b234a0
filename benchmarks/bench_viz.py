"""The viewer's speed: time to the first frame of ``taplan view`` and the server's playback update rate.

Workload: a 10 s plan moving all 14 joints (quintic, 100 Hz knots) in a 20-obstacle scene (a table, a floor and 18
seeded boxes on the table), both written to files.

* **First frame.** ``taplan view plan.json --scene scene.yaml --port 0`` in a subprocess, timed from the spawn:
  (1) until it prints its URL (robot, scene, paths and GUI built, the server listening), (2) until a websocket
  client speaking viser's protocol has received the whole scene (the server's side of the first frame), (3) until
  headless Chromium, opened on that URL right then, shows the robot: the first screenshot whose 3D area holds the
  robot's colour (CPU WebGL through SwiftShader here: a GPU draws faster). Side by side, the same for a bare viser
  script that only starts a server and adds 20 boxes (the floor under any viser viewer).
* **Playback.** In process: the time of one playback update (``Viewer.set_time``: FK of 14 joints, 15 joint-node
  poses, the closest pair over the 20 obstacles and self pairs, the limits table), warm-up then median/p95; and the
  rate the playback thread actually reaches while playing for a few seconds (target 30 Hz).

Run: ``python -m benchmarks.bench_viz [--quick]``. Load averages are recorded with the figures.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import _harness
from benchmarks._browser import Browser, find_chromium

DURATION = 10.0  # [s] the plan
OBSTACLES = 20
TARGET_FIRST_FRAME = 2.0  # [s]
TARGET_RATE = 30.0  # [Hz]
ROBOT_BLUE = np.array([90, 140, 220])  # taplan.viz's plan colour (lit: shades of it)


def workload(folder: Path) -> tuple[Path, Path]:
    """The 10 s plan and the 20-obstacle scene as files in ``folder``."""
    from taplan.robot import Robot
    from taplan.scene import Box, HalfSpace, Scene, save_scene
    from taplan.trajectory import Trajectory

    robot = Robot.teleavatar()
    rng = np.random.default_rng(20)
    t = np.linspace(0.0, DURATION, int(DURATION * 100) + 1)
    span = (robot.limits.upper - robot.limits.lower) * 0.15
    phase = rng.uniform(0, 2 * np.pi, robot.nq)
    w = 2 * np.pi / DURATION
    q = robot.home + span * (np.sin(w * t[:, None] + phase) - np.sin(phase))
    v = span * w * np.cos(w * t[:, None] + phase)
    a = -span * w * w * np.sin(w * t[:, None] + phase)
    plan = Trajectory(t, q, v, a, robot.joint_names).save(folder / "plan.json")
    scene = Scene()
    scene.add("floor", HalfSpace(), ([0.0, 0.0, -1.0], [0, 0, 0, 1]))
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.6, 0.0, -0.45], [0, 0, 0, 1]))
    for k in range(OBSTACLES - 2):
        size = rng.uniform(0.03, 0.08, 3)
        x, y = rng.uniform([0.4, -0.5], [0.85, 0.5])
        scene.add(f"box{k}", Box(tuple(size)), ([x, y, -0.43 + size[2] / 2], [0, 0, 0, 1]))
    path = folder / "scene.yaml"
    save_scene(scene, path)
    return plan, path


_BARE_VISER = """
import numpy as np, viser
server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
server.scene.configure_environment_map(hdri=None)
for k in range(20):
    server.scene.add_box(f"/box{k}", color=(90, 140, 220), dimensions=(0.1, 0.1, 0.1), position=(0.0, 0.1 * k, 0.0))
print(f"serving at http://127.0.0.1:{server.get_port()}", flush=True)
import time
time.sleep(600)
"""


def _robot_drawn(image: np.ndarray) -> bool:
    """The 3D area (left of the GUI panel) holds at least 400 pixels of the robot's blue."""
    area = image[:, :600].astype(int)
    blueish = (area[..., 2] > area[..., 0] + 40) & (area[..., 2] > 80)
    return int(blueish.sum()) > 400


def _scene_delivered(url: str, timeout: float = 60.0) -> int:
    """Connect to a viser server as its web client does and read until the whole scene has arrived (viser's
    ``ReplayDoneMessage`` closes the backlog a new client gets); the number of messages."""
    import msgspec
    import viser
    import zstandard
    from websockets.sync.client import connect

    count = 0
    with connect(url.replace("http", "ws"), subprotocols=[f"viser-v{viser.__version__}"], max_size=None) as ws:
        while True:
            frame = ws.recv(timeout=timeout)
            size, packed = int.from_bytes(frame[:8], "little"), int.from_bytes(frame[8:16], "little")
            inner = zstandard.ZstdDecompressor().decompress(frame[16 : 16 + packed], max_output_size=size)
            for message in msgspec.msgpack.decode(inner)["messages"]:
                count += 1
                if message.get("type") == "ReplayDoneMessage":
                    return count


def _cpu_seconds(root: int) -> float:
    """CPU time [s] (user + system) used so far by process ``root`` and its live descendants (Linux /proc): what a
    command costs whatever the machine's load, where wall-clock times on the shared 2 cores stretch with it."""
    tick = os.sysconf("SC_CLK_TCK")
    parents, used = {}, {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # gone meanwhile
        parents[int(entry.name)] = int(fields[1])
        used[int(entry.name)] = (int(fields[11]) + int(fields[12])) / tick
    total = 0.0
    for pid, seconds in used.items():
        ancestor = pid
        while ancestor not in (root, 0, 1) and ancestor in parents:
            ancestor = parents[ancestor]
        if ancestor == root:
            total += seconds
    return total


def first_frame(command: list[str], browser: Browser | None, timeout: float = 120.0) -> dict[str, float]:
    """Seconds from spawning ``command`` to its URL line, and to the browser's first frame with the robot; and the
    CPU time the command's process used to its URL line and to the scene delivered, and the CPU time Chromium's
    processes used from opening the page to that frame."""
    start = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        url = None
        for line in process.stdout:  # viser prints a banner first
            url = re.search(r"http://127\.0\.0\.1:\d+", line)
            if url is not None:
                break
        ready = time.perf_counter() - start
        if url is None:
            raise RuntimeError(f"no URL from {command}")
        out = {"url_printed_s": ready, "url_cpu_s": _cpu_seconds(process.pid)}
        _scene_delivered(url.group(0))
        out["scene_delivered_s"] = time.perf_counter() - start
        out["scene_cpu_s"] = _cpu_seconds(process.pid)
        if browser is not None:
            browser_cpu = _cpu_seconds(browser.process.pid)
            browser.open(url.group(0) + "/?fixedDpr=1")
            while not _robot_drawn(browser.screenshot()):
                if time.perf_counter() - start > timeout:
                    raise TimeoutError("the robot never appeared")
                time.sleep(0.05)
            out["first_frame_s"] = time.perf_counter() - start
            out["browser_cpu_s"] = _cpu_seconds(browser.process.pid) - browser_cpu
        return out
    finally:
        process.terminate()
        process.wait(timeout=20)


def playback(plan: Path, scene_path: Path, frames: int, seconds: float) -> dict[str, Any]:
    """Per-update time of the server (set_time) and the rate the playback thread reaches."""
    from taplan import viz
    from taplan.robot import Robot
    from taplan.scene import load_scene
    from taplan.trajectory import Trajectory

    robot = Robot.teleavatar()
    with contextlib.redirect_stdout(io.StringIO()):
        viewer = viz.Viewer(robot, load_scene(scene_path), viz.motions_of(robot, [Trajectory.load(plan)]), port=0)
    try:
        times = iter(np.tile(np.linspace(0.0, DURATION, 997), frames // 997 + 2))
        stats = _harness.time_calls(lambda: viewer.set_time(float(next(times))), frames, warmup=30)
        counted = []
        original = viewer.set_time

        def counting(t: float) -> None:
            counted.append(time.perf_counter())
            original(t)

        viewer.set_time = counting  # type: ignore[method-assign]
        viewer.play()
        time.sleep(seconds)
        viewer.pause()
        stamps = np.asarray(counted)
        rate = (len(stamps) - 1) / (stamps[-1] - stamps[0]) if len(stamps) > 1 else 0.0
        gaps = np.diff(stamps) * 1e3 if len(stamps) > 1 else np.zeros(1)
    finally:
        with contextlib.redirect_stdout(io.StringIO()):
            viewer.close()
    return {
        "update": stats,
        "update_capacity_hz": 1e6 / stats["median_us"],
        "playback_rate_hz": float(rate),
        "playback_gap_p95_ms": float(np.percentile(gaps, 95)),
        "target_hz": viewer.rate,
    }


def markdown(results: dict[str, Any]) -> str:
    first = results["first_frame"]
    rows = []
    for name, runs in first.items():
        row: list[Any] = [name]
        for key in ("url_printed_s", "scene_delivered_s", "first_frame_s"):
            values = [r[key] for r in runs if key in r]
            row += [float(np.median(values)), float(np.max(values))] if values else ["-", "-"]
        for key in ("url_cpu_s", "scene_cpu_s", "browser_cpu_s"):
            values = [r[key] for r in runs if key in r]
            row.append(float(np.median(values)) if values else "-")
        rows.append(row)
    p = results["playback"]
    text = [
        "## Viewer: first frame and playback (taplan view, 10 s plan, 14 joints, 20 obstacles)",
        "",
        f"From the command to the server listening with everything built (URL printed), to the whole scene "
        f"received by a client speaking viser's protocol (the server's side of the first frame), and to the first "
        f"browser frame showing the robot (headless Chromium, CPU WebGL), {len(next(iter(first.values())))} runs "
        f"each; target: first frame within {TARGET_FIRST_FRAME:.0f} s. Load average at the start "
        f"{results['load_start'][0]:.2f}, at the end {results['load_end'][0]:.2f} (2 cores shared): the wall "
        "times stretch with the load, so the CPU time each step used (the command's process to its URL and to the "
        "scene delivered; Chromium's processes from opening the page to the frame) is given too: on an idle core "
        "the wall time is about that CPU time.",
        "",
        _harness.markdown_table(
            [
                "what",
                "URL printed median [s]",
                "max [s]",
                "scene delivered median [s]",
                "max [s]",
                "browser frame median [s]",
                "max [s]",
                "CPU to URL [s]",
                "CPU to scene delivered [s]",
                "browser CPU to frame [s]",
            ],
            rows,
        ),
        "",
        f"Playback (server side, no browser connected): one update (FK, 15 joint nodes, closest pair over "
        f"{OBSTACLES} obstacles and the self pairs, limits table) takes {p['update']['median_us'] / 1e3:.2f} ms "
        f"median, {p['update']['p95_us'] / 1e3:.2f} ms p95 (capacity {p['update_capacity_hz']:.0f} Hz); while "
        f"playing, the thread updated the robot at {p['playback_rate_hz']:.1f} Hz (its rate "
        f"{p['target_hz']:.0f} Hz, required >= {TARGET_RATE:.0f} Hz; "
        f"p95 gap {p['playback_gap_p95_ms']:.1f} ms).",
    ]
    return "\n".join(text)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 runs per command, 300 timed updates")
    parser.add_argument("--runs", type=int, default=None, help="runs per command (5)")
    parser.add_argument("--no-browser", action="store_true", help="only time the server side")
    parser.add_argument("--no-save", action="store_true")
    args = parser.parse_args(argv)
    runs = args.runs or (2 if args.quick else 5)
    load_start = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="taplan-bench-viz-") as folder:
        plan, scene = workload(Path(folder))
        bare = Path(folder) / "bare_viser.py"
        bare.write_text(_BARE_VISER)
        browser = None if args.no_browser or find_chromium() is None else Browser(960, 640)
        try:
            commands = {
                "taplan view": [
                    sys.executable,
                    "-m",
                    "taplan",
                    "view",
                    str(plan),
                    "--scene",
                    str(scene),
                    "--port",
                    "0",
                ],
                "bare viser, 20 boxes": [sys.executable, str(bare)],
            }
            first = {name: [first_frame(cmd, browser) for _ in range(runs)] for name, cmd in commands.items()}
        finally:
            if browser is not None:
                browser.close()
        frames = 300 if args.quick else 1500
        results = {
            "first_frame": first,
            "playback": playback(plan, scene, frames, 3.0 if args.quick else 5.0),
            "load_start": load_start,
            "load_end": os.getloadavg(),
            "quick": args.quick,
        }
    text = markdown(results)
    print(text)
    if not args.no_save:
        _harness.save("viz", results, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
