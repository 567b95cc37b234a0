"""A headless Chromium driven through the DevTools protocol (CDP), for the viewer's browser tests and benchmark.

Chromium renders WebGL on the CPU here (SwiftShader; no GPU on CI): the flags below are the ones measured to work
(see the browser-test notes: ``--disable-software-rasterizer`` would leave the scene blank). Screenshots are taken
until two consecutive ones agree, so half-finished states (panel animations, a toast) are not asserted on.
"""

from __future__ import annotations

import base64
import contextlib
import io
import json
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Browser", "find_chromium", "project"]

FLAGS = (
    "--headless=new",
    "--no-sandbox",  # CI runs as root
    "--disable-gpu",
    "--use-angle=swiftshader-webgl",
    "--enable-unsafe-swiftshader",
    "--hide-scrollbars",
    "--mute-audio",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-background-timer-throttling",
    "--disable-renderer-backgrounding",
)


def find_chromium() -> str | None:
    """Path of Debian's chromium (or another Chromium/Chrome on PATH), or None."""
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


class Browser:
    """One headless Chromium with one page, driven over CDP.

    Args:
        width, height: Viewport [px] (device pixel ratio 1).
        executable: Chromium binary (default: :func:`find_chromium`).
    """

    def __init__(self, width: int = 960, height: int = 640, executable: str | None = None, timeout: float = 30.0):
        from websockets.sync.client import connect

        executable = executable or find_chromium()
        if executable is None:
            raise RuntimeError("chromium not found (Debian: apt-get install -y --no-install-recommends chromium)")
        self.width, self.height = width, height
        self._profile = tempfile.mkdtemp(prefix="taplan-chromium-")
        self.process = subprocess.Popen(
            [executable, *FLAGS, "--remote-debugging-port=0", f"--user-data-dir={self._profile}",
             f"--window-size={width},{height}", "about:blank"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )  # fmt: skip
        port_file = Path(self._profile) / "DevToolsActivePort"
        deadline = time.monotonic() + timeout
        while not (port_file.is_file() and port_file.read_text().count("\n") >= 1):
            if time.monotonic() > deadline or self.process.poll() is not None:
                self.close()
                raise RuntimeError("chromium did not open its DevTools port")
            time.sleep(0.05)
        port, path = port_file.read_text().split("\n")[:2]
        self._ws = connect(f"ws://127.0.0.1:{port}{path}", max_size=64 * 1024 * 1024, open_timeout=timeout)
        self._id = 0
        self._session: str | None = None
        self._target: str | None = None

    def send(self, method: str, timeout: float = 60.0, **params: Any) -> dict[str, Any]:
        """Send a CDP command (to the open page, or the browser when none) and return its result."""
        self._id += 1
        message: dict[str, Any] = {"id": self._id, "method": method, "params": params}
        if self._session is not None and not method.startswith("Target."):
            message["sessionId"] = self._session
        self._ws.send(json.dumps(message))
        deadline = time.monotonic() + timeout
        while True:
            reply = json.loads(self._ws.recv(timeout=max(0.01, deadline - time.monotonic())))
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def open(self, url: str) -> None:
        """Open ``url`` in a fresh page (the previous one is closed)."""
        if self._target is not None:
            self.send("Target.closeTarget", targetId=self._target)
            self._session = self._target = None
        self._target = self.send("Target.createTarget", url=url)["targetId"]
        self._session = self.send("Target.attachToTarget", targetId=self._target, flatten=True)["sessionId"]
        self.send("Page.enable")
        self.send(
            "Emulation.setDeviceMetricsOverride",
            width=self.width,
            height=self.height,
            deviceScaleFactor=1,
            mobile=False,
        )

    def evaluate(self, expression: str) -> Any:
        result = self.send("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        return result.get("result", {}).get("value")

    def key(self, key: str, code: str, key_code: int) -> None:
        """Press and release a key in the focused element."""
        for kind in ("rawKeyDown", "keyUp"):
            self.send("Input.dispatchKeyEvent", type=kind, key=key, code=code, windowsVirtualKeyCode=key_code)

    def screenshot(self) -> np.ndarray:
        """The viewport as an (H, W, 3) uint8 RGB array."""
        from PIL import Image

        data = base64.b64decode(self.send("Page.captureScreenshot", format="png")["data"])
        return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))

    def settled(self, timeout: float = 90.0, interval: float = 0.5, tolerance: int = 0) -> tuple[np.ndarray, float]:
        """A screenshot once two consecutive ones agree (at most ``tolerance`` differing pixels) and the page is not
        blank; and the seconds it took. Raises TimeoutError."""
        start = time.monotonic()
        previous = None
        while time.monotonic() - start < timeout:
            image = self.screenshot()
            same = previous is not None and int(np.count_nonzero(np.any(image != previous, axis=2))) <= tolerance
            if same and image.std() > 1.0:
                return image, time.monotonic() - start
            previous = image
            time.sleep(interval)
        raise TimeoutError(f"the page did not settle within {timeout} s")

    def close(self) -> None:
        if getattr(self, "_ws", None) is not None:
            with contextlib.suppress(Exception):
                self._ws.close()
            self._ws = None
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        shutil.rmtree(self._profile, ignore_errors=True)

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def project(points: np.ndarray, camera: Any, width: int, height: int) -> np.ndarray:
    """Pixel coordinates (N, 2) of world points through a perspective camera (``position``, ``look_at``, ``up``,
    vertical ``fov`` [rad]) filling a ``width`` x ``height`` canvas (three.js conventions)."""
    eye = np.asarray(camera.position, dtype=float)
    forward = np.asarray(camera.look_at, dtype=float) - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(camera.up, dtype=float))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    rel = np.atleast_2d(points) - eye
    depth = rel @ forward
    tan = np.tan(camera.fov / 2)
    x = (rel @ right) / (depth * tan * width / height)
    y = (rel @ up) / (depth * tan)
    return np.column_stack([(x + 1) / 2 * width, (1 - y) / 2 * height])
