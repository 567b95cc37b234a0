"""Robustness: 10,000+ generated inputs over every file and flag the command line reads.

Each input is written by ``benchmarks/_fuzz.py`` (trajectory JSON/CSV/NPZ, waypoint CSV, scene YAML/JSON, URDF
paths, rosbag2 MCAP files, flags and their ranges) from a seeded generator, given to ``taplan.cli.main`` in this
process (a full interpreter start per input would take hours on this machine), and judged: tracebacks (an escaping
exception or an internal error), wrong exit codes (not 0/1/2), exit 2 without exactly one error line, false passes
(exit 0 for a file beyond a limit), false fails (an unchanged valid input refused) and plans whose output
``taplan check`` does not pass. A sample runs as real ``python -m taplan`` processes, where C++ libraries' output
(urdfdom, the mcap reader) counts too.

Usage: ``python -m benchmarks.bench_fuzz [--quick] [--count N] [--subprocesses K] [--seed S] [--no-save]``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
import warnings
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import _fuzz, _harness

# share of the inputs per surface (the file formats of check get the most: they are what guards the robot)
WEIGHTS = {
    "trajectory_json": 0.19,
    "trajectory_csv": 0.19,
    "trajectory_npz": 0.14,
    "waypoint_csv": 0.07,
    "scene": 0.07,
    "urdf": 0.1,
    "bag": 0.08,
    "flags": 0.16,
}
PROBLEMS = ("traceback", "exit code", "error line", "false pass", "false fail", "bad output")


def _share_the_robot() -> None:
    """``Robot.teleavatar()`` without arguments built once in this process (60-90 ms of each input otherwise; the
    commands only read it). The sample of real processes and the tests build it per call as a user's run does."""
    from taplan.robot import Robot

    build = Robot.teleavatar
    shared: list[Robot] = []

    def teleavatar(cls: type[Robot], **kwargs: Any) -> Robot:
        if kwargs:
            return build(**kwargs)
        if not shared:
            shared.append(build())
        return shared[0]

    Robot.teleavatar = classmethod(teleavatar)  # type: ignore[method-assign]


def fuzz(count: int, subprocesses: int, seed: int, directory: Path) -> dict[str, Any]:
    _share_the_robot()
    rng = np.random.default_rng(seed)
    base = _fuzz.make_base(directory / "base")
    per_surface = {s: max(1, round(count * w)) for s, w in WEIGHTS.items()}
    rows: dict[str, dict[str, Any]] = {}
    examples: list[dict[str, Any]] = []
    for surface, n in per_surface.items():
        stats: Counter[str] = Counter()
        start = time.perf_counter()
        for i in range(n):
            spec = _fuzz.random_spec(rng, surface)
            work = directory / surface / str(i % 50)  # reused: keeps the disk use flat
            shutil.rmtree(work, ignore_errors=True)
            try:
                case, answer, problems = _fuzz.exercise(base, surface, spec, work)
            except Exception as exc:  # noqa: BLE001 - the generator's own failure (taplan's are judged inside)
                stats["generator errors"] += 1
                examples.append({"surface": surface, "spec": repr(spec), "generator error": repr(exc)})
                continue
            stats[f"exit {answer.code}"] += 1
            stats["violating inputs"] += case.violates
            stats["valid inputs"] += case.valid
            for p in problems:
                stats[p] += 1
                if len(examples) < 30:
                    examples.append({"surface": surface, "kind": case.kind, "argv": case.argv, "code": answer.code,
                                     "problem": p, "stderr": answer.err[-500:]})  # fmt: skip
        rows[surface] = {"inputs": n, "seconds": time.perf_counter() - start, **stats}
        print(f"{surface}: {dict(rows[surface])}", flush=True)
    sample = _subprocess_sample(base, rng, subprocesses, directory / "subprocess")
    return {"surfaces": rows, "subprocess": sample, "examples": examples, "seed": seed}


