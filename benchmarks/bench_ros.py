"""ROS 2 over DDS on loopback: round-trip latency command -> joint_states, and the sustained command rate.

Two processes, real Cyclone DDS discovery and serialisation on 127.0.0.1: ``taplan sim`` in a subprocess and this
process as the client. After enabling the simulated robot (heartbeat, READY):

* **Round trip.** Publish a ``/api/left_arm/joint_cmd`` with a new position (±1 mrad on l_joint1) and wait until
  ``/left_arm/joint_states`` reports it. The sim moves on its 100 Hz motion tick and publishes states at
  ``--rate``: the figure is transport + those ticks, as with a robot; the 1000 Hz row shows the transport better.
* **Sustained rate.** Publish valid ``joint_cmd`` messages to both arms as fast as one Python loop can for 2 s; the
  sim records what it received (its bag), so losses are counted.

Run: ``python -m benchmarks.bench_ros [--quick]``.
"""

from __future__ import annotations

import argparse
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import taplan
from benchmarks import _harness
from taplan import api
from taplan.ros.bag import read_messages
from taplan.ros.dds import DdsInterface, loopback_config
from taplan.ros.runner import Runner, RunnerConfig


def _start_sim(domain: int, rate: float, bag: Path, duration: float) -> subprocess.Popen:
    command = [sys.executable, "-m", "taplan", "sim", "--loopback", "--domain-id", str(domain)]
    command += ["--rate", str(rate), "--motion-rate", str(rate), "--duration", str(duration), "--bag", str(bag)]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert process.stdout is not None
    line = process.stdout.readline()
    if "TeleAvatar" not in line:
        raise RuntimeError(f"taplan sim did not start: {line}")
    return process


def _scenario(state_rate: float, samples: int, burst: float) -> dict[str, Any]:
    robot = taplan.Robot.teleavatar()
    domain = random.randint(100, 230)
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "sim.mcap"
        process = _start_sim(domain, state_rate, bag, duration=samples * 0.05 + burst + 15.0)
        interface = DdsInterface(domain, config=loopback_config())
        runner = Runner(interface, robot, config=RunnerConfig())
        start = runner.wait_for_state()
        runner.arm(start)
        enable = interface.create_publisher(api.FLOAT32, api.Topics.ENABLE)
        command = interface.create_publisher(api.JOINT_STATE, api.Topics.joint_cmd("left"))
        right = interface.create_publisher(api.JOINT_STATE, api.Topics.joint_cmd("right"))
        latest: list[float] = [float(start[0])]
        interface.create_subscription(
            api.JOINT_STATE, api.Topics.joint_states("left"), lambda f: latest.__setitem__(0, f["position"][0])
        )
        q = start[:7].copy()
        latencies = []
        next_beat = time.monotonic()
        for i in range(samples):
            q[0] = start[0] + (1e-3 if i % 2 == 0 else -1e-3)
            sent = time.perf_counter()
            command.publish(api.joint_cmd("left", q).fields)
            right.publish(api.joint_cmd("right", start[7:]).fields)
            while abs(latest[0] - q[0]) > 1e-12:
                interface.spin_once()
                if time.monotonic() >= next_beat:
                    enable.publish(api.fsm_enable(True).fields)
                    next_beat = time.monotonic() + 0.05
                if time.perf_counter() - sent > 1.0:
                    raise RuntimeError("no joint state echoed the command within 1 s")
            latencies.append((time.perf_counter() - sent) * 1e6)
        # paced at the robot's 77 Hz for `burst` seconds: nothing may be lost
        paced = 0
        q[0] = start[0] + 2e-3  # marks the paced commands in the sim's bag
        begin = time.perf_counter()
        while time.perf_counter() - begin < burst:
            command.publish(api.joint_cmd("left", q).fields)
            right.publish(api.joint_cmd("right", start[7:]).fields)
            paced += 1
            if time.monotonic() >= next_beat:
                enable.publish(api.fsm_enable(True).fields)
                next_beat = time.monotonic() + 0.05
            deadline = begin + paced / 77.0
            while time.perf_counter() < deadline:
                interface.spin_once()
                time.sleep(0.0005)
        # sustained rate: as fast as one loop can, both arms, heartbeat kept
        count = 0
        publish_us = []
        begin = time.perf_counter()
        while time.perf_counter() - begin < burst:
            q[0] = start[0] + 3e-3 + 1e-3 * (count % 2)  # marks the flood's commands
            t0 = time.perf_counter_ns()
            command.publish(api.joint_cmd("left", q).fields)
            publish_us.append((time.perf_counter_ns() - t0) / 1e3)
            right.publish(api.joint_cmd("right", start[7:]).fields)
            count += 1
            if time.monotonic() >= next_beat:
                enable.publish(api.fsm_enable(True).fields)
                next_beat = time.monotonic() + 0.05
            interface.spin_once()
        elapsed = time.perf_counter() - begin
        interface.close()
        time.sleep(0.5)
        process.terminate()
        process.wait(timeout=30)
        marks = [
            msg.position[0] - start[0] for topic, _, msg in read_messages(bag) if topic == api.Topics.joint_cmd("left")
        ]
        paced_received = sum(1 for m in marks if abs(m - 2e-3) < 1e-9)
        received = sum(1 for m in marks if m > 2.5e-3)
    stats = _harness.summarize(latencies)
    return {
        "state_rate_hz": state_rate,
        "round_trip_us": stats,
        "sustained": {
            "sent": count,
            "seconds": elapsed,
            "rate_hz": count / elapsed,
            "received_by_sim": received,
            "paced_77hz_sent": paced,
            "paced_77hz_received": paced_received,
            "publish_us": _harness.summarize(publish_us),
        },
    }


