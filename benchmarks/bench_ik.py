"""Differential IK: taplan vs mink and pink on the TeleAvatar (14 DOF), in one process.

1. Tracking: both end effectors follow 5 cm circles; posture cost 1e-2, damping 1e-3, position + velocity limits;
   dt 0.01 and 0.002 s; solvers daqp, quadprog, proxqp. taplan with acceleration limits on and off (collision on).
2. Acceleration step: a 15 cm step of the left end effector at 10 rad/s² (all joints), taplan vs pink's
   AccelerationLimit: peak |q̈|, overshoot, time to 1 mm, against the one-joint bang-bang lower bound.
3. Converge-to-pose: random reachable targets (FK of random configurations within the limits) per arm.

Run: ``python -m benchmarks.bench_ik [--quick] [--repeats N]``.
"""

from __future__ import annotations

import argparse
import time
import warnings
from typing import Any

import numpy as np
import pinocchio as pin

import taplan
from benchmarks import _harness
from taplan.ik import DifferentialIK, solve_pose

FRAMES = ("left_ee", "right_ee")
SOLVERS = ("daqp", "quadprog", "proxqp")
RADIUS = 0.05  # [m]
FREQUENCY = 0.5  # [Hz] of the circles
POSTURE_COST = 1e-2
DAMPING = 1e-3
ROUNDS = 5  # interleaved chunks per configuration in the timing benchmark


def _targets(robot: taplan.Robot, q0: np.ndarray, t: float) -> dict[str, np.ndarray]:
    out = {}
    for f in FRAMES:
        T = robot.frame_pose(q0, f)
        w = 2 * np.pi * FREQUENCY * t
        T[:3, 3] += RADIUS * np.array([0.0, np.cos(w) - 1.0, np.sin(w)])
        out[f] = T
    return out


# ------------------------------------------------------------------------------------------------------- peers
def _pink_model(robot: taplan.Robot, limits: taplan.JointLimits) -> pin.Model:
    model = pin.buildModelFromUrdf(str(robot.urdf_path))
    model.lowerPositionLimit = limits.lower.copy()
    model.upperPositionLimit = limits.upper.copy()
    model.velocityLimit = limits.velocity.copy()
    return model


class PinkIK:
    def __init__(self, robot, limits, dt, solver, acceleration=None):
        import pink
        from pink.limits import AccelerationLimit, ConfigurationLimit, VelocityLimit
        from pink.tasks import FrameTask, PostureTask

        self.model = _pink_model(robot, limits)
        self.data = self.model.createData()
        self.dt, self.solver, self.pink = dt, solver, pink
        self.config = pink.Configuration(self.model, self.data, robot.home)
        self.tasks = {f: FrameTask(f, position_cost=1.0, orientation_cost=1.0) for f in FRAMES}
        posture = PostureTask(cost=POSTURE_COST)
        posture.set_target(robot.home)
        self.all_tasks = [*self.tasks.values(), posture]
        self.limits = [ConfigurationLimit(self.model), VelocityLimit(self.model)]
        self.acc = None
        if acceleration is not None:
            self.acc = AccelerationLimit(self.model, np.asarray(acceleration))
            self.limits.append(self.acc)
        for f, task in self.tasks.items():
            task.set_target(self.config.get_transform_frame_to_world(f))

    def step(self, targets):
        for f, T in targets.items():
            self.tasks[f].set_target(pin.SE3(T[:3, :3], T[:3, 3]))
        v = self.pink.solve_ik(self.config, self.all_tasks, self.dt, self.solver, damping=DAMPING, limits=self.limits)
        if self.acc is not None:
            self.acc.set_last_integration(v, self.dt)
        self.config.integrate_inplace(v, self.dt)
        return v, self.config.q


