"""Nothing unsafe reaches the robot: what `taplan run` refuses, seen by an independent DDS participant.

Each test starts ``taplan sim --loopback`` on its own random domain (the fixtures of ``test_ros_run``) and records
every ``/api/{side}_arm/joint_cmd`` with a second participant (a separate :class:`DdsInterface`, as a ROS 2 node
listening on the robot's side would).
"""

from __future__ import annotations

import argparse
import random
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import test_ros_run
import yaml

import taplan
from taplan import api
from taplan.clearance import teleavatar_world
from taplan.errors import InvalidInputError
from taplan.ros.dds import DdsInterface, loopback_config
from taplan.ros.interface import FakeRosInterface
from taplan.ros.msg_definitions import FSM_STATE_TOPIC, INT32
from taplan.ros.runner import CheckFailedError, RunError, Runner, RunnerConfig
from taplan.stream import PoseStreamer
from taplan.timing import jerk_limited

robot = test_ros_run.robot  # the fixtures of test_ros_run (the Robot; a `taplan sim --loopback` subprocess)
start_sim = test_ros_run.start_sim

# the right gripper 95 mm inside the torso (torso / right_gripper_0), inside the joint limits; the straight path
# from home first touches the torso at 76 % of the way. (The pose before it put the fingers into the earlier
# estimate of the lift column below the torso; the real column is behind the torso, and that pose is 39 mm clear.)
INTO_TORSO = np.array([-0.607, -1.438, 2.201, -1.819, 0.805, -0.013, -0.458])


class CommandListener:
    """A second participant recording every joint_cmd of both arms (positions in the message order)."""

    def __init__(self, domain: int) -> None:
        self.interface = DdsInterface(domain, config=loopback_config())
        self.commands: dict[str, list[np.ndarray]] = {side: [] for side in api.SIDES}
        self.velocities: dict[str, list[np.ndarray]] = {side: [] for side in api.SIDES}
        for side in api.SIDES:
            self.interface.create_subscription(api.JOINT_STATE, api.Topics.joint_cmd(side), self._record(side))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _record(self, side: str):  # noqa: ANN202
        def record(fields: dict) -> None:
            self.commands[side].append(fields["position"])
            self.velocities[side].append(fields["velocity"])

        return record

    def _spin(self) -> None:
        while not self._stop.is_set():
            self.interface.spin_once()
            time.sleep(0.001)

    def close(self) -> dict[str, np.ndarray]:
        time.sleep(0.3)  # the last commands in flight
        self._stop.set()
        self._thread.join()
        self.interface.close()
        return {side: np.array(c, dtype=float).reshape(-1, 7) for side, c in self.commands.items()}


def _cli_run(sim, *arguments: str) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "taplan", "run", *arguments, "--loopback", "--domain-id", str(sim.domain)]
    command += test_ros_run.STEADY_CLI
    return subprocess.run(command, capture_output=True, text=True, timeout=120)


def test_run_refuses_a_one_sample_jump_that_check_fails_and_sends_nothing(robot, start_sim, tmp_path: Path) -> None:
    sim = start_sim()
    listener = CommandListener(sim.domain)
    t = np.arange(0.0, 2.0 + 1e-9, 0.01)  # a 100 Hz file
    q = np.repeat(robot.home[None, :], len(t), axis=0)
    q[100, 1] += 0.6  # one sample of l_joint2 0.6 rad off, inside its position limits
    path = tmp_path / "jump.csv"
    header = "time," + ",".join(f"{n}.pos" for n in robot.joint_names)
    np.savetxt(path, np.column_stack([t, q]), delimiter=",", header=header, comments="")
    checked = subprocess.run([sys.executable, "-m", "taplan", "check", str(path), "--no-png"], capture_output=True)
    assert checked.returncode == 1
    done = _cli_run(sim, str(path))
    sent = listener.close()
    assert done.returncode == 1, done.stdout + done.stderr
    last = done.stdout.strip().splitlines()[-1]
    assert last.startswith("taplan run: FAIL: plan: l_joint2: velocity"), last
    assert last.endswith("nothing was sent")
    assert "Traceback" not in done.stderr
    assert len(sent["left"]) == 0 and len(sent["right"]) == 0  # not one command reached the robot's side