def markdown(results: dict[str, Any]) -> str:
    rows = []
    for r in results["scenarios"]:
        rt, s = r["round_trip_us"], r["sustained"]
        rows.append(
            [
                f"{r['state_rate_hz']:g}",
                rt["median_us"] / 1e3,
                rt["p99_us"] / 1e3,
                rt["count"],
                s["rate_hz"],
                s["publish_us"]["median_us"],
                f"{s['received_by_sim']} / {s['sent']}",
                f"{s['paced_77hz_received']} / {s['paced_77hz_sent']}",
            ]
        )
    header = [
        "sim motion and joint_states rate [Hz]",
        "round trip median [ms]",
        "round trip p99 [ms]",
        "samples",
        "sustained joint_cmd rate, both arms [Hz]",
        "publish call median [µs]",
        "flood: received by the sim / sent",
        "paced at 77 Hz: received / sent",
    ]
    worst = min(r["sustained"]["rate_hz"] for r in results["scenarios"])
    return "\n".join(
        [
            "## ROS 2 over DDS (taplan.ros, loopback)",
            "",
            "`taplan sim` in a subprocess, this process as the client, Cyclone DDS on 127.0.0.1 (real discovery and "
            "CDR). Round trip: a `/api/left_arm/joint_cmd` with a new position until `/left_arm/joint_states` reports "
            "it; the sim moves and publishes at the row's rate, so the robot-like row (100 Hz) includes up to two "
            "10 ms ticks by design and the 1000 Hz row shows the transport. Sustained: joint_cmd to both arms from one "
            "Python loop for 2 s (flood), and paced at 77 Hz for 2 s, with the heartbeat; the sim's bag counts what "
            "arrived. Under the flood the sim's loop (one Python process) drains more slowly than the sender writes "
            "and keep-last 10 (rclpy's default QoS) drops the oldest samples (newer commands replace them).",
            "",
            _harness.markdown_table(header, rows),
            "",
            f"The slowest sustained rate, {worst:.0f} Hz, is {worst / 77:.0f} x the 77 Hz the robot takes.",
        ]
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="100 round trips, 1 s burst")
    parser.add_argument("--no-save", action="store_true")
    args = parser.parse_args(argv)
    samples, burst = (100, 1.0) if args.quick else (1000, 2.0)
    os.environ.pop("CYCLONEDDS_URI", None)
    scenarios = [_scenario(rate, samples, burst) for rate in (100.0, 1000.0)]
    results = {"scenarios": scenarios, "quick": args.quick}
    text = markdown(results)
    print(text)
    if not args.no_save:
        _harness.save("ros", results, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