def _mujoco_model(robot: taplan.Robot, limits: taplan.JointLimits):
    """The same URDF in MuJoCo (static links fused), with sites at the end-effector frames and taplan's limits."""
    import mujoco

    spec = mujoco.MjSpec.from_file(str(robot.urdf_path))
    for f in FRAMES:
        frame = robot.model.frames[robot.frame_id(f)]
        joint = robot.model.names[frame.parentJoint]
        body_name = None
        # the body of the joint's child link: find the body whose joint has this name
        for body in spec.bodies:
            if any(j.name == joint for j in body.joints):
                body_name = body.name
                break
        body = spec.body(body_name)
        placement = frame.placement
        quat = pin.Quaternion(placement.rotation).coeffs()  # x y z w
        body.add_site(name=f, pos=placement.translation, quat=[quat[3], quat[0], quat[1], quat[2]])
    model = spec.compile()
    for i, name in enumerate(robot.joint_names):
        jid = model.joint(name).id
        model.jnt_range[jid] = [limits.lower[i], limits.upper[i]]
        model.jnt_limited[jid] = 1
    index = np.array([model.joint(n).qposadr[0] for n in robot.joint_names])
    return model, index


class MinkIK:
    def __init__(self, robot, limits, dt, solver):
        import mink

        self.mink = mink
        self.model, self.index = _mujoco_model(robot, limits)
        self.config = mink.Configuration(self.model)
        q = np.zeros(self.model.nq)
        q[self.index] = robot.home
        self.config.update(q)
        self.dt, self.solver = dt, solver
        self.tasks = {f: mink.FrameTask(f, "site", position_cost=1.0, orientation_cost=1.0) for f in FRAMES}
        posture = mink.PostureTask(self.model, cost=POSTURE_COST)
        posture.set_target(q)
        self.all_tasks = [*self.tasks.values(), posture]
        self.limits = [
            mink.ConfigurationLimit(self.model),
            mink.VelocityLimit(self.model, {n: limits.velocity[i] for i, n in enumerate(robot.joint_names)}),
        ]

    def step(self, targets):
        for f, T in targets.items():
            self.tasks[f].set_target(self.mink.SE3.from_matrix(T))
        v = self.mink.solve_ik(self.config, self.all_tasks, self.dt, self.solver, damping=DAMPING, limits=self.limits)
        self.config.integrate_inplace(v, self.dt)
        return v[self.index], self.config.q[self.index]


# ------------------------------------------------------------------------------------------------ 1. tracking
def bench_tracking(robot, repeats: int, warmup: int) -> list[dict[str, Any]]:
    limits = robot.planning_limits
    rows = []
    for dt in (0.01, 0.002):
        for solver in SOLVERS:
            makers = {
                "taplan (acc on)": lambda dt=dt, solver=solver: DifferentialIK(
                    robot, dt, solver=solver, acceleration_limit=True
                ),
                "taplan (acc off)": lambda dt=dt, solver=solver: DifferentialIK(
                    robot, dt, solver=solver, acceleration_limit=False
                ),
                "taplan (acc on, numpy)": lambda dt=dt, solver=solver: DifferentialIK(
                    robot, dt, solver=solver, acceleration_limit=True, native=False
                ),
                "mink": lambda dt=dt, solver=solver: MinkIK(robot, limits, dt, solver),
                "pink": lambda dt=dt, solver=solver: PinkIK(robot, limits, dt, solver),
            }
            # the IKs take turns in chunks of steps (each continues its own trajectory), so that a noisy spell on
            # the shared machine hits every IK alike instead of whichever ran during it
            n = warmup + repeats
            targets = [_targets(robot, robot.home, k * dt) for k in range(n)]
            iks = {name: make() for name, make in makers.items()}
            samples = {name: [] for name in iks}
            errors = {name: [] for name in iks}
            for chunk in np.array_split(np.arange(n), ROUNDS):
                for name, ik in iks.items():
                    for k in chunk.tolist():
                        t0 = time.perf_counter_ns()
                        out = ik.step(targets[k])
                        t1 = time.perf_counter_ns()
                        if k >= warmup:
                            samples[name].append((t1 - t0) / 1e3)
                            q = out.q if hasattr(out, "q") else out[1]
                            errors[name].append(
                                max(
                                    np.linalg.norm(robot.frame_pose(q, f)[:3, 3] - targets[k][f][:3, 3]) for f in FRAMES
                                )
                            )
            for name in iks:
                stats = _harness.summarize(np.asarray(samples[name]))
                errors_arr = np.asarray(errors[name])
                rows.append(
                    {
                        "dt": dt,
                        "solver": solver,
                        "ik": name,
                        **stats,
                        "max_error_m": float(errors_arr.max()),
                        "rms_error_m": float(np.sqrt(np.mean(errors_arr**2))),
                        "native": bool(getattr(getattr(iks[name], "builder", None), "native", False)),
                    }
                )
    return rows


