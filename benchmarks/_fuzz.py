"""Generated inputs for every file and flag the ``taplan`` command line reads, and the judge of its answers.

Shared by ``tests/test_fuzz_*.py`` (hypothesis draws the :class:`Spec`) and ``benchmarks/bench_fuzz.py`` (a seeded
numpy generator draws it, 10,000+ times). A surface turns a spec into a :class:`Case`: the files it wrote, the
command line, and what the answer must be. :func:`judge` names what is wrong with an answer:

* ``traceback``: a Python traceback or an internal error (exit 3) anywhere;
* ``exit code``: an exit code other than 0 (pass), 1 (a check failed), 2 (bad input or usage);
* ``error line``: exit 2 without exactly one line ``taplan CMD: error: ...`` on stderr;
* ``false pass``: exit 0 for a file that violates a limit (the case's ``violates``);
* ``false fail``: an unchanged valid input that does not pass;
* ``bad output``: ``taplan plan`` wrote a trajectory that ``taplan check`` does not pass.

The violation oracle (:func:`exceeds`) is independent of :mod:`taplan.check`: it samples the trajectory at 20 kHz
and at its knots, so what it reports is a true excess (a lower bound of it), and any excess beyond the check's
stated tolerance must fail.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

SURFACES = ("trajectory_json", "trajectory_csv", "trajectory_npz", "waypoint_csv", "scene", "urdf", "bag", "flags")
SPECIAL_FLOATS = (0.0, -0.0, 1.0, -1.0, 1e-300, 1e308, -1e308, math.inf, -math.inf, math.nan, 0.5, 2.5, 1e9, -3.0)
SPECIAL_TEXT = ("", " ", "abc", "nan", "inf", "-inf", "1e999", "0x10", "null", "true", "\u00e9\u00e8", "l_joint1")
SPECIAL_TEXT += ("\x00",)
_ORACLE_RATE = 20_000.0  # [Hz]
_EXCESS = 1e-7  # relative and absolute margin above which the oracle calls an input a violation


@dataclass(frozen=True)
class Spec:
    """What to generate: a kind (index into the surface's kinds), two integers, a float, a text, a byte string."""

    kind: int
    a: int
    b: int
    x: float
    s: str
    blob: bytes = b""


@dataclass
class Case:
    surface: str
    kind: str
    argv: list[str]
    violates: bool = False  # the input breaks a limit: exit 0 is a false pass
    valid: bool = False  # the input is unchanged and valid: it must pass (exit 0)
    check_output: Path | None = None  # plan's output, to be checked after an exit 0
    check_flags: tuple[str, ...] = ()  # with these flags (TOPP-RA does not bound jerk: --no-jerk)


@dataclass
class Answer:
    code: int
    out: str
    err: str


@dataclass(repr=False)
class Base:
    """The valid inputs every mutation starts from (built once per process)."""

    robot: Any
    plan: Any  # a small quintic trajectory, within the hardware limits
    long_plan: Any  # the jerk-limited plan it was sampled from
    waypoints: np.ndarray
    urdf_text: str
    scene_text: str
    dir: Path
    extra: dict[str, Any] = field(default_factory=dict)


def make_base(directory: Path) -> Base:
    import taplan
    from taplan.timing import jerk_limited

    robot = taplan.Robot.teleavatar()
    q0 = robot.home
    waypoints = np.array([q0, q0 + 0.2, q0 + np.r_[[0.3, 0.1, -0.2, 0.2, 0.0, 0.1, 0.0] * 2]])
    long_plan = jerk_limited(waypoints, robot.planning_limits).trajectory
    plan = long_plan.resample(10.0)
    urdf = Path(taplan.__file__).parent / "models" / "teleavatar" / "teleavatar.urdf"
    scene = Path(__file__).resolve().parents[1] / "models" / "teleavatar" / "scenes" / "table.yaml"
    directory.mkdir(parents=True, exist_ok=True)
    return Base(robot, plan, long_plan, waypoints, urdf.read_text(), scene.read_text(), directory)


# ------------------------------------------------------------------------------------------------ the oracle
def exceeds(trajectory: Any, limits: Any) -> bool:
    """Whether ``trajectory`` breaks a position, velocity or acceleration limit by more than the margin."""
    lim = limits.subset(trajectory.joint_names)
    t = np.union1d(trajectory.sample_times(_ORACLE_RATE), trajectory.times)
    q = trajectory(t, 0)
    if np.any(q > lim.upper + 1e-9 + _EXCESS) or np.any(q < lim.lower - 1e-9 - _EXCESS):
        return True
    for order, bound in ((1, lim.velocity), (2, lim.acceleration)):
        if np.any(np.abs(trajectory(t, order)) > bound * (1 + _EXCESS) + _EXCESS):
            return True
    return False


# ----------------------------------------------------------------------------------------------- running
def run_inprocess(argv: list[str]) -> Answer:
    """``taplan.cli.main(argv)`` with stdout and stderr captured; an escaping exception is a traceback."""
    import traceback

    from taplan.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse (-h, usage errors)
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
        except BaseException:  # noqa: BLE001 - what a user would see as a traceback
            err.write(traceback.format_exc())
            code = 3
    return Answer(int(code), out.getvalue(), err.getvalue())


def run_subprocess(argv: list[str], timeout: float = 120.0) -> Answer:
    """``python -m taplan argv`` as a user runs it (stderr includes whatever C++ libraries print)."""
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    env.pop("TAPLAN_DEBUG", None)
    done = subprocess.run(
        [sys.executable, "-m", "taplan", *argv], capture_output=True, text=True, timeout=timeout, env=env
    )
    return Answer(done.returncode, done.stdout, done.stderr)


def judge(case: Case, answer: Answer) -> list[str]:
    """The problems of ``answer`` to ``case`` (empty: a correct answer)."""
    problems = []
    text = answer.out + answer.err
    if "Traceback (most recent call last)" in text or answer.code == 3 or "internal error" in answer.err:
        problems.append("traceback")
    elif answer.code not in (0, 1, 2):
        problems.append("exit code")
    if answer.code == 2:
        lines = answer.err.strip().splitlines()
        command = case.argv[0] if case.argv and not case.argv[0].startswith("-") else ""
        prefix = f"taplan {command}: error: " if command in _COMMANDS else "taplan"
        if len(lines) != 1 or not lines[0].startswith(prefix):
            problems.append("error line")
    if case.violates and answer.code == 0:
        problems.append("false pass")
    if case.valid and answer.code != 0:
        problems.append("false fail")
    return problems


def judge_output(case: Case) -> list[str]:
    """After ``taplan plan`` exited 0: its trajectory passes ``taplan check`` (hardware limits)."""
    if case.check_output is None or not case.check_output.is_file():
        return []
    answer = run_inprocess(["check", str(case.check_output), "--no-png", *case.check_flags])
    return [] if answer.code == 0 else ["bad output"]


_COMMANDS = ("info", "demo", "plan", "check", "replay", "run", "sim", "bench", "view")


# ------------------------------------------------------------------------------------------- helpers
def _pick(seq: Any, i: int) -> Any:
    return seq[i % len(seq)]


def _fraction(x: float) -> float:
    """A number in [0, 1) from any float (NaN and infinities give 0.5)."""
    return abs(x) % 1.0 if math.isfinite(x) else 0.5


def _special(spec: Spec) -> float:
    return spec.x if spec.b % 3 == 0 else _pick(SPECIAL_FLOATS, spec.b)


def _limits(base: Base, name: str) -> Any:
    return base.robot.limits if name == "hardware" else base.robot.planning_limits


def _write(path: Path, content: str | bytes) -> Path:
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8", errors="surrogatepass")
    return path


def _fields(trajectory: Any) -> dict[str, Any]:
    """The contract's fields of a trajectory (numpy arrays), as the writer stores them."""
    return {k: (np.asarray(v) if k != "joint_names" else list(v)) for k, v in trajectory.to_dict().items()}


def _json_text(fields: dict[str, Any]) -> str:
    def plain(v: Any) -> Any:
        return v.tolist() if isinstance(v, np.ndarray) else v

    return json.dumps({k: plain(v) for k, v in fields.items()})


def _npz_bytes(fields: dict[str, Any]) -> bytes:
    buffer = io.BytesIO()
    arrays = {}
    for k, v in fields.items():
        try:
            arrays[k] = np.asarray(v)
        except ValueError:  # ragged: only as an object array (the reader must refuse pickles)
            arrays[k] = np.asarray(v, dtype=object)
    np.savez(buffer, **arrays)
    return buffer.getvalue()


# ------------------------------------------------------------------------------- semantic mutations
def _shift_past_limit(base: Base, traj: Any, spec: Spec, limits: Any) -> Any:
    """One joint moved as a whole (coefficients and samples alike) past its position limit by 1e-7..2 rad."""
    from taplan.trajectory import Trajectory

    j = spec.a % traj.n_joints
    lim = limits.subset(traj.joint_names)
    over = 10 ** (-7 + 7.3 * _fraction(spec.x))  # [rad]: 1e-7..2
    q = traj(np.union1d(traj.sample_times(1000.0), traj.times), 0)[:, j]
    delta = (lim.upper[j] - q.max() + over) if spec.b % 2 else (lim.lower[j] - q.min() - over)
    c = traj.coefficients.copy()
    c[:, 0, j] += delta
    return Trajectory.from_polynomials(traj.times, c, traj.joint_names)


def _stretch(traj: Any, spec: Spec) -> Any:
    factor = 0.05 + 1.5 * _fraction(spec.x)  # < 1: faster
    return traj.stretched(factor)


def _bump(traj: Any, spec: Spec) -> Any:
    """A smooth bump (amplitude up to 3 rad) on one joint, as quintic samples at 50 Hz."""
    from taplan.trajectory import Trajectory

    j = spec.a % traj.n_joints
    amp = _fraction(spec.x) * 3.0 * (1 if spec.b % 2 else -1)
    t = traj.sample_times(50.0)
    q, v, a = (traj(t, k).copy() for k in range(3))
    tc, w = traj.times[0] + traj.duration * ((spec.b % 7) + 1) / 8, traj.duration / 6
    g = np.exp(-(((t - tc) / w) ** 2))
    q[:, j] += amp * g
    v[:, j] += amp * g * (-2 * (t - tc) / w**2)
    a[:, j] += amp * g * ((2 * (t - tc) / w**2) ** 2 - 2 / w**2)
    return Trajectory(t, q, v, a, traj.joint_names)


def _coefficient(traj: Any, spec: Spec) -> Any:
    from taplan.trajectory import Trajectory

    c = traj.coefficients.copy()
    k, j = spec.a % c.shape[0], spec.b % c.shape[2]
    i = (spec.a // 7) % c.shape[1]
    c[k, i, j] += float(np.clip(spec.x, -1e3, 1e3)) if math.isfinite(spec.x) else 1.0
    return Trajectory.from_polynomials(traj.times, c, traj.joint_names, continuity_tol=1e9, continuous_velocity=False)


SEMANTIC = ("valid", "shift", "stretch", "bump", "coefficient", "raw_positions", "raw_positions_linear")
STRUCTURAL = (
    "drop_field",
    "field_type",
    "cell",
    "rows",
    "columns",
    "names_duplicate",
    "names_unknown",
    "names_type",
    "times_swap",
    "times_repeat",
    "times_scale",
    "extra_field",
    "degree",
    "top_level",
    "truncate",
    "garbage",
    "empty",
)
CSV_TEXT = ("csv_cell", "csv_header", "csv_drop_line", "csv_dup_line", "csv_bom", "csv_separator", "csv_blank_lines")
CSV_TEXT += ("csv_header_only", "csv_extra_column", "csv_swap_columns", "csv_ragged")
NPZ_BYTES = ("npz_object", "npz_corrupt", "npz_not_zip")
TRAJECTORY_KINDS = {
    "json": SEMANTIC + STRUCTURAL,
    "csv": SEMANTIC + STRUCTURAL + CSV_TEXT,
    "npz": SEMANTIC + STRUCTURAL + NPZ_BYTES,
}
_FIELD_NAMES = ("joint_names", "times", "positions", "velocities", "accelerations", "coefficients")
_CONTROLLERS = ("seed", "intended", "jtc", "jtc-none", "joint-position", "joint-velocity", "trajectory")


def _structural(fields: dict[str, Any], kind: str, spec: Spec) -> dict[str, Any] | str | bytes:
    f = dict(fields)
    name = _pick(_FIELD_NAMES, spec.a)
    if kind == "drop_field":
        f.pop(name, None)
    elif kind == "field_type":
        f[name] = _pick([None, spec.s, spec.x, {}, [], [[[spec.x]]], [spec.s] * 3, True], spec.b)
    elif kind == "cell":
        arr = np.array(f.get(name, f["positions"]), dtype=object)
        flat = arr.reshape(-1)
        if flat.size:
            flat[spec.b % flat.size] = _special(spec) if spec.a % 4 else spec.s
        f[name] = arr.tolist()
    elif kind in ("rows", "columns"):
        arr = np.asarray(f.get(name, f["positions"]))
        axis = 0 if kind == "rows" or arr.ndim < 2 else arr.ndim - 1
        if spec.b % 2 and arr.shape[axis] > 0:
            arr = np.delete(arr, spec.a % arr.shape[axis], axis=axis)
        else:
            arr = np.concatenate([arr, np.take(arr, [-1], axis=axis)], axis=axis) if arr.size else arr
        f[name] = arr
    elif kind == "names_duplicate":
        names = list(f["joint_names"])
        names[spec.a % len(names)] = names[(spec.a + 1 + spec.b % (len(names) - 1)) % len(names)]
        f["joint_names"] = names
    elif kind == "names_unknown":
        names = list(f["joint_names"])
        names[spec.a % len(names)] = spec.s or "bogus"
        f["joint_names"] = names
    elif kind == "names_type":
        f["joint_names"] = _pick([list(range(len(f["joint_names"]))), spec.s, None, [[1]], [spec.x]], spec.b)
    elif kind == "times_swap":
        t = np.array(f["times"], dtype=float)
        i = spec.a % (len(t) - 1)
        t[[i, i + 1]] = t[[i + 1, i]]
        f["times"] = t
    elif kind == "times_repeat":
        t = np.array(f["times"], dtype=float)
        i = spec.a % (len(t) - 1)
        t[i + 1] = t[i]
        f["times"] = t
    elif kind == "times_scale":
        with np.errstate(all="ignore"):
            f["times"] = np.asarray(f["times"], dtype=float) * _special(spec)
    elif kind == "extra_field":
        f[spec.s or "extra"] = spec.x
    elif kind == "degree":
        c = np.asarray(f.get("coefficients", np.zeros((1, 1, 1))))
        f["coefficients"] = c[:, : spec.a % 12] if spec.b % 2 else np.concatenate([c] * (1 + spec.a % 3), axis=1)
    elif kind == "top_level":
        return _pick(["[1, 2]", "3", '"text"', "null", "[]", "{}", "[{}]", "{" * 100000 + "}" * 100000], spec.a)
    return f


def _csv_text_mutation(text: str, kind: str, spec: Spec) -> str:
    lines = text.splitlines()
    if kind == "csv_cell":
        row = lines[1 + spec.a % (len(lines) - 1)].split(",")
        row[spec.b % len(row)] = _pick([spec.s, repr(_special(spec)), "", "1,2", '"5"'], spec.a)
        lines[1 + spec.a % (len(lines) - 1)] = ",".join(row)
    elif kind == "csv_header":
        head = lines[0].split(",")
        i = spec.a % len(head)
        head[i] = spec.s if spec.b % 2 else head[i] + _pick(["x", ".vle", " "], spec.b)
        lines[0] = ",".join(head)
    elif kind == "csv_drop_line":
        del lines[spec.a % len(lines)]
    elif kind == "csv_dup_line":
        i = spec.a % len(lines)
        lines.insert(i, lines[i])
    elif kind == "csv_bom":
        return "\ufeff" + text
    elif kind == "csv_separator":
        return text.replace(",", _pick([";", "\t", " ", ", "], spec.a))
    elif kind == "csv_blank_lines":
        lines.insert(1 + spec.a % len(lines), "")
    elif kind == "csv_header_only":
        lines = lines[:1]
    elif kind == "csv_extra_column":
        lines = [line + ("," + (spec.s or "extra") if i == 0 else f",{spec.x!r}") for i, line in enumerate(lines)]
    elif kind == "csv_swap_columns":
        rows = [line.split(",") for line in lines]
        i, j = spec.a % len(rows[0]), spec.b % len(rows[0])
        for r in rows:
            if max(i, j) < len(r):
                r[i], r[j] = r[j], r[i]
        lines = [",".join(r) for r in rows]
    elif kind == "csv_ragged":
        i = 1 + spec.a % (len(lines) - 1)
        lines[i] = ",".join(lines[i].split(",")[: spec.b % 30])
    return "\n".join(lines) + "\n"


def _trajectory_case(base: Base, spec: Spec, fmt: str, path: Path) -> Case:
    """A trajectory file in ``fmt`` and one of check / check via a controller / plan / replay on it."""
    from taplan.io import save_trajectory

    kinds = TRAJECTORY_KINDS[fmt]
    kind = _pick(kinds, spec.kind)
    surface = f"trajectory_{fmt}"
    limits_name = "planning" if spec.a % 5 == 0 else "hardware"
    limits = _limits(base, limits_name)
    traj = base.long_plan if spec.b % 11 == 0 else base.plan
    command = "check"
    argv_tail: list[str] = ["--no-png"]
    if limits_name == "planning":
        argv_tail += ["--limits", "planning"]
    roll = (spec.a + spec.b) % 10
    if roll == 7:
        argv_tail += ["--controller", _pick(_CONTROLLERS, spec.a // 3)]
    violates = valid = False
    if kind in SEMANTIC:
        if kind == "valid":
            valid = limits_name == "hardware" and roll != 7  # through a controller the base may step
            mutated = traj
        elif kind == "shift":
            mutated = _shift_past_limit(base, traj, spec, limits)
        elif kind == "stretch":
            mutated = _stretch(traj, spec)
        elif kind == "bump":
            mutated = _bump(traj, spec)
        elif kind == "coefficient":
            try:
                mutated = _coefficient(traj, spec)
            except Exception:  # noqa: BLE001 - an edit the trajectory class itself refuses: use it raw
                mutated = traj
        if kind in ("raw_positions", "raw_positions_linear"):
            fields = _fields(traj)
            j = spec.a % traj.n_joints
            q = np.array(fields["positions"], dtype=float)
            over = 1e-6 + 2.0 * _fraction(spec.x)
            q[spec.b % len(q), j] = (limits.upper[j] + over) if spec.b % 2 else (limits.lower[j] - over)
            fields["positions"] = q
            if kind == "raw_positions_linear":
                fields = {k: fields[k] for k in ("joint_names", "times", "positions")}
            violates = True
            content = _serialise(fields, fmt)
            _write(path, content)
        else:
            violates = violates or exceeds(mutated, limits)
            save_trajectory(mutated, path)
    else:
        fields = _fields(traj)
        if kind in CSV_TEXT:
            save_trajectory(traj, path)
            content: Any = _csv_text_mutation(path.read_text(), kind, spec)
        elif kind in NPZ_BYTES:
            save_trajectory(traj, path)
            raw = path.read_bytes()
            if kind == "npz_object":
                fields["positions"] = np.array([[spec.s] * traj.n_joints] * len(traj.times), dtype=object)
                buffer = io.BytesIO()
                np.savez(buffer, **{k: np.asarray(v, dtype=object) for k, v in fields.items()})
                content = buffer.getvalue()
            elif kind == "npz_corrupt":
                cut = bytearray(raw)
                for i in range(1 + spec.b % 8):
                    cut[(spec.a * 7919 + i * 104729) % len(cut)] ^= 0xFF
                content = bytes(cut)
            else:
                content = spec.blob or spec.s.encode("utf-8", "surrogatepass")
        elif kind == "truncate":
            save_trajectory(traj, path)
            raw = path.read_bytes()
            content = raw[: int(len(raw) * _fraction(spec.x))]
        elif kind == "garbage":
            content = spec.blob + spec.s.encode("utf-8", "surrogatepass")
        elif kind == "empty":
            content = b""
        else:
            result = _structural(fields, kind, spec)
            content = result if isinstance(result, str) else _serialise(result, fmt)
        _write(path, content)
    if roll in (8, 9) and kind not in ("valid",) and spec.b % 4 == 0:
        command, argv_tail = ("plan", ["--method", "topp", "-o", str(path.with_name("out.json"))])
    elif roll == 6 and spec.b % 3 == 0:
        command = "replay"
        argv_tail = ["--controller", _pick(_CONTROLLERS[:-1], spec.a), "-o", str(path.with_name("replay.csv"))]
    if command != "check":
        valid = False
        violates = violates and kind in ("shift", "raw_positions", "raw_positions_linear") and command == "plan"
    return Case(surface, kind, [command, str(path), *argv_tail], violates=violates, valid=valid)


def _serialise(fields: Any, fmt: str) -> str | bytes:
    if isinstance(fields, (str, bytes)):
        return fields
    if fmt == "json":
        return _json_text(fields)
    if fmt == "npz":
        return _npz_bytes(fields)
    return _csv_text(fields)


def _csv_text(fields: dict[str, Any]) -> str:
    """The contract's CSV layout, written here (not by taplan) so that malformed fields can be written too."""
    raw = fields.get("joint_names")
    names = [str(n) for n in np.ravel(np.asarray(raw, dtype=object))] if raw is not None else []
    header = ["time"]
    columns: list[np.ndarray] = []
    t = np.atleast_1d(np.asarray(fields.get("times", []), dtype=object))
    columns.append(t.reshape(len(t), -1)[:, :1] if t.size else np.zeros((0, 1)))
    for tag, key in (("pos", "positions"), ("vel", "velocities"), ("acc", "accelerations")):
        if key in fields and fields[key] is not None:
            try:
                arr = np.asarray(fields[key], dtype=object)
                arr = arr.reshape(arr.shape[0] if arr.ndim else 1, -1) if arr.size else np.zeros((0, 1))
            except ValueError:  # ragged: one cell of text per row
                arr = np.array([[str(fields[key])]], dtype=object)
            header += [f"{n}.{tag}" for n in names[: arr.shape[1]]] + ["?"] * max(0, arr.shape[1] - len(names))
            columns.append(arr)
    rows = max((c.shape[0] for c in columns), default=0)
    lines = [",".join(header)]
    for r in range(rows):
        cells = []
        for c in columns:
            cells += [repr(x) if isinstance(x, float) else str(x) for x in (c[r] if r < c.shape[0] else [])]
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------------------ waypoints
WAYPOINT_KINDS = ("valid", "outside", "cell", "header", "one_row", "repeat", "subset", "unknown", "garbage", "wide")


def _waypoint_case(base: Base, spec: Spec, path: Path) -> Case:
    kind = _pick(WAYPOINT_KINDS, spec.kind)
    robot = base.robot
    lim = robot.planning_limits
    rng = np.random.default_rng(abs(spec.a * 1_000_003 + spec.b))
    n = 2 + spec.a % 4
    span = lim.upper - lim.lower
    q = lim.lower + span * (0.05 + 0.9 * rng.random((n, 14)))
    names = list(robot.joint_names)
    violates = valid = False
    if kind == "outside":
        j = spec.b % 14
        over = 1e-6 + 2.0 * _fraction(spec.x)
        q[spec.a % n, j] = robot.limits.upper[j] + over if spec.b % 2 else robot.limits.lower[j] - over
        violates = True
    elif kind == "one_row":
        q = q[:1]
    elif kind == "repeat":
        q[1] = q[0]
    elif kind == "subset":
        keep = sorted(set(rng.choice(14, size=1 + spec.b % 14, replace=False).tolist()))
        q, names = q[:, keep], [names[k] for k in keep]
    elif kind == "unknown":
        names[spec.b % 14] = spec.s or "bogus"
    elif kind == "wide":
        q = np.hstack([q, q[:, :1]])
        names.append(_pick([names[0], spec.s, "extra"], spec.b))
    lines = [",".join(names)] + [",".join(repr(float(x)) for x in row) for row in q]
    if kind == "cell":
        row = lines[1 + spec.a % n].split(",")
        row[spec.b % len(row)] = _pick([spec.s, repr(_special(spec)), ""], spec.a)
        lines[1 + spec.a % n] = ",".join(row)
    elif kind == "header":
        lines[0] = lines[0].replace(names[spec.b % len(names)], spec.s, 1)
    content: str | bytes = "\n".join(lines) + "\n"
    if kind == "garbage":
        content = spec.blob + spec.s.encode("utf-8", "surrogatepass")
    _write(path, content)
    method = "topp" if spec.b % 3 else "jerk"
    out = path.with_name("timed.json")
    valid = kind == "valid"
    argv = ["plan", str(path), "--method", method, "-o", str(out)]
    flags = ("--no-jerk",) if method == "topp" else ()
    return Case("waypoint_csv", kind, argv, violates, valid, out, flags)


# --------------------------------------------------------------------------------------------- scenes
SCENE_KINDS = ("valid", "yaml_edit", "json", "value", "shape", "pose", "syntax", "top_level", "alias_bomb")
SCENE_KINDS += ("garbage", "empty", "many")


def _scene_case(base: Base, spec: Spec, path: Path) -> Case:
    import yaml

    kind = _pick(SCENE_KINDS, spec.kind)
    data = yaml.safe_load(base.scene_text)
    obstacle = data["obstacles"][spec.a % len(data["obstacles"])]
    suffix = ".yaml"
    content: str | bytes
    if kind == "yaml_edit":
        key = _pick(["frame", "obstacles", "name", "shape", "pose"], spec.b)
        (data if key in data else obstacle).pop(key, None) if spec.a % 2 else (data if key in data else obstacle)
        if not spec.a % 2:
            (data if key in data else obstacle)[key] = _pick([spec.s, spec.x, None, [], {}], spec.b // 5)
    elif kind == "value":
        target = _pick(["size", "xyz", "xyzw"], spec.b)
        holder = obstacle["shape"] if target == "size" else obstacle["pose"]
        values = list(holder.get(target, [0.0]))
        values[spec.a % len(values)] = _special(spec) if spec.a % 3 else spec.s
        holder[target] = values
    elif kind == "shape":
        obstacle["shape"] = _pick(
            [
                {"type": spec.s},
                {"type": "sphere", "radius": _special(spec)},
                {"type": "cylinder", "radius": 0.05, "length": _special(spec)},
                {"type": "capsule", "radius": _special(spec), "length": 0.1},
                {"type": "mesh", "file": spec.s or "missing.stl"},
                {"type": "box", "size": [0.1, 0.1]},
                {"type": "box", "size": [0.1, 0.1, 0.1], "extra": 1},
            ],
            spec.b,
        )
    elif kind == "pose":
        obstacle["pose"] = _pick(
            [
                {"xyz": [0.0, 0.0, 0.0], "xyzw": [0.0, 0.0, 0.0, 0.0]},
                {"xyz": [0.0, 0.0], "xyzw": [0, 0, 0, 1]},
                {"xyz": [0.2, 0.3, 0.0], "xyzw": [0, 0, 0, 1]},  # inside the robot: planning must refuse
                {"xyz": [spec.x, 0.0, 0.0]},
                spec.s,
            ],
            spec.b,
        )
    elif kind == "top_level":
        data = _pick([[1, 2], "text", 3, None, {"obstacles": spec.s}, {"frame": "world", "obstacles": []}], spec.b)
    elif kind == "many":
        data["obstacles"] = [dict(obstacle, name=f"o{i}") for i in range(1 + spec.a % 40)]
    if kind == "json":
        suffix = ".json"
        content = json.dumps(data)
    elif kind == "syntax":
        content = base.scene_text.replace(":", _pick([" -", "::", ""], spec.a), 1 + spec.b % 5)
    elif kind == "alias_bomb":
        content = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
            f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n"
            for p, c in zip("abcdefgh", "bcdefghi", strict=True)
        )
    elif kind == "garbage":
        content = spec.blob + spec.s.encode("utf-8", "surrogatepass")
    elif kind == "empty":
        content = ""
    else:
        content = yaml.safe_dump(data)
    path = path.with_suffix(suffix)
    _write(path, content)
    waypoints = base.extra.get("scene_waypoints")
    if waypoints is None:
        q0 = base.robot.home
        waypoints = base.dir / "scene_wp.csv"
        rows = [",".join(base.robot.joint_names)] + [",".join(repr(float(x)) for x in q) for q in (q0, q0 + 0.05)]
        waypoints.write_text("\n".join(rows) + "\n")
        base.extra["scene_waypoints"] = waypoints
    out = path.with_name("scene_plan.json")
    argv = ["plan", str(waypoints), "--scene", str(path), "-o", str(out)]
    return Case("scene", kind, argv, valid=kind == "valid", check_output=out)


# ---------------------------------------------------------------------------------------------- URDFs
URDF_KINDS = ("valid", "missing", "directory", "empty", "garbage", "truncate", "limit_value", "drop_tag", "xml_bomb")
URDF_KINDS += ("wrong_suffix", "no_robot")


def _urdf_case(base: Base, spec: Spec, path: Path) -> Case:
    import re

    kind = _pick(URDF_KINDS, spec.kind)
    text = base.urdf_text
    target = path.with_suffix(".urdf")
    content: str | bytes | None = text
    if kind == "missing":
        content = None
        target = path.with_name("does_not_exist.urdf")
    elif kind == "directory":
        content = None
        target = path.with_name("a_directory.urdf")
        target.mkdir(exist_ok=True)
    elif kind == "empty":
        content = ""
    elif kind == "garbage":
        content = spec.blob + spec.s.encode("utf-8", "surrogatepass")
    elif kind == "truncate":
        content = text[: int(len(text) * _fraction(spec.x))]
    elif kind == "limit_value":
        attr = _pick(["lower", "upper", "velocity", "effort"], spec.b)
        matches = list(re.finditer(rf'{attr}="([^"]*)"', text))
        m = matches[spec.a % len(matches)]
        value = repr(_special(spec)) if spec.a % 3 else spec.s.replace('"', "")
        content = text[: m.start(1)] + value + text[m.end(1) :]
    elif kind == "drop_tag":
        tag = _pick(["<limit ", "<joint ", "<link ", "<parent ", "<child ", "<axis "], spec.b)
        start = [m.start() for m in re.finditer(re.escape(tag), text)]
        s0 = start[spec.a % len(start)]
        end = text.find("/>", s0) + 2 if tag != "<joint " else text.find("</joint>", s0) + len("</joint>")
        content = text[:s0] + text[end:]
    elif kind == "xml_bomb":
        content = (
            '<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;">'
            '<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;"><!ENTITY d "&c;&c;&c;&c;&c;&c;&c;&c;">]><robot name="&d;"/>'
        )
    elif kind == "wrong_suffix":
        target = path.with_suffix(".txt")
    elif kind == "no_robot":
        content = '<?xml version="1.0"?><robot name="empty"></robot>'
    if content is not None:
        _write(target, content)
    return Case("urdf", kind, ["info", "--urdf", str(target)], valid=kind == "valid")


# ------------------------------------------------------------------------------------------------ bags
BAG_KINDS = ("valid", "past_limit", "nan", "names", "lengths", "order", "one_message", "empty_bag", "truncate")
BAG_KINDS += ("flip_bytes", "append", "one_side", "not_mcap")


def _bag_case(base: Base, spec: Spec, path: Path) -> Case:
    from taplan import api
    from taplan.ros import bag

    kind = _pick(BAG_KINDS, spec.kind)
    path = path.with_suffix(".mcap")
    rate = 77.0
    t = base.long_plan.sample_times(rate)
    q = base.long_plan(t, 0)
    left = base.robot.indices(api.ARM_JOINT_NAMES["left"])
    right = base.robot.indices(api.ARM_JOINT_NAMES["right"])
    violates = False
    if kind == "past_limit":
        j = spec.a % 14
        over = 1e-6 + 2.0 * _fraction(spec.x)
        row = spec.b % len(q)
        q[row:, j] += (base.robot.limits.upper[j] - q[row:, j].min() + over) if spec.b % 2 else 0.0
        if not spec.b % 2:
            q[row:, j] += base.robot.limits.lower[j] - q[row:, j].max() - over
        violates = True
    elif kind == "nan":
        q[spec.a % len(q), spec.b % 14] = _pick([math.nan, math.inf, -math.inf, 1e308], spec.a)
    start = 1_700_000_000_000_000_000
    stamps = start + np.round(t * 1e9).astype(np.int64)
    if kind == "order":
        i = spec.a % (len(stamps) - 1)
        stamps[[i, i + 1]] = stamps[[i + 1, i]]
    count = {"one_message": 1, "empty_bag": 0}.get(kind, len(t))
    with bag.BagWriter(path) as writer:
        for k in range(count):
            for side, cols in (("left", left), ("right", right)):
                if kind == "one_side" and side == "right":
                    continue
                names = list(api.ARM_JOINT_NAMES[side])
                positions = [float(x) for x in q[k, cols]]
                if kind == "names" and k == spec.b % count:
                    names[spec.a % 7] = spec.s or "bogus"
                if kind == "lengths" and k == spec.b % count:
                    positions = positions[: spec.a % 7]
                fields = {"name": names, "position": positions, "velocity": [], "effort": []}
                writer.record(api.Topics.joint_cmd(side), api.JOINT_STATE, fields, int(stamps[k]))
                writer.record(api.Topics.joint_states(side), api.JOINT_STATE, fields, int(stamps[k]) + 3_000_000)
            if k % 7 == 0:
                writer.record(api.Topics.ENABLE, api.FLOAT32, {"data": 1.0}, int(stamps[k]))
    raw = path.read_bytes()
    if kind == "truncate":
        _write(path, raw[: int(len(raw) * _fraction(spec.x))])
    elif kind == "flip_bytes":
        damaged = bytearray(raw)
        for i in range(1 + spec.b % 16):
            damaged[(spec.a * 7919 + i * 104729) % len(damaged)] ^= 1 << (i % 8)
        _write(path, bytes(damaged))
    elif kind == "append":
        _write(path, raw + spec.blob + spec.s.encode("utf-8", "surrogatepass"))
    elif kind == "not_mcap":
        _write(path, spec.blob or b"not an mcap file")
    return Case("bag", kind, ["check", str(path)], violates=violates)


# ---------------------------------------------------------------------------------------------- flags
_VALUES = ("0", "-1", "1", "1e9", "1e-9", "nan", "inf", "-inf", "abc", "", "77", "100", "0.5", "2", "1e308", "-0")
_FLAGS = {
    "check": ("--controller", "--update-rate", "--pub-rate", "--command-rate", "--jitter", "--limits", "--source",
              "--rate", "--no-jerk", "--png", "--no-png", "--json"),
    "replay": ("--controller", "--update-rate", "--pub-rate", "--command-rate", "--jitter", "-o"),
    "plan": ("--method", "--limits", "-o", "--rate", "--margin", "--recorded", "--max-deviation", "--fastest",
             "--stream"),
    "info": ("--json", "--urdf"),
    "view": ("--scene", "--host", "--port", "--play", "--duration", "--urdf"),
    "run": ("--domain-id", "--hold", "--duration", "--rate", "--state-timeout", "--tracking-error", "--wait"),
    "sim": ("--domain-id", "--duration", "--rate", "--motion-rate", "--motion", "--stall-after"),
    "demo": ("-o", "--no-plots"),
    "bench": ("--only",),
}  # fmt: skip
_SWITCHES = {"--no-jerk", "--no-png", "--json", "--recorded", "--fastest", "--play", "--no-plots"}
_CHOICES = {
    "--controller": _CONTROLLERS + ("bogus",),
    "--limits": ("hardware", "planning", "x"),
    "--source": ("updates", "samples", "x"),
    "--method": ("topp", "jerk", "optimize"),
    "--stream": ("measured", "commanded", "x"),
    "--motion": ("joint", "interpolate", "x"),
}


def _flags_case(base: Base, spec: Spec, path: Path) -> Case:
    """A command with a random set of its flags at random values; commands that would start a server, the network
    or a long job always get one value they must refuse."""
    from taplan.io import save_trajectory

    rng = np.random.default_rng(abs(spec.a * 7_777_777 + spec.b * 31 + spec.kind))
    commands = list(_FLAGS)
    command = _pick(commands, spec.kind)
    plan_file = base.extra.get("flags_plan")
    if plan_file is None:
        plan_file = save_trajectory(base.plan, base.dir / "flags_plan.json")
        base.extra["flags_plan"] = plan_file
    files = {
        "check": str(plan_file),
        "replay": str(plan_file),
        "plan": str(plan_file),
        "view": str(plan_file),
        "run": str(plan_file),
    }
    argv = [command]
    if command in files:
        argv.append(_pick([files[command], files[command], spec.s, str(path.with_name("missing.json"))], spec.b))
    flags = list(_FLAGS[command])
    chosen = rng.choice(len(flags), size=min(len(flags), 1 + spec.a % 4), replace=False)
    for i in chosen:
        flag = flags[int(i)]
        argv.append(flag)
        if flag in _SWITCHES:
            continue
        if flag in _CHOICES:
            argv.append(str(rng.choice(_CHOICES[flag])))
        elif flag in ("-o", "--png", "--json", "--urdf", "--scene"):
            suffix = str(rng.choice([".json", ".csv", ".png", ".txt", ".npz", ""]))
            where = rng.choice(["here", "missing_dir", "existing_dir", "text"])
            target = {
                "here": str(path.with_name("flag_out" + suffix)),
                "missing_dir": str(path.parent / "no" / "such" / ("out" + suffix)),
                "existing_dir": str(path.parent),
                "text": spec.s,
            }[str(where)]
            argv.append(target)
        else:
            argv.append(str(rng.choice(_VALUES)) if spec.a % 5 else repr(spec.x))
    if spec.b % 9 == 0:
        argv.insert(1 + rng.integers(len(argv)), _pick(["--bogus", "-x", "--", "---", "-", "extra"], spec.a))
    # never start a server, a DDS participant or a full job: one refused value keeps each of these short
    if command == "view":
        argv += ["--html", str(path.with_name("view.txt"))]  # not .html: refused before serving
    elif command in ("run", "sim"):
        # a refused rate; and should it be accepted, a bounded time on a private loopback DDS domain
        argv += ["--rate", "1e9", "--loopback", "--domain-id", "229"]
        argv += ["--duration", "2"] if command == "sim" else ["--wait", "2"]
    elif command == "demo":
        argv += ["-o", str(plan_file)]  # an existing file
    elif command == "bench":
        argv += ["--only", "no_such_benchmark"]
    return Case("flags", command, argv)


# --------------------------------------------------------------------------------------------- dispatch
def kinds(surface: str) -> tuple[str, ...]:
    return {
        "trajectory_json": TRAJECTORY_KINDS["json"],
        "trajectory_csv": TRAJECTORY_KINDS["csv"],
        "trajectory_npz": TRAJECTORY_KINDS["npz"],
        "waypoint_csv": WAYPOINT_KINDS,
        "scene": SCENE_KINDS,
        "urdf": URDF_KINDS,
        "bag": BAG_KINDS,
        "flags": tuple(_FLAGS),
    }[surface]


def make_case(base: Base, surface: str, spec: Spec, directory: Path) -> Case:
    """Write the input files of ``spec`` on ``surface`` into ``directory`` and return the case."""
    directory.mkdir(parents=True, exist_ok=True)
    if surface.startswith("trajectory_"):
        fmt = surface.removeprefix("trajectory_")
        return _trajectory_case(base, spec, fmt, directory / f"traj.{fmt}")
    builder = {
        "waypoint_csv": lambda: _waypoint_case(base, spec, directory / "wp.csv"),
        "scene": lambda: _scene_case(base, spec, directory / "scene.yaml"),
        "urdf": lambda: _urdf_case(base, spec, directory / "robot.urdf"),
        "bag": lambda: _bag_case(base, spec, directory / "run.mcap"),
        "flags": lambda: _flags_case(base, spec, directory / "flags"),
    }[surface]
    return builder()


def random_spec(rng: np.random.Generator, surface: str) -> Spec:
    """A spec from a numpy generator (the benchmark's source; the tests draw specs with hypothesis)."""
    n = len(kinds(surface))
    x = float(rng.choice(SPECIAL_FLOATS)) if rng.random() < 0.2 else float(rng.normal(0.0, 3.0))
    s = str(rng.choice(SPECIAL_TEXT)) if rng.random() < 0.7 else "".join(map(chr, rng.integers(32, 0x2FF, 8)))
    blob = bytes(rng.integers(0, 256, int(rng.integers(0, 64)), dtype=np.uint8))
    return Spec(int(rng.integers(n)), int(rng.integers(0, 10_000)), int(rng.integers(0, 10_000)), x, s, blob)


def exercise(base: Base, surface: str, spec: Spec, directory: Path) -> tuple[Case, Answer, list[str]]:
    """Make the case, run it in process, judge it (and plan's output)."""
    case = make_case(base, surface, spec, directory)
    answer = run_inprocess(case.argv)
    problems = judge(case, answer)
    if answer.code == 0 and not problems:
        problems += judge_output(case)
    return case, answer, problems
