"""The end-to-end demo behind ``taplan demo``: plan, replay, check and compare on the bundled TeleAvatar.

Four plans, each jerk-limited under ``robot.planning_limits`` and starting from the home pose:

1. **reach**: both end effectors to a pair of reachable poses (the FK of ``READY_POSE``, hands ahead of the
   chest), solved with :func:`taplan.ik.solve_pose`;
2. **line**: both end effectors 12 cm straight down, together (Cartesian straight lines through IK);
3. **pick**: the right hand goes above an object, descends 10 cm in a straight line, dwells while the gripper
   closes, lifts 10 cm and returns home, while the left arm holds;
4. **scene**: with the bundled table-and-box scene (``models/teleavatar/scenes/table.yaml``), the right hand reaches
   across the box to a pose over the table: :func:`taplan.planning.plan_motion` finds the detour (the straight
   joint-space motion would hit the box), times it jerk-limited and certifies it collision-free;
5. **seen**: the same reach planned in the scene as the wrist depth cameras see it: depth images rendered from the
   scene file at scan poses (noise, missing pixels), fused into 1 cm voxels (:func:`taplan.scene.scan.perceive`),
   and the plan certified against the voxels and checked against the true table and box.

Every plan is replayed through the reference controllers (ros2_control JTC, the industrial simulator of seed 000
as intended, and the robot's joint mode at 100 Hz commands) and checked against the hardware ceilings. On the reach
motion, the approaches of the robot guide's own demos run side by side: linear interpolation sent at 50 Hz (and at
100 Hz) as position targets, and the clipped P-controller (``v = clip(kp·(q_des − q))``) of the joint-mode demos.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from taplan.check import Report, check
from taplan.errors import InfeasibleError
from taplan.ik import solve_pose
from taplan.io import output_path
from taplan.limits import JointLimits
from taplan.planning.cartesian import cartesian_offset
from taplan.reference import IndustrialSimulator, JointModeRobot, JointTrajectoryController, Replay
from taplan.robot import Robot
from taplan.timing import jerk_limited
from taplan.trajectory import Trajectory, Waypoint, concatenate

__all__ = ["DemoResult", "PlanResult", "Comparison", "run_demo", "READY_POSE"]

# A symmetric working pose with both hands ahead of the chest, left arm then right arm [rad]; the reach targets are
# its end-effector poses (IK then finds its own configuration for them).
_READY_RIGHT = np.array([-0.6, -0.8, 0.3, -1.4, 0.0, 0.3, 0.0])
READY_POSE = np.concatenate([0.0 - _READY_RIGHT, _READY_RIGHT])

# The scene plan's goal: the right arm reaching across the box, the hand above its near edge (its right_tcp pose
# is the target) [rad]. (The earlier goal, joint 2 at -1.537 rad, put the upper arm into the shoulders' body.)
SCENE_REACH_RIGHT = np.array([-0.841, -1.177, 1.323, -1.504, -0.348, -0.033, -0.58])
SCENE_FILE = Path(__file__).resolve().parent / "models" / "teleavatar" / "scenes" / "table.yaml"  # TELEAVATAR_SCENES

COMMAND_RATE = 100.0  # [Hz]: taplan streams at the arm's loop rate (the vendor's own zero.py does too)
GUIDE_RATE = 50.0  # [Hz]: the guide's demos publish at 50 Hz


@dataclass
class PlanResult:
    """One plan: its trajectory, how it was made, its replays and their reports."""

    name: str
    description: str
    trajectory: Trajectory
    notes: list[str] = field(default_factory=list)
    replays: dict[str, Replay] = field(default_factory=dict)
    reports: dict[str, Report] = field(default_factory=dict)


@dataclass
class Comparison:
    """One approach to the same motion, replayed through the robot's joint mode."""

    approach: str
    replay: Replay
    report: Report


@dataclass
class DemoResult:
    plans: list[PlanResult]
    comparisons: list[Comparison]
    out_dir: Path
    files: list[Path]