# ------------------------------------------------------------------------------------------- 2. acceleration step
def bench_acceleration_step(robot, dt: float = 0.002, duration: float = 3.0) -> list[dict[str, Any]]:
    a = 10.0  # [rad/s²]
    limits = robot.planning_limits.replace(acceleration=np.full(robot.nq, a))
    q0 = robot.home
    start = robot.frame_pose(q0, "left_ee")
    goal = start.copy()
    goal[:3, 3] += [0.0, 0.0, 0.15]
    direction = np.array([0.0, 0.0, 1.0])
    final = solve_pose(robot, {"left_ee": goal, "right_ee": robot.frame_pose(q0, "right_ee")}, q0)
    dq = np.abs(final.q - q0)
    lower_bound = float(np.max(2.0 * np.sqrt(dq / a)))  # the most-moving joint, bang-bang, no velocity limit
    results = []
    runners = {
        "taplan (proxqp)": DifferentialIK(robot, dt, limits, solver="proxqp", collision=False),
        "pink AccelerationLimit (proxqp)": PinkIK(robot, limits, dt, "proxqp", acceleration=limits.acceleration),
    }
    for name, ik in runners.items():
        v_prev = np.zeros(robot.nq)
        peak, overshoot, t_reach = 0.0, -np.inf, np.nan
        times = []
        steps = int(duration / dt)
        for k in range(steps):
            t0 = time.perf_counter_ns()
            try:
                out = ik.step({"left_ee": goal})
            except Exception as exc:  # peers may fail; recorded
                results.append({"ik": name, "error": repr(exc)})
                break
            times.append((time.perf_counter_ns() - t0) / 1e3)
            v, q = (out.velocity, out.q) if hasattr(out, "velocity") else out
            peak = max(peak, float(np.max(np.abs(v - v_prev)) / dt))
            v_prev = np.array(v)
            p = robot.frame_pose(q, "left_ee")[:3, 3]
            overshoot = max(overshoot, float((p - start[:3, 3]) @ direction) - 0.15)
            err = float(np.linalg.norm(p - goal[:3, 3]))
            if err <= 1e-3 and np.isnan(t_reach):
                t_reach = (k + 1) * dt
            if err > 1e-3:
                t_reach = np.nan
        else:
            results.append(
                {
                    "ik": name,
                    "peak_acc": peak,
                    "peak_acc_over_limit": peak / a - 1.0,
                    "overshoot_mm": 1e3 * max(overshoot, 0.0),
                    "time_to_1mm_s": t_reach,
                    "lower_bound_s": lower_bound,
                    "ratio": t_reach / lower_bound,
                    "median_step_us": float(np.median(times)),
                }
            )
    return results


# --------------------------------------------------------------------------------------------- 3. converge-to-pose
def _peer_converge(step, pose_error, max_iterations=200):
    for it in range(1, max_iterations + 1):
        step()
        p, r = pose_error()
        if p <= 1e-3 and r <= 1e-2:
            return True, it
    return False, max_iterations


