"""Time parameterisation: taplan.timing.retime / jerk_limited vs toppra with its defaults.

Seeded random 7-DOF paths (TeleAvatar left arm, planning limits) of 10, 50 and 200 waypoints. For each method:
compute time, trajectory duration, and the largest sampled (1 kHz) |q̇|/limit, |q̈|/limit and |jerk|/limit, plus
failures. toppra's defaults: ``TOPPRA([JointVelocityConstraint, JointAccelerationConstraint], path)`` with its own
gridpoint proposal and ``ParametrizeSpline`` output, on the same ``taplan.timing.Path``.

Run: ``python -m benchmarks.bench_timing [--quick] [--repeats N]``.
"""

from __future__ import annotations

import argparse
import logging
import time
from typing import Any

import numpy as np
import toppra
import toppra.algorithm
import toppra.constraint

import taplan
from benchmarks import _harness
from benchmarks._paths import random_walk
from taplan.timing import Path, jerk_limited, retime

SIZES = (10, 50, 200)
RATE = 1000.0  # [Hz] sampling for the limit checks


def _ratios(
    evaluate: Any, duration: float, limits: taplan.JointLimits, jerk: bool = False
) -> tuple[float, float, float]:
    t = np.arange(0.0, duration, 1.0 / RATE)
    t = np.append(t, duration)
    v = float(np.max(np.abs(evaluate(t, 1)) / limits.velocity))
    a = float(np.max(np.abs(evaluate(t, 2)) / limits.acceleration))
    j = float(np.max(np.abs(evaluate(t, 3)) / limits.jerk)) if jerk else float("nan")
    return v, a, j


def _timed(func: Any, repeats: int) -> tuple[Any, float]:
    out = None
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        out = func()
        samples.append(time.perf_counter() - start)
    return out, float(np.median(samples)) * 1e3


def toppra_defaults(path: Path, limits: taplan.JointLimits) -> Any:
    instance = toppra.algorithm.TOPPRA(
        [
            toppra.constraint.JointVelocityConstraint(limits.velocity),
            toppra.constraint.JointAccelerationConstraint(limits.acceleration),
        ],
        path,
    )
    return instance.compute_trajectory()


def run(sizes: tuple[int, ...], seeds: int, repeats: int, jerk: bool) -> dict[str, Any]:
    logging.getLogger("toppra").setLevel(logging.ERROR)
    robot = taplan.Robot.teleavatar()
    limits = robot.planning_limits.subset(robot.group("left").joint_names)
    rows: list[dict[str, Any]] = []
    for size in sizes:
        for seed in range(seeds):
            path = Path(random_walk(limits, size, 1000 * size + seed))
            record: dict[str, Any] = {"waypoints": size, "seed": seed}
            traj, ms = _timed(lambda p=path: toppra_defaults(p, limits), repeats)
            if traj is None:
                record["toppra"] = {"failed": True, "ms": ms}
            else:
                v, a, _ = _ratios(traj, traj.duration, limits)
                record["toppra"] = {"failed": False, "ms": ms, "duration": traj.duration, "vel": v, "acc": a}
            try:
                ours, ms = _timed(lambda p=path: retime(p, limits), repeats)
                v, a, _ = _ratios(ours, ours.duration, limits)
                record["retime"] = {"failed": False, "ms": ms, "duration": ours.duration, "vel": v, "acc": a}
            except taplan.TaplanError as exc:
                record["retime"] = {"failed": True, "error": str(exc)}
            if jerk:
                try:
                    res, ms = _timed(lambda p=path: jerk_limited(p, limits), 1)
                    tr = res.trajectory
                    v, a, j = _ratios(tr, tr.duration, limits, jerk=True)
                    record["jerk_limited"] = {
                        "failed": False,
                        "ms": ms,
                        "duration": tr.duration,
                        "ratio_to_topp": res.duration_ratio,
                        "vel": v,
                        "acc": a,
                        "jerk": j,
                    }
                except taplan.TaplanError as exc:
                    record["jerk_limited"] = {"failed": True, "error": str(exc)}
            rows.append(record)
    return {"rows": rows, "rate_hz": RATE, "limits": "TeleAvatar left arm, planning limits (0.3 x ceilings)"}