def _pose_targets(robot: Robot, q: np.ndarray) -> dict[str, np.ndarray]:
    return {g.ee_frame: robot.frame_pose(q, g.ee_frame) for g in robot.groups.values()}


def plan_reach(robot: Robot, limits: JointLimits, q_start: np.ndarray) -> PlanResult:
    targets = _pose_targets(robot, READY_POSE)
    ik = solve_pose(robot, targets, q_start, limits=limits, collision=True)
    if not ik.success:
        raise InfeasibleError(f"demo reach targets not reached: {ik.position_error}")
    result = jerk_limited(np.vstack([q_start, ik.q]), limits)
    notes = [
        f"IK: {ik.iterations} iterations, errors "
        + ", ".join(f"{f} {1e3 * e:.2f} mm" for f, e in ik.position_error.items()),
        f"jerk-limited {result.trajectory.duration:.3f} s = {result.duration_ratio:.3f} x TOPP-RA "
        f"({result.topp_duration:.3f} s)",
    ]
    return PlanResult("reach", "both arms to two end-effector poses (IK)", result.trajectory, notes)


def plan_line(robot: Robot, limits: JointLimits, q_start: np.ndarray) -> PlanResult:
    frames = [g.ee_frame for g in robot.groups.values()]
    line = cartesian_offset(robot, q_start, {frame: [0.0, 0.0, -0.12] for frame in frames}, limits=limits)
    notes = [
        f"{len(line.waypoints)} IK samples; deviation from the lines {1e6 * line.max_position_deviation:.2f} µm, "
        f"{np.degrees(line.max_orientation_deviation):.4f} deg; {line.duration:.3f} s"
    ]
    return PlanResult("line", "both hands 12 cm straight down together (Cartesian lines)", line.trajectory, notes)


def plan_pick(robot: Robot, limits: JointLimits, q_start: np.ndarray) -> PlanResult:
    right = robot.group("right")
    T_grasp = robot.frame_pose(READY_POSE, right.ee_frame)
    T_grasp[:3, 3] += [0.05, 0.0, -0.10]  # an object on a table in front of the right hand
    T_above = T_grasp.copy()
    T_above[2, 3] += 0.10
    hold = {robot.group("left").ee_frame: robot.frame_pose(q_start, robot.group("left").ee_frame)}
    ik = solve_pose(robot, {**hold, right.ee_frame: T_above}, q_start, limits=limits, collision=True)
    if not ik.success:
        raise InfeasibleError(f"demo pick: the pre-grasp pose is not reached: {ik.position_error}")
    approach = jerk_limited(np.vstack([q_start, ik.q]), limits).trajectory
    descend = cartesian_offset(robot, approach.positions[-1], {right.ee_frame: [0.0, 0.0, -0.10]}, limits=limits)
    dwell = _dwell(descend.trajectory, 0.5)
    lift = cartesian_offset(robot, descend.trajectory.positions[-1], {right.ee_frame: [0.0, 0.0, 0.10]}, limits=limits)
    back = jerk_limited(np.vstack([lift.trajectory.positions[-1], q_start]), limits).trajectory
    trajectory = concatenate([approach, descend.trajectory, dwell, lift.trajectory, back])
    notes = [
        f"approach {approach.duration:.2f} s, descend {descend.duration:.2f} s "
        f"(line deviation {1e6 * descend.max_position_deviation:.2f} µm), dwell 0.50 s (gripper closes), "
        f"lift {lift.duration:.2f} s ({1e6 * lift.max_position_deviation:.2f} µm), return {back.duration:.2f} s"
    ]
    return PlanResult("pick", "right hand: above, straight down, grasp, straight up, home", trajectory, notes)