def bench_converge(robot, count: int) -> list[dict[str, Any]]:
    import mink
    import pink
    from pink.limits import ConfigurationLimit
    from pink.tasks import FrameTask, PostureTask

    limits = robot.planning_limits
    rng = np.random.default_rng(2026)
    names = ("taplan", "taplan (first order)", "mink", "pink")
    stats = {name: {"success": 0, "iterations": []} for name in names}
    pmodel = _pink_model(robot, limits)
    mmodel, index = _mujoco_model(robot, limits)
    for k in range(count * 2):
        frame = FRAMES[k % 2]
        goal = robot.frame_pose(rng.uniform(limits.lower, limits.upper), frame)
        res = solve_pose(robot, {frame: goal}, robot.home)
        stats["taplan"]["success"] += res.success
        stats["taplan"]["iterations"].append(res.iterations)
        res = solve_pose(robot, {frame: goal}, robot.home, second_order=False)
        stats["taplan (first order)"]["success"] += res.success
        stats["taplan (first order)"]["iterations"].append(res.iterations)
        # pink
        config = pink.Configuration(pmodel, pmodel.createData(), robot.home)
        task = FrameTask(frame, position_cost=1.0, orientation_cost=1.0)
        task.set_target(pin.SE3(goal[:3, :3], goal[:3, 3]))
        posture = PostureTask(cost=1e-3)
        posture.set_target(robot.home)
        plim = [ConfigurationLimit(pmodel)]

        def pink_step(config=config, task=task, posture=posture, plim=plim):
            v = pink.solve_ik(config, [task, posture], 1.0, "daqp", damping=1e-6, limits=plim)
            config.integrate_inplace(v, 1.0)

        def pink_err(config=config, frame=frame, goal=goal):
            T = config.get_transform_frame_to_world(frame)
            return np.linalg.norm(T.translation - goal[:3, 3]), np.linalg.norm(pin.log3(T.rotation @ goal[:3, :3].T))

        ok, it = _peer_converge(pink_step, pink_err)
        stats["pink"]["success"] += ok
        stats["pink"]["iterations"].append(it)
        # mink
        mconfig = mink.Configuration(mmodel)
        q = np.zeros(mmodel.nq)
        q[index] = robot.home
        mconfig.update(q)
        mtask = mink.FrameTask(frame, "site", position_cost=1.0, orientation_cost=1.0)
        mtask.set_target(mink.SE3.from_matrix(goal))
        mposture = mink.PostureTask(mmodel, cost=1e-3)
        mposture.set_target(q)
        mlim = [mink.ConfigurationLimit(mmodel)]

        def mink_step(mconfig=mconfig, mtask=mtask, mposture=mposture, mlim=mlim):
            v = mink.solve_ik(mconfig, [mtask, mposture], 1.0, "daqp", damping=1e-6, limits=mlim)
            mconfig.integrate_inplace(v, 1.0)

        def mink_err(mconfig=mconfig, frame=frame, goal=goal):
            T = mconfig.get_transform_frame_to_world(frame, "site").as_matrix()
            return np.linalg.norm(T[:3, 3] - goal[:3, 3]), np.linalg.norm(pin.log3(T[:3, :3] @ goal[:3, :3].T))

        ok, it = _peer_converge(mink_step, mink_err)
        stats["mink"]["success"] += ok
        stats["mink"]["iterations"].append(it)
    return [
        {
            "ik": name,
            "targets": 2 * count,
            "success_rate": s["success"] / (2 * count),
            "median_iterations": float(np.median(s["iterations"])),
        }
        for name, s in stats.items()
    ]


# ------------------------------------------------------------------------------------------------------ 4. sweep
SWEEP_VEL_TOL = 1e-9  # [rad/s]
SWEEP_ACC_REL_TOL = 1e-9  # relative to a dt
SWEEP_DIST_TOL = 2e-4  # [m], one step's linearisation error allowed below the margin
SWEEP_MARGIN = 0.02  # [m], DifferentialIK's default collision margin


