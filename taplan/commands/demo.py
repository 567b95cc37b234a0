"""Plan, replay, check and compare on the bundled TeleAvatar model (no robot needed).

Three jerk-limited plans (a dual-arm reach to two end-effector poses, a dual-arm Cartesian straight line, a pick
with straight descent and lift) are replayed through the reference controllers and checked against the hardware
limits; the robot guide's own approaches (linear interpolation at 50 Hz, the clipped P-controller) run on the same
motion for comparison. Report, plots (PNG), trajectories and a 3D page of the scene plan (``scene.html``, opens
without a server) go into the output folder.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-o", "--out", default="taplan-demo", help="output folder (default ./taplan-demo)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from taplan.demo import run_demo
    from taplan.io import output_path

    output_path(args.out, "--out", directory=True)  # before the progress bar, so an error is one clean line

    start = time.perf_counter()
    bar = tqdm(total=9 if not args.no_plots else 6, desc="taplan demo", unit="step", leave=False)

    def progress(message: str) -> None:
        bar.set_postfix_str(message[:60])
        bar.update(1)

    result = run_demo(args.out, progress=progress, plots=not args.no_plots)
    bar.close()
    print(
        "taplan demo on the bundled TeleAvatar: plans under the planning limits, checks against the hardware ceilings\n"
    )
    failed = 0
    for plan in result.plans:
        print(f"== {plan.name}: {plan.description} ({plan.trajectory.duration:.2f} s)")
        for note in plan.notes:
            print(f"   {note}")
        print(
            f"   {'replayed through':<28}{'peak v/lim':>11}{'peak a/lim':>11}{'max |dv| [rad/s]':>18}"
            f"{'SPARC':>8}  result"
        )
        for label, report in plan.reports.items():
            failed += not report.passed
            print(_row(label, report))
        print()
    print("== the guide's approaches vs taplan on the reach motion, as the arm's 100 Hz joint loop runs them")
    print(f"   {'approach':<50}{'peak a/lim':>11}{'max |dv| [rad/s]':>18}{'SPARC':>8}  result")
    for c in result.comparisons:
        print(_row(c.approach, c.report, width=50, velocity=False))
    print(
        "\n   |dv| is the largest velocity change between two 10 ms updates; a step larger than the acceleration"
        "\n   ceiling x 10 ms is a velocity step the arm cannot follow. Position targets sent at 50 Hz into a 100 Hz"
        "\n   loop move every other tick (a staircase) whatever the plan: stream at the loop rate (taplan.stream)."
    )
    print(f"\nwrote {len(result.files)} files to {result.out_dir.resolve()}/ in {time.perf_counter() - start:.1f} s:")
    for path in result.files:
        print(f"   {path.name}")
    return 1 if failed else 0


def _row(label, report, width: int = 28, velocity: bool = True) -> str:
    joints = report.joints
    v = max(j.peak_velocity / j.velocity_limit for j in joints)
    a = max(j.peak_acceleration / j.acceleration_limit for j in joints)
    dv = max(j.max_velocity_step for j in joints)
    moved = [j.sparc for j in joints if j.sparc is not None and np.isfinite(j.sparc)]  # a still joint has none
    sparc = float(np.mean(moved)) if moved else float("nan")
    reasons = {f.split(" ")[0] for j in joints for f in j.failures}
    reasons |= {f.split(":")[0] for f in report.failures if not any(f.startswith(j.name) for j in joints)}
    verdict = "PASS" if report.passed else "FAIL: " + "; ".join(sorted(reasons))
    vcol = f"{v:>11.3f}" if velocity else ""
    return f"   {label:<{width}}{vcol}{a:>11.3f}{dv:>18.4f}{sparc:>8.2f}  {verdict}"