def plan_scene(robot: Robot, limits: JointLimits, q_start: np.ndarray) -> PlanResult:
    from taplan.planning import plan_motion
    from taplan.scene import load_scene

    goal = q_start.copy()
    goal[robot.group("right").indices] = SCENE_REACH_RIGHT
    target = {"right_tcp": robot.frame_pose(goal, "right_tcp")}
    plan = plan_motion(robot, q_start, target, load_scene(SCENE_FILE), limits)
    r = plan.report
    notes = [
        f"{r.stage}: {r.waypoints} waypoints, path {r.path_length:.2f} rad, planned in "
        f"{sum(r.stage_times.values()):.2f} s ("
        + ", ".join(f"{k} {v * 1e3:.0f} ms" for k, v in r.stage_times.items())
        + ")",
        f"verified collision-free: clearance >= {r.min_clearance * 1e3:.1f} mm "
        f"({r.min_clearance_pair[0]} / {r.min_clearance_pair[1]})",
    ]
    return PlanResult("scene", "right hand across a box on a table (collision-free planning)", plan.trajectory, notes)


def plan_scene_seen(robot: Robot, limits: JointLimits, q_start: np.ndarray) -> PlanResult:
    from taplan.planning import plan_motion, verify_trajectory
    from taplan.scene import CollisionWorld, Perception, load_scene
    from taplan.scene.camera import PinholeCamera
    from taplan.scene.scan import perceive, scan_configurations

    truth = load_scene(SCENE_FILE)
    camera = PinholeCamera(160, 120, 84.25, 84.25, 80.0, 60.0)  # the wrist camera's field of view, quarter size
    goal = q_start.copy()
    goal[robot.group("right").indices] = SCENE_REACH_RIGHT
    # scan views that look where the hand goes; what they do not see of the workspace blocks the plan
    probe = Perception(robot, unknown="free", resolution=0.01)
    views = scan_configurations(probe, truth, focus=[goal])
    perception = perceive(robot, truth, views, camera=camera, resolution=0.01)
    perception.mark_robot_free(q_start)  # the robot stands there: known free
    perception.update_scene()
    voxels = len(perception.scene.obstacles["perceived"].shape)
    target = {"right_tcp": robot.frame_pose(goal, "right_tcp")}
    # ~3,000 merged voxel boxes answer slower than two boxes: a wider wall-clock budget (about 1 s of CPU time)
    plan = plan_motion(robot, q_start, target, perception.scene, limits, max_time=30.0)
    against_truth = verify_trajectory(CollisionWorld(robot, truth), plan.trajectory)
    r = plan.report
    notes = [
        f"perceived {voxels} voxels of 1 cm from depth images rendered at the wrist cameras' scan poses; "
        f"{r.stage}, planned in {sum(r.stage_times.values()):.2f} s",
        f"certified against the voxels: clearance >= {r.min_clearance * 1e3:.1f} mm; against the true scene: "
        f"{'collision-free' if against_truth.collision_free else 'IN COLLISION'} "
        f"(clearance >= {against_truth.min_clearance * 1e3:.1f} mm)",
    ]
    what = "the scene plan in what the wrist cameras saw (depth images -> voxels)"
    return PlanResult("seen", what, plan.trajectory, notes)


def _on_command_grid(trajectory: Trajectory, period: float) -> Trajectory:
    """Slow a plan down by less than one period so its duration is a whole number of command periods: the last
    command then lands on the controllers' update grid instead of leaving a short final period."""
    periods = np.ceil(trajectory.duration / period - 1e-9)
    return trajectory.stretched(periods * period / trajectory.duration)


def _dwell(before: Trajectory, seconds: float) -> Trajectory:
    q = before.positions[-1]
    zeros = np.zeros_like(q)
    return Trajectory([0.0, seconds], [q, q], [zeros, zeros], [zeros, zeros], joint_names=before.joint_names)