def bench_sweep(robot, count: int, seed: int = 2027) -> list[dict[str, Any]]:
    """Random states (30 % up to 10 % of the range outside the limits, half moving) and targets, 3 steps each."""
    from taplan.ik import Kinematics
    from taplan.ik.limits import capsule_pair_distance

    lim = robot.planning_limits
    pairs = robot.capsule_pairs("left", "right")
    kin = Kinematics(robot.model)
    span = lim.upper - lim.lower
    rows = []
    for dt in (0.01, 0.002):
        rng = np.random.default_rng(seed)
        ik = DifferentialIK(robot, dt, collision_margin=SWEEP_MARGIN)
        counts = {"exceptions": 0, "nan": 0, "velocity_violations": 0, "acceleration_violations": 0}
        worst_margin = np.inf
        outside = 0
        errors: list[str] = []
        t0 = time.perf_counter()
        for _ in range(count // 2):
            out_frac = 0.1 if rng.random() < 0.3 else 0.0
            q = rng.uniform(lim.lower - out_frac * span, lim.upper + out_frac * span)
            outside += not lim.within(q)
            moving = rng.random() < 0.5
            v0 = rng.uniform(-lim.velocity, lim.velocity) * rng.random() if moving else np.zeros(robot.nq)
            targets = {f: robot.frame_pose(rng.uniform(lim.lower, lim.upper), f) for f in FRAMES if rng.random() < 0.8}
            kin.update(q)
            d0 = min(capsule_pair_distance(kin, a, b)[0] for a, b in pairs)
            try:
                ik.reset(q, v0)
                v_prev = v0
                for _ in range(3):
                    out = ik.step(targets)
                    if not (np.all(np.isfinite(out.velocity)) and np.all(np.isfinite(out.q))):
                        counts["nan"] += 1
                    counts["velocity_violations"] += int(np.any(np.abs(out.velocity) > lim.velocity + SWEEP_VEL_TOL))
                    counts["acceleration_violations"] += int(
                        np.any(np.abs(out.velocity - v_prev) > lim.acceleration * dt * (1 + SWEEP_ACC_REL_TOL))
                    )
                    v_prev = out.velocity
                    if d0 >= SWEEP_MARGIN and not moving:
                        kin.update(out.q)
                        d = min(capsule_pair_distance(kin, a, b)[0] for a, b in pairs)
                        worst_margin = min(worst_margin, d - SWEEP_MARGIN)
            except Exception as exc:  # counted, never expected
                counts["exceptions"] += 1
                errors.append(repr(exc)[:300])
        rows.append(
            {
                "dt": dt,
                "states": count // 2,
                "steps": 3 * (count // 2),
                "outside_limits": outside,
                **counts,
                "min_distance_minus_margin_m": float(worst_margin),
                "seconds": time.perf_counter() - t0,
                "errors": errors[:5],
            }
        )
    return rows


# ----------------------------------------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small run (< 60 s)")
    parser.add_argument("--repeats", type=int, default=None, help="timed steps per configuration")
    parser.add_argument("--no-save", action="store_true")
    args = parser.parse_args(argv)
    repeats = args.repeats or (150 if args.quick else 1000)
    warmup = 30 if args.quick else 100
    warnings.filterwarnings("ignore")
    robot = taplan.Robot.teleavatar()
    tracking = bench_tracking(robot, repeats, warmup)
    step = bench_acceleration_step(robot, duration=2.0 if args.quick else 3.0)
    converge = bench_converge(robot, 20 if args.quick else 500)
    sweep = bench_sweep(robot, 1000 if args.quick else 10000)
    results = {
        "tracking": tracking,
        "acceleration_step": step,
        "converge": converge,
        "sweep": sweep,
        "quick": args.quick,
    }
    md = _markdown(tracking, step, converge, sweep)
    if not args.no_save:
        _harness.save("ik", results, md)
    print(md)
    return results


def _markdown(tracking, step, converge, sweep) -> str:
    lines = ["## Differential IK: taplan vs mink and pink (TeleAvatar, 14 DOF)", ""]
    lines.append(
        f"Both end effectors track {RADIUS * 100:.0f} cm circles at {FREQUENCY} Hz; posture cost {POSTURE_COST}, "
        f"damping {DAMPING}; position + velocity limits (planning limits). taplan also has collision avoidance on; "
        "'acc on' adds acceleration limits with braking (toward the targets, relative to their motion estimated by "
        "finite differences). taplan's default builds each step's QP with a kernel generated by CasADi and compiled "
        "once by the system's C compiler (cached); 'numpy' is the same builder without it. Step time includes "
        "setting targets, building, solving and integrating; the IKs "
        "of a (dt, solver) group take turns in 5 chunks of steps (same process), so machine noise hits them alike. "
        "Tracking error: "
        "hand position after the step vs the target given to it, worst hand, over the timed steps (after the warm-up)."
    )
    lines.append("")
    header = ["dt [s]", "solver", "IK", "median [µs]", "p95 [µs]", "RMS tracking error [mm]", "max [mm]"]
    rows = [
        [
            r["dt"],
            r["solver"],
            r["ik"] + (" [native]" if r.get("native") else ""),
            r["median_us"],
            r["p95_us"],
            1e3 * r["rms_error_m"],
            1e3 * r["max_error_m"],
        ]
        for r in tracking
    ]
    lines.append(_harness.markdown_table(header, rows))
    verdicts = []
    for dt in (0.01, 0.002):
        sub = [r for r in tracking if r["dt"] == dt]
        peer = min(r["median_us"] for r in sub if r["ik"] in ("mink", "pink"))
        ours = min(r["median_us"] for r in sub if r["ik"] == "taplan (acc on)")
        verdicts.append(
            f"dt {dt}: taplan (acc on) best {ours:.0f} µs vs fastest peer {peer:.0f} µs = {ours / peer:.2f}x"
        )
    goal_met = all(float(v.split("= ")[1][:-1]) <= 1 / 3 for v in verdicts)
    lines += [
        "",
        "Goal (taplan with acceleration limits <= 1/3 of the fastest peer): "
        + ("met" if goal_met else "NOT met")
        + "; "
        + "; ".join(verdicts),
        "",
    ]
    lines.append("### Acceleration step (15 cm, 10 rad/s², dt 0.002 s)")
    lines.append("")
    header = ["IK", "peak abs(q̈) [rad/s²]", "overshoot [mm]", "time to 1 mm [s]", "bang-bang bound [s]", "ratio"]
    rows = [
        [
            r["ik"],
            r.get("peak_acc", "-"),
            r.get("overshoot_mm", "-"),
            r.get("time_to_1mm_s", "-"),
            r.get("lower_bound_s", "-"),
            r.get("ratio", r.get("error", "-")),
        ]
        for r in step
    ]
    lines.append(_harness.markdown_table(header, rows))
    ours = next((r for r in step if r["ik"].startswith("taplan") and "peak_acc" in r), None)
    if ours:
        ok = ours["peak_acc_over_limit"] <= 1e-6 and ours["overshoot_mm"] <= 1.0 and ours["ratio"] <= 1.3
        lines += [
            "",
            "Goal (peak <= limit, overshoot <= 1 mm, time <= 1.3x bound): " + ("met" if ok else "NOT met"),
            "",
        ]
    lines.append("### Converge-to-pose (random reachable targets, 1 mm / 0.01 rad)")
    lines.append("")
    lines.append(
        "One FK target per case (alternating hands, from home). An iteration is one kinematics evaluation and one "
        "QP: for mink and pink one `solve_ik` + integration; for taplan one evaluation of placements, Jacobians and "
        "(by default) the second-order term J̇·v of the Gauss-Newton step from the same evaluation (geodesic-"
        "acceleration Levenberg-Marquardt), then at most one QP. 'first order' turns that term off."
    )
    lines.append("")
    rows = [[r["ik"], r["targets"], r["success_rate"], r["median_iterations"]] for r in converge]
    lines.append(_harness.markdown_table(["IK", "targets", "success", "median iterations"], rows))
    t = next(r for r in converge if r["ik"] == "taplan")
    peers = [r for r in converge if not r["ik"].startswith("taplan")]
    ok = t["success_rate"] >= 0.995 and all(t["median_iterations"] < p["median_iterations"] for p in peers)
    lines += [
        "",
        "Goal (>= 99.5 % success, fewer median iterations than mink and pink): " + ("met" if ok else "NOT met"),
        "",
    ]
    lines.append("### Seeded sweep (random states and targets, 3 steps each)")
    lines.append("")
    lines.append(
        "States: 30 % drawn up to 10 % of the range outside the position limits, half with a random previous velocity "
        f"within the limits; random targets for each hand (80 %). Distance checked for states starting at rest at "
        f"least {SWEEP_MARGIN * 1e3:.0f} mm apart (tolerance {SWEEP_DIST_TOL * 1e3:.1f} mm of linearisation error)."
    )
    lines.append("")
    header = ["dt [s]", "states", "steps", "outside limits", "exceptions", "NaN", "velocity viol.", "accel. viol."]
    header.append("min distance - margin [mm]")
    rows = [
        [
            r["dt"],
            r["states"],
            r["steps"],
            r["outside_limits"],
            r["exceptions"],
            r["nan"],
            r["velocity_violations"],
            r["acceleration_violations"],
            1e3 * r["min_distance_minus_margin_m"],
        ]
        for r in sweep
    ]
    lines.append(_harness.markdown_table(header, rows))
    total = sum(r["states"] for r in sweep)
    ok = all(
        r["exceptions"] == r["nan"] == r["velocity_violations"] == r["acceleration_violations"] == 0
        and r["min_distance_minus_margin_m"] >= -SWEEP_DIST_TOL
        for r in sweep
    )
    lines += [
        "",
        "Goal (>= 10,000 states: no exceptions, NaN or limit violations, margin kept): "
        + ("met" if ok and total >= 10000 else "NOT met")
        + f" ({total} states)",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