def test_run_refuses_a_plan_into_the_torso_without_a_scene(robot, start_sim) -> None:
    sim = start_sim()
    listener = CommandListener(sim.domain)
    goal = robot.home.copy()
    goal[7:] = INTO_TORSO
    assert teleavatar_world().min_distance(goal)[0] < -0.04  # [m] 95 mm deep by the URDF's own capsules
    plan = jerk_limited(np.array([robot.home, goal]), robot.planning_limits, method="path").trajectory
    report = taplan.check(plan, robot.limits)  # the Python check sees it too, with no scene
    assert not report.passed and "torso" in report.clearance.line()
    interface = DdsInterface(sim.domain, config=loopback_config())
    runner = Runner(interface, robot)
    with pytest.raises(CheckFailedError, match="torso / right_gripper_0 in collision.*nothing was sent"):
        runner.execute(plan)
    interface.close()
    sent = listener.close()
    assert len(sent["left"]) == 0 and len(sent["right"]) == 0
    assert "9 robot bodies" in runner.presend.clearance.line() or "robot bodies" in runner.presend.clearance.line()


def test_hostile_streamed_targets_never_leave_the_limits_or_enter_the_torso(robot, start_sim) -> None:
    sim = start_sim()
    listener = CommandListener(sim.domain)
    interface = DdsInterface(sim.domain, config=loopback_config())
    runner = Runner(interface, robot, config=test_ros_run.STEADY)
    start = runner.wait_for_state()
    jump = start.copy()
    jump[1] += 1.5  # a 1.5 rad jump of l_joint2 in one target
    nan = start.copy()
    nan[3] = np.nan
    far = start + 50.0  # far outside every limit
    torso = start.copy()
    torso[7:] = INTO_TORSO
    schedule = [(0.0, jump), (0.4, nan), (0.6, far), (1.2, torso), (2.2, start)]

    def targets(t: float) -> np.ndarray | None:  # each target once, when it is due (as a live feed sends them)
        if schedule and schedule[0][0] <= t:
            return schedule.pop(0)[1]
        return None

    result = runner.stream(targets, 5.0)
    assert result.status == "completed", result.reason
    np.testing.assert_allclose(result.sent[-1], start, atol=1e-6)  # back where it started [rad]
    # a pose target inside the torso through a pose streamer whose IK keeps only the arms apart: the runner's
    # guard stops the stream before any command (or its stop) reaches the torso
    goal = start.copy()
    goal[7:] = INTO_TORSO
    inside = robot.frame_pose(goal, "right_ee")
    streamer = PoseStreamer(robot, runner.period, frames=("right_ee",), timeout=None)
    dive = runner.stream(lambda t: {"right_ee": inside}, 4.0, streamer=streamer)
    interface.close()
    sent = listener.close()
    assert dive.status == "stopped" and "collision" in dive.reason, dive.reason
    n = min(len(sent["left"]), len(sent["right"]))
    assert n > 100, result.reason
    commands = np.hstack([sent["left"][:n], sent["right"][:n]])
    assert np.all(np.isfinite(commands))
    assert np.all(commands >= robot.limits.lower - 1e-9) and np.all(commands <= robot.limits.upper + 1e-9)
    velocity = np.abs(np.diff(commands, axis=0)) * runner.config.rate  # [rad/s] at the command period
    assert np.all(velocity <= robot.limits.velocity * (1 + 1e-6))
    world = teleavatar_world()
    clearance = min(world.min_distance(q)[0] for q in commands)
    assert clearance > 0.0, clearance  # [m] no command put a body into another


class Operator:
    """A second participant: sends ``/api/fsm/enable -1`` and records the FSM and every enable it sees."""

    def __init__(self, domain: int) -> None:
        self.interface = DdsInterface(domain, config=loopback_config())
        self.enables: list[tuple[float, float]] = []
        self.states: list[tuple[float, int]] = []
        self.interface.create_subscription(
            api.FLOAT32, api.Topics.ENABLE, lambda f: self.enables.append((time.monotonic(), f["data"]))
        )
        self.interface.create_subscription(
            INT32, FSM_STATE_TOPIC, lambda f: self.states.append((time.monotonic(), f["data"]))
        )
        self.publisher = self.interface.create_publisher(api.FLOAT32, api.Topics.ENABLE)
        self.disabled_at: float | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._stop.is_set():
            self.interface.spin_once()
            time.sleep(0.001)

    def disable_when_driving(self, after: float) -> None:
        """Send -1 ``after`` [s] once the robot is READY (in a thread)."""

        def wait_then_disable() -> None:
            end = time.monotonic() + 60
            while not any(s == 2 for _, s in self.states) and time.monotonic() < end:
                time.sleep(0.01)
            time.sleep(after)
            self.disabled_at = time.monotonic()
            self.publisher.publish(api.fsm_enable(False).fields)

        threading.Thread(target=wait_then_disable, daemon=True).start()

    def close(self, linger: float = 1.5) -> None:
        time.sleep(linger)  # watch what follows the disable
        self._stop.set()
        self._thread.join()
        self.interface.close()

    def heartbeats_after(self, t: float) -> int:
        return sum(1 for when, value in self.enables if when > t and value > 0)