def replay_plan(plan: PlanResult, limits: JointLimits) -> None:
    """Replay a plan through the reference controllers and check each replay against ``limits``."""
    t100 = plan.trajectory.resample(COMMAND_RATE)
    names = plan.trajectory.joint_names
    waypoints = _stamped(t100.waypoints(velocities=True, accelerations=True))
    plan.replays["jtc (quintic)"] = JointTrajectoryController().replay(waypoints, joint_names=names)
    plan.replays["industrial sim (intended)"] = IndustrialSimulator(mode="intended").replay(
        _stamped(t100.waypoints(velocities=True)), joint_names=names
    )
    plan.replays["joint mode @100 Hz"] = JointModeRobot(limits).replay_trajectory(plan.trajectory, COMMAND_RATE)
    plan.reports["plan @1 kHz"] = check(plan.trajectory, limits, name=f"{plan.name}: plan")
    for label, replay in plan.replays.items():
        plan.reports[label] = check(replay, limits, name=f"{plan.name}: {label}")


def _stamped(waypoints: list[Waypoint]) -> list[Waypoint]:
    """Waypoints whose times are whole nanoseconds, as ``Duration(secs, nsecs)`` would carry them: ROS truncates a
    float like 0.07 s (0.0699999...) to 69 999 999 ns, and the simulator then adds a 1 ns step to its grid."""
    return [replace(w, time_from_start=round(w.time_from_start * 1e9) / 1e9 + 1e-10) for w in waypoints]


def compare_with_guide(robot: Robot, plan: PlanResult, limits: JointLimits) -> list[Comparison]:
    """The guide's approaches to the same start, goal and duration, replayed by the robot's joint mode."""
    q0, q1 = plan.trajectory.positions[0], plan.trajectory.positions[-1]
    duration = plan.trajectory.duration
    out = []
    for rate in (GUIDE_RATE, COMMAND_RATE):
        t = np.arange(0.0, duration + 0.5, 1.0 / rate)
        alpha = np.clip(t / duration, 0.0, 1.0)[:, None]
        q_des = q0 + alpha * (q1 - q0)
        replay = JointModeRobot(limits).replay(t, q_des, q0, joint_names=robot.joint_names)
        out.append(Comparison(f"guide: linear @{rate:.0f} Hz, position target", replay, check(replay, limits)))
    t = np.arange(0.0, duration + 0.5, 1.0 / GUIDE_RATE)
    alpha = np.clip(t / duration, 0.0, 1.0)[:, None]
    q_des = q0 + alpha * (q1 - q0)
    replay = JointModeRobot(limits, convention="velocity").replay(t, q_des, q0, joint_names=robot.joint_names)
    out.append(Comparison("guide: linear + P-controller, clip 0.3 vel_limit", replay, check(replay, limits)))
    step = np.repeat(q1[None], t.size, axis=0)
    replay = JointModeRobot(limits, convention="velocity", kp=np.ones(robot.nq), velocity_fraction=0.25 / 44.0).replay(
        t, step, q0, joint_names=robot.joint_names
    )
    out.append(Comparison("guide 3.3: final target + P (kp 1, clip)", replay, check(replay, limits)))
    taplan_replay = plan.replays["joint mode @100 Hz"]
    out.append(Comparison("taplan: jerk-limited @100 Hz", taplan_replay, plan.reports["joint mode @100 Hz"]))
    fifty = JointModeRobot(limits).replay_trajectory(plan.trajectory, GUIDE_RATE)
    out.append(Comparison("taplan: jerk-limited @50 Hz", fifty, check(fifty, limits)))
    return out


