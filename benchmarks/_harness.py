"""Timing and result files shared by the benchmarks.

Each benchmark times a callable after a warm-up, reports median / p95 / p99 in microseconds, and saves a JSON file
and a Markdown fragment under ``benchmarks/results/``; ``python -m benchmarks`` stitches the fragments into
``benchmarks/RESULTS.md`` with the machine and library versions.
"""

from __future__ import annotations

import json
import platform
import time
from collections.abc import Callable, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

RESULTS_DIR = Path(__file__).resolve().parent / "results"

PACKAGES = (
    "taplan",
    "pin",
    "numpy",
    "qpsolvers",
    "proxsuite",
    "daqp",
    "quadprog",
    "osqp",
    "toppra",
    "ruckig",
    "casadi",
    "mink",
    "mujoco",
    "pin-pink",
)


def time_calls(func: Callable[[], Any], repeats: int, warmup: int = 50) -> dict[str, float]:
    """Call ``func`` ``warmup`` times untimed, then ``repeats`` times timed; statistics in [µs]."""
    for _ in range(warmup):
        func()
    samples = np.empty(repeats)
    clock = time.perf_counter_ns
    for i in range(repeats):
        start = clock()
        func()
        samples[i] = clock() - start
    return summarize(samples / 1e3)


def summarize(samples_us: Sequence[float] | np.ndarray) -> dict[str, float]:
    """Median, p95, p99, mean and count of samples given in [µs]."""
    s = np.asarray(samples_us, dtype=float)
    return {
        "median_us": float(np.median(s)),
        "p95_us": float(np.percentile(s, 95)),
        "p99_us": float(np.percentile(s, 99)),
        "mean_us": float(np.mean(s)),
        "count": int(s.size),
    }


def machine() -> dict[str, Any]:
    """The machine and the versions of the libraries that matter."""
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    import os

    return {
        "python": platform.python_version(),
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "versions": versions,
    }


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A Markdown table; floats get 4 significant digits."""

    def cell(x: Any) -> str:
        return f"{x:.4g}" if isinstance(x, float) else str(x)

    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(cell(x) for x in row) + " |" for row in rows]
    return "\n".join(lines)


def save(name: str, results: dict[str, Any], markdown: str) -> Path:
    """Write ``results/<name>.json`` (with the machine) and ``results/<name>.md`` (a section of RESULTS.md)."""
    RESULTS_DIR.mkdir(parents=True, exist_ok=True)
    payload = {"benchmark": name, "machine": machine(), "results": results}
    path = RESULTS_DIR / f"{name}.json"
    path.write_text(json.dumps(payload, indent=2, default=float))
    (RESULTS_DIR / f"{name}.md").write_text(markdown.rstrip() + "\n")
    return path