def test_an_outside_disable_wins_over_a_running_plan(robot, start_sim) -> None:
    sim = start_sim()
    operator = Operator(sim.domain)
    interface = DdsInterface(sim.domain, config=loopback_config())
    runner = Runner(interface, robot, config=test_ros_run.STEADY)
    start = runner.wait_for_state()
    plan = test_ros_run._plan(robot, start, 0.8, legs=3)  # about 3 s
    operator.disable_when_driving(0.8)
    result = runner.execute(plan)
    ended = time.monotonic()
    interface.close()
    operator.close()
    assert operator.disabled_at is not None
    assert result.status == "disabled", result.reason
    assert "disabled by another node" in result.reason
    assert ended - operator.disabled_at < 1.5  # [s]
    assert result.sent_times[-1] < plan.duration  # it did not drive on
    # not one heartbeat after the operator's -1 (one may have been in flight: 20 Hz, sent < 5 ms before)
    assert operator.heartbeats_after(operator.disabled_at + 0.005) == 0
    assert all(s == 0 for when, s in operator.states if when > operator.disabled_at + 0.1)  # stays paused


def test_cli_hold_exits_1_when_another_node_disables(robot, start_sim) -> None:
    sim = start_sim()
    operator = Operator(sim.domain)
    operator.disable_when_driving(0.5)
    done = _cli_run(sim, "--hold", "6")
    ended = time.monotonic()
    operator.close(linger=0.0)
    assert done.returncode == 1, done.stdout + done.stderr
    assert "disabled by another node" in done.stdout
    assert ended - operator.disabled_at < 3.0  # it did not hold on for the full 6 s [s] (the CLI's start is slow)
    assert operator.heartbeats_after(operator.disabled_at + 0.005) == 0


def test_sim_is_as_strict_as_the_robot(robot, start_sim) -> None:
    sim = start_sim("--refuse-out-of-range")
    link = DdsInterface(sim.domain, config=loopback_config())
    states: list[int] = []
    measured: list[np.ndarray] = []
    link.create_subscription(INT32, FSM_STATE_TOPIC, lambda f: states.append(f["data"]))
    link.create_subscription(
        api.JOINT_STATE, api.Topics.joint_states("left"), lambda f: measured.append(np.array(f["position"]))
    )
    enable = link.create_publisher(api.FLOAT32, api.Topics.ENABLE)
    command = link.create_publisher(api.JOINT_STATE, api.Topics.joint_cmd("left"))
    link.spin_for(1.0)
    for _ in range(10):  # a heartbeat of 0.5 is not the guide's 1.0: the robot stays paused
        enable.publish({"data": 0.5})
        link.spin_for(0.05)
    assert states and states[-1] == 0
    enable.publish(api.fsm_enable(True).fields)
    link.spin_for(0.2)
    assert states[-1] == 1  # SLOW_START
    home = robot.home[:7]
    outside = home.copy()
    outside[1] = robot.limits.upper[1] + 0.5  # l_joint2 beyond its limit
    for _ in range(5):
        enable.publish(api.fsm_enable(True).fields)
        command.publish(api.joint_cmd("left", outside).fields)
        link.spin_for(0.05)
    np.testing.assert_allclose(measured[-1], home, atol=1e-9)  # refused: nothing moved
    link.close()
    sim.process.terminate()  # SIGTERM ends it like Ctrl-C
    assert sim.process.wait(timeout=20) == 0
    log = sim.output()
    assert "Traceback" not in log, log
    assert "enable 0.5: the heartbeat is exactly 1.0" in log
    assert "refused /api/left_arm/joint_cmd: l_joint2" in log
    assert "'out_of_range': 5" in log and "'enable_value': 10" in log  # counted in the summary