def run_demo(
    out_dir: str | Path = "taplan-demo",
    *,
    robot: Robot | None = None,
    progress: Callable[[str], None] | None = None,
    plots: bool = True,
) -> DemoResult:
    """Plan, replay, check and compare; write plots, trajectories and reports into ``out_dir``."""
    say = progress or (lambda message: None)
    robot = robot or Robot.teleavatar()
    planning = robot.planning_limits
    hardware = robot.limits
    out = output_path(out_dir, "out_dir", directory=True)

    say("reach: IK to two end-effector poses, jerk-limited timing")
    reach = plan_reach(robot, planning, robot.home)
    say("line: both hands 12 cm straight down")
    line_plan = plan_line(robot, planning, reach.trajectory.positions[-1])
    say("pick: above, straight down, grasp, straight up, home")
    pick = plan_pick(robot, planning, robot.home)
    say("scene: around a box on a table, certified collision-free")
    scene_plan = plan_scene(robot, planning, robot.home)
    say("seen: the same reach around what the wrist depth cameras see")
    seen_plan = plan_scene_seen(robot, planning, robot.home)
    plans = [reach, line_plan, pick, scene_plan, seen_plan]
    for plan in plans:
        plan.trajectory = _on_command_grid(plan.trajectory, 1.0 / COMMAND_RATE)
    for plan in plans:
        say(f"replay and check: {plan.name}")
        replay_plan(plan, hardware)
    say("the guide's approaches on the reach motion")
    comparisons = compare_with_guide(robot, reach, hardware)
    files = write_outputs(out, robot, plans, comparisons, plots=plots, say=say)
    return DemoResult(plans, comparisons, out, files)


def write_outputs(
    out: Path,
    robot: Robot,
    plans: list[PlanResult],
    comparisons: list[Comparison],
    *,
    plots: bool,
    say: Callable[[str], None],
) -> list[Path]:
    """Trajectories (exact JSON, and CSV sampled at 100 Hz), the report (JSON), the scene plan as a self-contained
    3D page (HTML) and plots (PNG)."""
    import json

    files: list[Path] = []
    for plan in plans:
        files.append(plan.trajectory.save(out / f"{plan.name}.json"))
        files.append(plan.trajectory.resample(COMMAND_RATE).save(out / f"{plan.name}_100hz.csv"))
    payload = {
        "plans": {
            plan.name: {"description": plan.description, "notes": plan.notes}
            | {label: report.to_dict() for label, report in plan.reports.items()}
            for plan in plans
        },
        "guide_comparison": {c.approach: c.report.to_dict() for c in comparisons},
    }
    path = out / "report.json"
    path.write_text(json.dumps(payload, indent=1, default=float))
    files.append(path)
    scene_plan = next((plan for plan in plans if plan.name == "scene"), None)
    if scene_plan is not None:  # the scene plan in 3D: a page that opens in a browser without a server
        from taplan.scene import load_scene
        from taplan.viz import write_html

        files.append(write_html(out / "scene.html", scene_plan.trajectory, scene=load_scene(SCENE_FILE), robot=robot))
    if plots:
        from taplan.plots import save_profiles

        for plan in plans:
            say(f"plots: {plan.name}")
            title = f"{plan.name}: the plan ({plan.description}), hardware limits"
            files.append(save_profiles(plan.trajectory, out / f"{plan.name}_plan.png", robot.limits, title=title))
            replay = plan.replays["jtc (quintic)"]
            title = f"{plan.name} through ros2_control's joint_trajectory_controller (quintic), hardware limits"
            files.append(save_profiles(replay, out / f"{plan.name}_jtc.png", robot.limits, samples=False, title=title))
        files.append(_comparison_plot(out / "guide_vs_taplan.png", robot, comparisons))
    files.append(write_markdown_report(out / "report.md", plans, comparisons, plots=plots))
    return files


def _summary(report: Report) -> list[str]:
    """Peak velocity and acceleration as fractions of their limits, the largest velocity step, mean SPARC, verdict."""
    joints = report.joints
    v = max(j.peak_velocity / j.velocity_limit for j in joints)
    a = max(j.peak_acceleration / j.acceleration_limit for j in joints)
    dv = max(j.max_velocity_step for j in joints)
    moved = [j.sparc for j in joints if np.isfinite(j.sparc)]
    sparc = f"{np.mean(moved):.2f}" if moved else "-"
    verdict = "**PASS**" if report.passed else "**FAIL**: " + "; ".join(report.failures[:3])
    return [f"{v:.2f}", f"{a:.2f}", f"{dv:.4f}", sparc, verdict]