def _summary(results: dict[str, Any]) -> tuple[list[list[Any]], bool]:
    table: list[list[Any]] = []
    ok = True
    sizes = sorted({r["waypoints"] for r in results["rows"]})
    for size in sizes:
        rows = [r for r in results["rows"] if r["waypoints"] == size]
        base = [r["toppra"] for r in rows]
        for method in ("toppra", "retime", "jerk_limited"):
            recs = [r[method] for r in rows if method in r]
            if not recs:
                continue
            good = [x for x in recs if not x["failed"]]
            fails = len(recs) - len(good)
            ms = float(np.median([x["ms"] for x in good])) if good else float("nan")
            dur = float(np.mean([x["duration"] for x in good])) if good else float("nan")
            pairs = zip(recs, base, strict=True)
            rel = [x["duration"] / b["duration"] for x, b in pairs if not x["failed"] and not b["failed"]]
            vmax = max((x["vel"] for x in good), default=float("nan"))
            amax = max((x["acc"] for x in good), default=float("nan"))
            jmax = max((x["jerk"] for x in good), default=float("nan")) if method == "jerk_limited" else "-"
            extra = f"{max(x['ratio_to_topp'] for x in good):.3f}" if method == "jerk_limited" and good else "-"
            table.append([size, method, ms, dur, f"{max(rel):.4f}" if rel else "-", vmax, amax, jmax, extra, fails])
            if method != "toppra":
                ok &= fails == 0 and vmax <= 1 + 1e-6 and amax <= 1 + 1e-6
                if method == "retime":
                    ok &= bool(rel) and max(rel) <= 1.02 and min(rel) >= 0.98
                    ok &= ms <= float(np.median([b["ms"] for b in base if not b["failed"]]))
                if method == "jerk_limited":
                    ok &= isinstance(jmax, float) and jmax <= 1 + 1e-6
                    ok &= max(x["ratio_to_topp"] for x in good) <= 1.15
    return table, ok


def markdown(results: dict[str, Any], seeds: int) -> str:
    table, ok = _summary(results)
    header = [
        "waypoints",
        "method",
        "compute [ms] (median)",
        "duration [s] (mean)",
        "max duration / toppra",
        "max abs(q̇)/limit",
        "max abs(q̈)/limit",
        "max abs(jerk)/limit",
        "max jerk-limited / TOPP-RA duration",
        "failures",
    ]
    lines = [
        "## Time parameterisation (taplan.timing vs toppra defaults)",
        "",
        f"Seeded random-walk 7-DOF paths (TeleAvatar left arm, planning limits), {seeds} path(s) per size; "
        "limits checked on 1 kHz samples. `toppra` = `TOPPRA([JointVelocityConstraint, JointAccelerationConstraint], "
        "path)` with its default gridpoints and `ParametrizeSpline`; `retime` = `taplan.timing.retime`; "
        "`jerk_limited` = `taplan.timing.jerk_limited` (TOPP-RA + moving-average filter of s(t)).",
        "",
        _harness.markdown_table(header, table),
        "",
        "Goals (zero violations for retime and jerk_limited, retime compute <= toppra and duration within 2 %, "
        f"jerk-limited duration <= 1.15 x TOPP-RA): **{'met' if ok else 'NOT met'}**.",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="10 and 50 waypoints, 1 path each, < 60 s")
    parser.add_argument("--repeats", type=int, default=3, help="timed calls per method and path (median)")
    parser.add_argument("--seeds", type=int, default=3, help="random paths per size")
    parser.add_argument("--no-jerk", action="store_true", help="skip the jerk-limited method")
    parser.add_argument("--no-save", action="store_true", help="print only")
    args = parser.parse_args(argv)
    sizes = (10, 50) if args.quick else SIZES
    seeds = 1 if args.quick else args.seeds
    repeats = 1 if args.quick else args.repeats
    results = run(sizes, seeds, repeats, jerk=not args.no_jerk)
    text = markdown(results, seeds)
    print(text)
    if not args.no_save:
        _harness.save("timing", results, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