def test_run_exits_within_a_second_of_the_robot_side_crashing(robot, start_sim, tmp_path: Path) -> None:
    sim = start_sim()
    watcher = Operator(sim.domain)  # only watches /fsm_state
    plan = tmp_path / "plan.json"
    test_ros_run._plan(robot, robot.home, 0.8, legs=3).save(plan)  # about 3 s
    command = [sys.executable, "-m", "taplan", "run", str(plan), "--loopback", "--domain-id", str(sim.domain)]
    run = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    end = time.monotonic() + 60
    while not any(s == 2 for _, s in watcher.states) and time.monotonic() < end:
        time.sleep(0.01)
    time.sleep(0.5)  # driving
    sim.process.kill()
    killed = time.monotonic()
    out, err = run.communicate(timeout=30)
    exited = time.monotonic() - killed
    watcher.close(linger=0.0)
    assert run.returncode == 1, out + err
    # named by the states' age (>= MIN_STALE, 200 ms), not by the tracking error the stall causes later
    assert "taplan run: stopped: no joint states for " in out, out
    age = float(out.split("no joint states for ")[1].split()[0])
    assert 0.2 <= age < 0.6, out  # [s] MIN_STALE (200 ms) plus the scheduling of a CI machine running the suite
    # [s] no writer lingers for acknowledgements from the dead reader, no slow interpreter teardown: 0.8 s expected
    # alone (stall 0.2 s + brake 0.3 s + close 0.3 s); the margin is for the full suite's load on 2 cores
    assert exited < 1.5, exited


def test_malformed_joint_states_are_one_warning_and_a_final_reason(robot, caplog) -> None:
    domain = random.randint(100, 230)
    interface = DdsInterface(domain, config=loopback_config())
    fake_robot = DdsInterface(domain, config=loopback_config())
    runner = Runner(interface, robot, config=RunnerConfig(wait_timeout=1.0))
    publishers = {s: fake_robot.create_publisher(api.JOINT_STATE, api.Topics.joint_states(s)) for s in api.SIDES}
    end = time.monotonic() + 5
    while any(p.matched() == 0 for p in publishers.values()) and time.monotonic() < end:
        time.sleep(0.01)
    bad = {"name": ["l_joint1", "l_joint2", "l_joint3", "l_joint4", "l_joint5", "l_joint6", "l_wrist"]}

    def flood() -> None:  # 100 Hz of a driver whose names are not the guide's
        for _ in range(80):
            for side in api.SIDES:
                publishers[side].publish({**bad, "position": [0.0] * 7})
            time.sleep(0.01)

    thread = threading.Thread(target=flood)
    thread.start()
    with caplog.at_level("WARNING", logger="taplan.ros.runner"), pytest.raises(RunError) as raised:
        runner.wait_for_state()
    thread.join()
    interface.close()
    fake_robot.close()
    message = str(raised.value)
    assert "arrived and were rejected" in message and "l_wrist" in message, message
    assert runner.rejected_states > 50
    warnings = [r for r in caplog.records if "ignoring" in r.getMessage()]
    assert 1 <= len(warnings) <= 2  # one line a second, not one per message


@pytest.mark.parametrize("mode", ["zero", "feedforward", "feedback"])
def test_commanded_velocity_is_a_documented_choice(robot, start_sim, mode: str) -> None:
    sim = start_sim()
    listener = CommandListener(sim.domain)
    interface = DdsInterface(sim.domain, config=loopback_config())
    runner = Runner(interface, robot, config=replace(test_ros_run.STEADY, command_velocity=mode))
    start = runner.wait_for_state()
    plan = test_ros_run._plan(robot, start, 0.3)
    result = runner.execute(plan)
    interface.spin_for(0.3)
    final = runner.measured()[1]
    interface.close()
    listener.close()
    assert result.status == "completed", result.reason
    np.testing.assert_allclose(final, plan.positions[-1], atol=test_ros_run.GOAL_TOL)  # the sim reads positions
    v = np.array(listener.velocities["left"], dtype=float)
    peak = np.abs(plan(np.linspace(0, plan.duration, 2001), 1)[:, :7]).max(axis=0)  # [rad/s]
    if mode == "zero":
        assert np.all(v == 0.0)
    elif mode == "feedforward":  # the plan's velocity, sampled at the commands
        np.testing.assert_allclose(np.abs(v).max(axis=0), peak, rtol=0.02)
    else:  # clip(kp (q_cmd - q_measured), 0.3 v_max): bounded by the guide's caps, and not zero while moving
        caps = 0.3 * np.asarray(api.VELOCITY_LIMIT)
        assert np.all(np.abs(v) <= caps + 1e-9)
        assert np.abs(v).max() > 0.01