def write_markdown_report(path: Path, plans: list[PlanResult], comparisons: list[Comparison], *, plots: bool) -> Path:
    """The demo's report for a person: per plan its description, notes, the check of the plan and of each
    controller's replay as a table, and its plots; then the guide's approaches against taplan's (``report.json``
    holds every number)."""
    head = "| checked | peak v / limit | peak a / limit | max \\|Δv\\| [rad/s] | SPARC | result |"
    rule = "|---|---:|---:|---:|---:|---|"
    lines = [
        "# taplan demo on the bundled TeleAvatar",
        "",
        "Plans under the planning limits, checked against the hardware ceilings, as planned (1 kHz) and as each "
        "reference controller replays them. Every number is in `report.json`; trajectories are the `<plan>.json` "
        "files (exact) and `<plan>_100hz.csv` (samples at 100 Hz). The scene plan in 3D: [scene.html](scene.html).",
        "",
    ]
    for plan in plans:
        lines += [f"## {plan.name}: {plan.description} ({plan.trajectory.duration:.2f} s)", ""]
        lines += [f"- {note}" for note in plan.notes] + ([""] if plan.notes else [])
        lines += [head, rule]
        lines += ["| " + " | ".join([label, *_summary(report)]) + " |" for label, report in plan.reports.items()]
        lines.append("")
        if plots:
            lines += [f"![{plan.name}: the plan]({plan.name}_plan.png)", ""]
            lines += [f"![{plan.name} through the joint trajectory controller]({plan.name}_jtc.png)", ""]
    lines += ["## The guide's approaches against taplan's (the reach motion, the arm's 100 Hz joint loop)", ""]
    lines += [head.replace("checked", "approach"), rule]
    lines += ["| " + " | ".join([c.approach, *_summary(c.report)]) + " |" for c in comparisons]
    lines += [
        "",
        "|Δv| is the largest velocity change between two 10 ms updates; more than the acceleration ceiling × 10 ms is "
        "a velocity step the arm cannot follow.",
        "",
    ]
    if plots:
        lines += ["![the guide's approaches against taplan's](guide_vs_taplan.png)", ""]
    path.write_text("\n".join(lines))
    return path


def _comparison_plot(path: Path, robot: Robot, comparisons: list[Comparison]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = [c for c in comparisons if "@50 Hz" not in c.approach or c.approach.startswith("guide")]
    taplan_replay = next(c.replay for c in comparisons if c.approach.startswith("taplan"))
    moved = np.abs(taplan_replay.positions[-1] - taplan_replay.initial_positions)
    joint = int(np.argmax(moved / robot.limits.acceleration))  # the joint that needs its acceleration most
    fig, axes = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    for c in shown:  # taplan at 50 Hz has the staircase of any 50 Hz position stream: in the table, not here
        t = np.concatenate([[0.0], c.replay.times])
        v = np.concatenate([[0.0], c.replay.velocities[:, joint]])
        axes[0].step(t, v, where="pre", label=c.approach, linewidth=1.2)
        dv = np.abs(np.diff(v))
        axes[1].step(t[1:], dv, where="pre", linewidth=1.2)
    step_limit = robot.limits.acceleration[joint] / COMMAND_RATE
    axes[1].axhline(step_limit, color="k", linestyle="--", label="acceleration ceiling x 10 ms")
    axes[0].set_ylabel(f"{robot.joint_names[joint]} velocity [rad/s]")
    axes[1].set_ylabel("|Δv| per 10 ms update [rad/s]")
    axes[1].set_xlabel("time [s]")
    axes[0].legend(fontsize=8)
    axes[1].legend(fontsize=8)
    axes[0].set_title("The reach motion as the arm's 100 Hz joint loop executes it")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