def _subprocess_sample(base: _fuzz.Base, rng: np.random.Generator, count: int, directory: Path) -> dict[str, Any]:
    stats: Counter[str] = Counter()
    start = time.perf_counter()
    surfaces = list(WEIGHTS)
    for i in range(count):
        surface = surfaces[i % len(surfaces)]
        case = _fuzz.make_case(base, surface, _fuzz.random_spec(rng, surface), directory / str(i))
        answer = _fuzz.run_subprocess(case.argv)
        stats["inputs"] += 1
        stats[f"exit {answer.code}"] += 1
        for p in _fuzz.judge(case, answer):
            stats[p] += 1
    return {"seconds": time.perf_counter() - start, **stats}


def markdown(results: dict[str, Any]) -> str:
    rows = []
    total: Counter[str] = Counter()
    for surface, r in results["surfaces"].items():
        total.update({k: v for k, v in r.items() if isinstance(v, int)})
        rows.append(
            [surface, r["inputs"], r.get("exit 0", 0), r.get("exit 1", 0), r.get("exit 2", 0)]
            + [r.get("violating inputs", 0)]
            + [r.get(p, 0) for p in PROBLEMS]
            + [f"{r['seconds']:.0f}"]
        )
    rows.append(
        ["**all**", total["inputs"], total["exit 0"], total["exit 1"], total["exit 2"], total["violating inputs"]]
        + [total[p] for p in PROBLEMS]
        + [f"{sum(r['seconds'] for r in results['surfaces'].values()):.0f}"]
    )
    sub = results["subprocess"]
    header = ["surface", "inputs", "exit 0", "exit 1", "exit 2", "beyond a limit"] + list(PROBLEMS) + ["s"]
    lines = [
        "## Robustness (fuzzing the command line)",
        "",
        f"`python -m benchmarks.bench_fuzz` (seed {results['seed']}): {total['inputs']:,} generated inputs given to "
        "`taplan.cli.main` in process, judged by `benchmarks/_fuzz.py` — tracebacks (or internal errors, exit 3), "
        "exit codes other than 0 pass / 1 check failed / 2 bad input, exit 2 without exactly one line "
        "`taplan CMD: error: ...`, **false passes** (exit 0 for an input beyond a position, velocity or "
        "acceleration limit: positions, coefficients, timing or bumps moved past it; the oracle samples at 20 kHz), "
        "false fails (an unchanged valid input refused) and plans whose output `taplan check` refuses. "
        f"Load average at the start {results['load_start'][0]:.1f} on {os.cpu_count()} cores.",
        "",
        _harness.markdown_table(header, rows),
        "",
        f"As real `python -m taplan` processes (C++ libraries' output on stderr counts): {sub.get('inputs', 0)} "
        f"inputs, exits 0/1/2 = {sub.get('exit 0', 0)}/{sub.get('exit 1', 0)}/{sub.get('exit 2', 0)}, "
        + ", ".join(f"{p} {sub.get(p, 0)}" for p in PROBLEMS)
        + f" ({sub['seconds']:.0f} s).",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1,000 inputs and 8 processes")
    parser.add_argument("--count", type=int, default=None, help="inputs in process (10,500)")
    parser.add_argument("--subprocesses", type=int, default=None, help="inputs as real processes (40)")
    parser.add_argument("--seed", type=int, default=20261127)
    parser.add_argument("--no-save", action="store_true")
    args = parser.parse_args(argv)
    count = args.count or (1000 if args.quick else 10_500)
    subprocesses = args.subprocesses if args.subprocesses is not None else (8 if args.quick else 40)
    load_start = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="taplan-fuzz-") as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        results = fuzz(count, subprocesses, args.seed, Path(tmp))
    results.update(load_start=load_start, load_end=os.getloadavg(), quick=args.quick)
    text = markdown(results)
    print(text)
    if not args.no_save:
        _harness.save("fuzz", results, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