def test_bag_directory_opens_in_rosbags_with_the_wire_bytes_and_survives_sigkill(robot, start_sim, tmp_path) -> None:
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    sim = start_sim()
    # what another participant receives is what went on the wire: its bytes must be the recorded ones
    wire: list[bytes] = []
    listener = DdsInterface(sim.domain, config=loopback_config())
    reader = listener.create_subscription(api.JOINT_STATE, api.Topics.joint_cmd("left"), lambda f: None).reader
    plan = tmp_path / "plan.json"
    test_ros_run._plan(robot, robot.home, 0.8, legs=3).save(plan)
    bag = tmp_path / "run"
    command = [sys.executable, "-m", "taplan", "run", str(plan), "--loopback", "--domain-id", str(sim.domain)]
    run = subprocess.Popen([*command, "--bag", str(bag)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    end = time.monotonic() + 90
    while time.monotonic() < end and len(wire) < 120 and run.poll() is None:  # ~1.6 s of commands at 77 Hz
        wire += [sample.serialize() for sample in reader.take(N=256) if hasattr(sample, "position")]
        time.sleep(0.002)
    run.kill()  # SIGKILL while recording: no close, no footer of the file being written
    run.wait(timeout=30)
    listener.close()
    assert len(wire) >= 120, run.stdout.read() + run.stderr.read()

    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["storage_identifier"] == "mcap" and info["relative_file_paths"]
    with Reader(bag) as rosbag:  # rosbag2's own layout: metadata.yaml, storage mcap, cdr, offered QoS
        assert rosbag.duration > 0.5e9  # [ns] everything up to the last finished second
        topics = {c.topic: c for c in rosbag.connections}
        command_topic = topics[api.Topics.joint_cmd("left")]
        assert command_topic.ext.serialization_format == "cdr"
        assert command_topic.ext.offered_qos_profiles  # parsed from the metadata
        recorded = [raw for connection, _, raw in rosbag.messages() if connection.topic == command_topic.topic]
    assert len(wire) - 2 * 77 < len(recorded) <= len(wire)  # at most the last second (and the kill's moment) lost
    assert recorded == wire[: len(recorded)]  # byte for byte, in order

    typestore = get_typestore(Stores.ROS2_HUMBLE)
    with AnyReader([bag], default_typestore=typestore) as anyreader:
        stamps = []
        for connection, log_time, raw in anyreader.messages():
            if connection.topic == api.Topics.joint_cmd("right"):
                message = anyreader.deserialize(raw, connection.msgtype)
                stamps.append((log_time, message.header.stamp.sec * 10**9 + message.header.stamp.nanosec))
    assert stamps
    offsets = np.array([abs(log - header) for log, header in stamps]) * 1e-9  # [s]
    assert offsets.max() < 1e-6  # the log time is the wire time (the header stamp), not a later re-stamp

    checked = subprocess.run([sys.executable, "-m", "taplan", "check", str(bag)], capture_output=True, text=True)
    assert "heartbeat" in checked.stdout and "run:" in checked.stdout, checked.stdout + checked.stderr


def _joint_states_bag(robot, path: Path, step: float, *, with_commands: bool = False) -> None:
    """1.3 s of both arms' joint_states at 100 Hz with encoder-like noise (5e-5 rad): l_joint5 ramps at -0.2 rad/s
    and at t = 1 s its velocity steps by ``-step`` [rad/s] within one sample (inside its position limits)."""
    from taplan.ros.bag import BagWriter

    rng = np.random.default_rng(7)
    t = np.arange(0.0, 1.3, 0.01)
    q = np.repeat(robot.home[None, :], len(t), axis=0)
    q[:, 4] -= 0.2 * t + step * np.maximum(t - 1.0, 0.0)
    noisy = q + rng.normal(0.0, 5e-5, q.shape)
    start = 1_700_000_000 * 10**9
    with BagWriter(path) as writer:
        for k, tk in enumerate(t):
            time_ns = start + int(round(tk * 1e9))
            for side in api.SIDES:
                index = robot.indices(api.ARM_JOINT_NAMES[side])
                names = list(api.ARM_JOINT_NAMES[side])
                fields = {"name": names, "position": noisy[k, index].tolist(), "velocity": [], "effort": []}
                writer.record(api.Topics.joint_states(side), api.JOINT_STATE, fields, time_ns)
                if with_commands:
                    command = api.joint_cmd(side, q[k, index]).fields
                    writer.record(api.Topics.joint_cmd(side), api.JOINT_STATE, command, time_ns)
            if with_commands and k % 5 == 0:
                writer.record(api.Topics.ENABLE, api.FLOAT32, {"data": 1.0}, time_ns)


def test_check_judges_what_the_robot_measured(robot, tmp_path: Path) -> None:
    from taplan.ros.bag import read_run
    from taplan.ros.run_check import check_run

    smooth, stepped, both = tmp_path / "smooth", tmp_path / "stepped", tmp_path / "both"
    _joint_states_bag(robot, smooth, 0.0)
    _joint_states_bag(robot, stepped, 2.5)
    _joint_states_bag(robot, both, 2.5, with_commands=True)
    assert check_run(read_run(smooth), robot.limits).passed  # noise and sampling are not a failure
    report = check_run(read_run(stepped), robot.limits)
    assert not report.passed and report.commanded is None
    failures = report.measured.joint("l_joint5").failures
    assert any("velocity step" in f or "acceleration" in f for f in failures), report.table()
    cli = subprocess.run([sys.executable, "-m", "taplan", "check", str(stepped)], capture_output=True, text=True)
    assert cli.returncode == 1, cli.stdout + cli.stderr  # was: exit 2 "no commanded joint stream"
    assert "run: FAIL" in cli.stdout
    # with (smooth) commands present the step is marked on the measured row, not "ok"
    mixed = check_run(read_run(both), robot.limits)
    assert not mixed.measured.joint("l_joint5").passed, mixed.table()


def test_sim_adjust_mode_as_the_guide_describes(robot, start_sim) -> None:
    sim = start_sim()
    link = DdsInterface(sim.domain, config=loopback_config())
    states: list[tuple[float, int]] = []
    measured: list[tuple[float, np.ndarray]] = []
    link.create_subscription(INT32, FSM_STATE_TOPIC, lambda f: states.append((time.monotonic(), f["data"])))
    link.create_subscription(
        api.JOINT_STATE,
        api.Topics.joint_states("left"),
        lambda f: measured.append((time.monotonic(), np.array(f["position"]))),
    )
    enable = link.create_publisher(api.FLOAT32, api.Topics.ENABLE)
    adjust = link.create_publisher(api.FLOAT32, api.Topics.ADJUST)
    command = link.create_publisher(api.JOINT_STATE, api.Topics.joint_cmd("left"))
    link.spin_for(1.0)
    home = robot.home[:7]
    away = home.copy()
    away[3] -= 0.4  # l_joint4 0.4 rad from home
    for _ in range(40):  # enabled, the arm moves away at the slow-start speed
        enable.publish(api.fsm_enable(True).fields)
        command.publish(api.joint_cmd("left", away).fields)
        link.spin_for(0.05)
    np.testing.assert_allclose(measured[-1][1], away, atol=1e-6)
    enable.publish(api.fsm_enable(False).fields)
    link.spin_for(0.2)
    adjust.publish(api.fsm_adjust(True).fields)  # ADJUST MODE: back to the adjust pose (home), no heartbeat needed
    started = time.monotonic()
    while time.monotonic() < started + 20.0:  # [s] 0.8 s alone; the full suite's load on 2 cores can starve the sim
        command.publish(api.joint_cmd("left", away).fields)  # ignored while the routine owns the arm
        link.spin_for(0.05)
        seen = [s for t, s in states if t > started + 0.1]
        if 3 in seen and seen[-1] == 0 and time.monotonic() > started + 1.5:
            break
    link.spin_for(0.3)  # the joint states published with the pause
    link.close()
    during = [s for t, s in states if t > started + 0.1]
    assert 3 in during  # ADJUST
    assert during[-1] == 0  # it paused on its own once the routine was complete
    # [rad] the routine ends when the arm is within 1e-3 of the pose (taplan sim's completion test); how close the
    # last motion step came depends on when the FSM check fell between them (6.6e-5 rad seen in CI)
    np.testing.assert_allclose(measured[-1][1], home, atol=1e-3)
    arrived = min(t for t, q in measured if t > started and np.abs(q - home).max() < 1e-3)
    assert arrived - started > 0.6  # [s] 0.4 rad at the slow-start speed (0.5 rad/s) takes 0.8 s
    sim.process.terminate()
    sim.process.wait(timeout=20)
    assert "adjust complete" in sim.output()


def test_plan_without_a_scene_checks_the_robots_own_bodies(robot, tmp_path: Path) -> None:
    goal = robot.home.copy()
    goal[7:] = INTO_TORSO
    waypoints = tmp_path / "into_torso.csv"
    np.savetxt(waypoints, np.vstack([robot.home, goal]), delimiter=",", header=",".join(robot.joint_names), comments="")
    out = tmp_path / "plan.json"
    done = subprocess.run(
        [sys.executable, "-m", "taplan", "plan", str(waypoints), "-o", str(out)], capture_output=True, text=True
    )
    assert done.returncode == 1, done.stdout + done.stderr  # was: exit 0, the plan "passed"
    assert "robot bodies (head, shoulders, torso, carriage, column," in done.stdout
    assert "FAIL: torso / right_gripper_0 in collision" in done.stdout
    checked = subprocess.run([sys.executable, "-m", "taplan", "check", str(out), "--no-png"], capture_output=True)
    assert checked.returncode == 1


def test_a_plan_that_does_not_start_at_the_robot_is_refused_before_anything_is_sent(robot, start_sim) -> None:
    sim = start_sim()
    listener = CommandListener(sim.domain)
    interface = DdsInterface(sim.domain, config=loopback_config())
    runner = Runner(interface, robot)
    start = runner.wait_for_state()
    away = start.copy()
    away[2] += 0.3  # [rad] l_joint3, beyond the 0.05 rad start tolerance
    plan = jerk_limited(np.array([away, start]), robot.planning_limits, method="path").trajectory
    with pytest.raises(RunError, match=r"the plan starts 0\.3\d* rad from the measured l_joint3 .*current state"):
        runner.execute(plan)
    interface.close()
    sent = listener.close()
    assert len(sent["left"]) == 0 and len(sent["right"]) == 0


@pytest.mark.parametrize(
    ("config", "period", "expected"),
    [
        (RunnerConfig(), 0.010, 0.2),  # 5 periods = 50 ms, raised to the 200 ms floor
        (RunnerConfig(state_timeout=1.0), 0.010, 0.2),  # the ceiling alone does not lengthen a 100 Hz stall
        (RunnerConfig(state_timeout=1.0), 0.100, 0.5),  # 5 periods of a 10 Hz robot
        (RunnerConfig(state_timeout=1.0, stale_periods=float("inf")), 0.010, 1.0),  # taplan run --state-timeout 1
        (RunnerConfig(state_timeout=0.1, stale_periods=float("inf")), 0.010, 0.1),
    ],
)
def test_the_stall_time_follows_the_measured_period_and_the_config(robot, config, period, expected) -> None:
    fake = FakeRosInterface()
    runner = Runner(fake, robot, config=config, clock=fake.now)
    for _ in range(200):  # both arms, long enough for the smoothed period to settle
        fake.advance(period)
        for side in api.SIDES:
            fake.deliver(api.Topics.joint_states(side), {"name": [], "position": [0.0] * 7})
    assert runner.stale_after() == pytest.approx(expected, abs=1e-6)  # [s]


def test_the_cli_state_timeout_is_the_stall_time() -> None:
    """``taplan run --state-timeout S`` stops after S without states, whatever the robot's rate."""
    from taplan.commands import run as run_command

    parser = argparse.ArgumentParser()
    run_command.add_arguments(parser)
    config = run_command.runner_config(parser.parse_args(["--hold", "1", "--state-timeout", "0.7"]))
    fake = FakeRosInterface()
    runner = Runner(fake, taplan.Robot.teleavatar(), config=config, clock=fake.now)
    for _ in range(200):  # 100 Hz states
        fake.advance(0.01)
        for side in api.SIDES:
            fake.deliver(api.Topics.joint_states(side), {"name": [], "position": [0.0] * 7})
    assert runner.stale_after() == pytest.approx(0.7, abs=1e-9)  # [s]


def test_runner_config_refuses_meaningless_stall_periods() -> None:
    for bad in (0.0, -5.0, float("nan"), True, "5"):
        with pytest.raises(InvalidInputError, match="stale_periods"):
            RunnerConfig(stale_periods=bad)
