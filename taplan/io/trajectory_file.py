"""The trajectory-file contract: one reader and one writer for JSON, CSV and NPZ.

Layouts (one trajectory, joints in file order, SI units):

* **JSON**: an object ``{"joint_names": [...], "times": [...], "positions": [[...], ...], "velocities": ...,
  "accelerations": ..., "coefficients": ...}``.
* **NPZ**: the same keys as arrays (read without pickle; ``joint_names`` a string array).
* **CSV**: a header ``time,<joint>.pos,...`` then optionally ``<joint>.vel``, ``<joint>.acc`` and ``<joint>.c0 ..
  <joint>.c<d>`` columns, every joint in each group; one row per sample. The coefficient cells of row ``k`` describe
  segment ``k`` (from ``times[k]`` to ``times[k+1]``); the last row leaves them empty.

Rules, the same for every format and every reader:

* ``joint_names``: n >= 1 unique strings; a reader that knows the robot also requires each to be one of its joints.
* ``times``: N >= 2 finite values, strictly increasing (steps above 1e-12 s).
* ``positions`` [rad] (required), ``velocities`` [rad/s], ``accelerations`` [rad/s²] (needs velocities): shape
  (N, n), finite.
* ``coefficients``: shape (N-1, d+1, n) with 1 <= d+1 <= 16, finite; segment k is ``sum_i c[k, i] (t - t_k)**i``.
  The trajectory is then exactly this piecewise polynomial, and every sample field in the file must agree with it
  at the sample times (right-hand values; the last sample is the end of the last segment) within
  :data:`POSITION_TOL` (1e-9 rad), :data:`VELOCITY_TOL` (1e-6 rad/s) and :data:`ACCELERATION_TOL` (1e-3 rad/s²);
  otherwise the load fails naming the first disagreement (field, joint, time, both values). A file written by
  :func:`save_trajectory` agrees to the last bit: the samples are computed from the coefficients.
* Without coefficients the samples define the interpolation (as :class:`~taplan.trajectory.Trajectory` documents):
  positions only, linear; with velocities, cubic Hermite; with accelerations too, quintic Hermite.

Every format is exact: JSON writes shortest round-trip floats, CSV 17 significant digits, NPZ the binary values,
and a polynomial trajectory keeps its coefficients in all three. Every violation is a :class:`~taplan.errors.
ConfigError` whose one-line message starts with the file name and names the field, what was found and what is valid.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from taplan.errors import ConfigError, InvalidInputError
from taplan.trajectory import Trajectory

__all__ = [
    "ACCELERATION_TOL",
    "POSITION_TOL",
    "VELOCITY_TOL",
    "load_trajectory",
    "read_waypoints",
    "save_trajectory",
]

POSITION_TOL = 1e-9  # [rad]
VELOCITY_TOL = 1e-6  # [rad]/[s]
ACCELERATION_TOL = 1e-3  # [rad]/[s]²
SUFFIXES = (".json", ".csv", ".npz")
_MAX_TERMS = 16  # polynomial degree 15: jerk_limited's path-timed pieces reach degree 11
_TIME_STEP = 1e-12  # [s]
_SAMPLE_FIELDS = (("positions", 0, POSITION_TOL, "rad"), ("velocities", 1, VELOCITY_TOL, "rad/s"))
_SAMPLE_FIELDS += (("accelerations", 2, ACCELERATION_TOL, "rad/s²"),)
_CSV_TAGS = {"pos": "positions", "vel": "velocities", "acc": "accelerations"}


class _FileError(ConfigError):
    """A contract violation; the message is ``<file>: <field>: expected ..., found ...``."""

    def __init__(self, path: Path, field: str, found: Any, expected: str) -> None:
        shown = str(found)
        shown = shown if len(shown) <= 120 else shown[:117] + "..."
        super().__init__(f"{str(path)!r}: {field}: expected {expected}, found {shown}")


# ------------------------------------------------------------------------------------------------------- load
def load_trajectory(path: str | Path, joint_names: Sequence[str] | None = None) -> Trajectory:
    """Read and validate a trajectory file (see the module docstring for the contract).

    Args:
        path: A ``.json``, ``.csv`` or ``.npz`` file.
        joint_names: The robot's joints; when given, every joint in the file must be one of them.

    Raises:
        ConfigError: the file is missing, unreadable or breaks the contract (the message names the field).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise _FileError(path, "file name", path.name, "a trajectory file ending in .json, .csv or .npz")
    if not path.is_file():
        raise ConfigError(f"trajectory file not found: {str(path)!r}")
    reader = {".json": _read_json, ".csv": _read_csv, ".npz": _read_npz}[suffix]
    return build_trajectory(reader(path), joint_names, source=path)


def build_trajectory(
    fields: dict[str, Any], joint_names: Sequence[str] | None = None, *, source: str | Path = "data"
) -> Trajectory:
    """The trajectory that ``fields`` (the contract's keys) describe, validated; errors name ``source``."""
    path = Path(source)
    names = _joint_names(path, fields.get("joint_names"), joint_names)
    n = len(names)
    times = _array(path, fields, "times", required=True)
    if times.ndim != 1 or times.shape[0] < 2:
        raise _FileError(path, "times", f"shape {times.shape}", "a list of at least 2 times [s]")
    _finite(path, "times", times)
    steps = np.diff(times)
    if np.any(steps <= _TIME_STEP):
        k = int(np.argmax(steps <= _TIME_STEP))
        raise _FileError(
            path, "times", f"times[{k}]={times[k]!r}, times[{k + 1}]={times[k + 1]!r}", "strictly increasing times"
        )
    samples: dict[str, np.ndarray] = {}
    for field, _, _, _ in _SAMPLE_FIELDS:
        array = _array(path, fields, field, required=field == "positions")
        if array is None:
            continue
        if array.shape != (times.shape[0], n):
            raise _FileError(
                path,
                field,
                f"shape {array.shape}",
                f"shape ({times.shape[0]}, {n}): one row per time, one column per joint",
            )
        _finite(path, field, array, names, times)
        samples[field] = array
    if "accelerations" in samples and "velocities" not in samples:
        raise _FileError(path, "accelerations", "accelerations without velocities", "velocities as well")
    coefficients = _array(path, fields, "coefficients", required=False)
    if coefficients is None:
        return Trajectory(times, samples["positions"], samples.get("velocities"), samples.get("accelerations"), names)
    expected = (times.shape[0] - 1, f"1..{_MAX_TERMS}", n)
    if coefficients.ndim != 3 or coefficients.shape[0] != expected[0] or coefficients.shape[2] != n:
        raise _FileError(path, "coefficients", f"shape {coefficients.shape}", f"shape {expected}: one per segment")
    if not 1 <= coefficients.shape[1] <= _MAX_TERMS:
        raise _FileError(
            path, "coefficients", f"shape {coefficients.shape}", f"shape {expected}: degree at most {_MAX_TERMS - 1}"
        )
    _finite(path, "coefficients", coefficients)
    try:
        trajectory = Trajectory.from_polynomials(times, coefficients, names, continuous_velocity=False)
    except InvalidInputError as exc:
        raise _FileError(path, "coefficients", exc.received, exc.expected) from None
    _agree(path, trajectory, samples)
    return trajectory


def _agree(path: Path, trajectory: Trajectory, samples: dict[str, np.ndarray]) -> None:
    """Raise on the earliest sample (then the first joint) where the file's samples and coefficients differ."""
    derived = {"positions": trajectory.positions, "velocities": trajectory.velocities}
    derived["accelerations"] = trajectory.accelerations
    for field, _, tol, unit in _SAMPLE_FIELDS:
        if field not in samples:
            continue
        given, exact = samples[field], derived[field]
        bad = np.abs(given - exact) > tol
        if np.any(bad):
            row = int(np.argmax(bad.any(axis=1)))
            col = int(np.argmax(bad[row]))
            joint = trajectory.joint_names[col]
            raise ConfigError(
                f"{str(path)!r}: {field} disagree with coefficients at {joint}, t={trajectory.times[row]:.9g} s "
                f"(sample {row}): {field} {given[row, col]:.12g} {unit}, coefficients {exact[row, col]:.12g} {unit} "
                f"(tolerance {tol:g} {unit})"
            )


def _joint_names(path: Path, value: Any, known: Sequence[str] | None) -> tuple[str, ...]:
    if value is None:
        raise _FileError(path, "joint_names", "nothing", "a list of joint names")
    if isinstance(value, np.ndarray):
        if value.ndim != 1 or value.dtype.kind != "U":
            raise _FileError(path, "joint_names", f"array of {value.dtype} shape {value.shape}", "a list of strings")
        value = value.tolist()
    if not isinstance(value, list | tuple) or not value or not all(isinstance(x, str) and x for x in value):
        raise _FileError(path, "joint_names", value, "a non-empty list of non-empty strings")
    seen: set[str] = set()
    for name in value:
        if name in seen:
            raise _FileError(path, "joint_names", f"{name!r} twice", "unique joint names")
        seen.add(name)
    if known is not None:
        valid = set(known)
        for name in value:
            if name not in valid:
                shown = ", ".join(known)
                raise _FileError(path, "joint_names", f"unknown joint {name!r}", f"joints of the robot ({shown})")
    return tuple(value)


def _array(path: Path, fields: dict[str, Any], field: str, *, required: bool) -> np.ndarray | None:
    value = fields.get(field)
    if value is None:
        if required:
            raise _FileError(path, field, "nothing", f"a '{field}' entry")
        return None
    try:
        raw = np.asarray(value)
    except (ValueError, TypeError, OverflowError):  # ragged nesting, numbers too large for a float
        raise _FileError(path, field, "nested lists of unequal lengths", "a rectangular array of numbers") from None
    if raw.dtype.kind not in "iuf":
        raise _FileError(path, field, f"values of type {raw.dtype}", "numbers")
    try:
        return raw.astype(float)
    except OverflowError:
        raise _FileError(path, field, "an integer too large for a float", "finite numbers") from None


def _finite(
    path: Path, field: str, array: np.ndarray, names: Sequence[str] = (), times: np.ndarray | None = None
) -> None:
    bad = ~np.isfinite(array)
    if not np.any(bad):
        return
    where = np.argwhere(bad)[0]
    found = f"{array[tuple(where)]} at index {tuple(int(i) for i in where)}"
    if names and times is not None and array.ndim == 2:
        found = f"{array[tuple(where)]} for {names[where[1]]} at t={times[where[0]]:.9g} s"
    raise _FileError(path, field, found, "finite numbers (no NaN or inf)")


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_bytes())
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError, ValueError) as exc:
        raise ConfigError(f"{str(path)!r}: not valid JSON ({_first_line(exc)})") from None
    except OSError as exc:
        raise ConfigError(f"{str(path)!r}: cannot read ({exc.strerror or exc})") from None
    if not isinstance(data, dict):
        raise _FileError(path, "top level", f"a JSON {type(data).__name__}", "a JSON object with 'times', 'positions'")
    return data


def _read_npz(path: Path) -> dict[str, Any]:
    try:
        with np.load(path, allow_pickle=False) as npz:
            if not isinstance(npz, np.lib.npyio.NpzFile):
                raise ConfigError(f"{str(path)!r}: not an NPZ archive (a single .npy array)")
            return {key: npz[key] for key in npz.files}
    except ConfigError:
        raise
    except AttributeError:  # np.load returned a plain array for a .npy written under an .npz name
        raise ConfigError(f"{str(path)!r}: not an NPZ archive") from None
    except Exception as exc:  # noqa: BLE001 - a damaged archive raises anything (BadZipFile, zlib.error,
        # NotImplementedError for a flipped compression byte, ...): all of it is a file that cannot be read
        raise ConfigError(
            f"{str(path)!r}: not a readable NPZ archive without pickled objects ({type(exc).__name__}: "
            f"{_first_line(exc)})"
        ) from None


def _csv_rows(path: Path, text: str) -> list[list[str]]:
    """The non-blank rows of a CSV text; the csv module's own errors (e.g. a field of megabytes) as contract errors."""
    try:
        return [row for row in csv.reader(io.StringIO(text)) if row and any(cell.strip() for cell in row)]
    except csv.Error as exc:
        raise _FileError(path, "CSV", str(exc), "comma-separated rows of numbers under a header") from None


def _read_csv(path: Path) -> dict[str, Any]:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (UnicodeDecodeError, OSError) as exc:
        raise ConfigError(f"{str(path)!r}: cannot read as UTF-8 text ({_first_line(exc)})") from None
    rows = _csv_rows(path, text)
    if not rows:
        raise _FileError(path, "header", "an empty file", "a header 'time,<joint>.pos,...' and at least 2 rows")
    header = [cell.strip() for cell in rows[0]]
    if header[0] != "time":
        raise _FileError(
            path,
            "header",
            f"first column {header[0]!r}",
            "'time' (a waypoint CSV without times is read by 'taplan plan', which times it)",
        )
    columns = _csv_columns(path, header)
    body = rows[1:]
    if len(body) < 2:
        raise _FileError(path, "rows", f"{len(body)} data row(s)", "at least 2 samples")
    table = np.empty((len(body), len(header)))
    for r, row in enumerate(body):
        line = r + 2
        if len(row) != len(header):
            raise _FileError(path, f"line {line}", f"{len(row)} cells", f"{len(header)} cells, one per header column")
        for c, cell in enumerate(row):
            cell = cell.strip()
            if cell == "" and columns[c][0] == "coefficients" and r == len(body) - 1:
                table[r, c] = 0.0  # the last row carries no segment
                continue
            try:
                table[r, c] = float(cell)
            except ValueError:
                raise _FileError(path, f"line {line}, column {header[c]!r}", repr(cell), "a number") from None
    return _csv_fields(path, header, columns, table)


def _csv_columns(path: Path, header: list[str]) -> list[tuple[str, str, int]]:
    """(field, joint, coefficient index) of every column; ('times', '', 0) for the first."""
    out = [("times", "", 0)]
    for name in header[1:]:
        joint, dot, tag = name.rpartition(".")
        if not dot or not joint:
            raise _FileError(path, "header", f"column {name!r}", "'<joint>.pos', '.vel', '.acc' or '.c<k>' columns")
        if tag in _CSV_TAGS:
            out.append((_CSV_TAGS[tag], joint, 0))
        elif tag[:1] == "c" and tag[1:].isdigit() and int(tag[1:]) < _MAX_TERMS:
            out.append(("coefficients", joint, int(tag[1:])))
        else:
            raise _FileError(
                path,
                "header",
                f"column {name!r}",
                f"'<joint>.pos', '.vel', '.acc' or '.c0'..'.c{_MAX_TERMS - 1}' columns",
            )
    seen: set[tuple[str, str, int]] = set()
    for name, column in zip(header, out, strict=True):
        if column in seen:
            raise _FileError(path, "header", f"column {name!r} twice", "each column once")
        seen.add(column)
    return out


def _csv_fields(
    path: Path, header: list[str], columns: list[tuple[str, str, int]], table: np.ndarray
) -> dict[str, Any]:
    names = [joint for field, joint, _ in columns if field == "positions"]
    if not names:
        raise _FileError(path, "header", ",".join(header)[:80], "'<joint>.pos' columns after 'time'")
    index = {(field, joint, k): c for c, (field, joint, k) in enumerate(columns)}
    fields: dict[str, Any] = {"joint_names": names, "times": table[:, 0]}
    for field in ("positions", "velocities", "accelerations"):
        present = [joint for f, joint, _ in columns if f == field]
        if not present:
            continue
        stray = [joint for joint in present if joint not in names]
        missing = [joint for joint in names if joint not in present]
        tag = {v: k for k, v in _CSV_TAGS.items()}[field]
        if stray:
            raise _FileError(
                path,
                "header",
                f"column '{stray[0]}.{tag}' for a joint with no '.pos' column",
                f"'.{tag}' columns for the joints {', '.join(names)}",
            )
        if missing:
            raise _FileError(
                path, "header", f"no '{missing[0]}.{tag}' column", f"'.{tag}' columns for every joint or none"
            )
        fields[field] = table[:, [index[(field, joint, 0)] for joint in names]]
    terms = sorted({k for f, _, k in columns if f == "coefficients"})
    if terms:
        for joint in {joint for f, joint, _ in columns if f == "coefficients"} - set(names):
            raise _FileError(
                path,
                "header",
                f"coefficient columns for {joint!r}, which has no '.pos' column",
                f"coefficients of the joints {', '.join(names)}",
            )
        for joint in names:
            for k in range(terms[-1] + 1):
                if ("coefficients", joint, k) not in index:
                    raise _FileError(
                        path, "header", f"no '{joint}.c{k}' column", f"'.c0'..'.c{terms[-1]}' columns for every joint"
                    )
        cols = [[index[("coefficients", joint, k)] for joint in names] for k in range(terms[-1] + 1)]
        fields["coefficients"] = np.stack([table[:-1, c] for c in cols], axis=1)  # (N-1, d+1, n)
    return fields


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0][:160] if text else type(exc).__name__


# ------------------------------------------------------------------------------------------------------- save
def save_trajectory(trajectory: Trajectory, path: str | Path) -> Path:
    """Write ``trajectory`` to ``.json``, ``.csv`` or ``.npz`` (by suffix), exactly; returns the path.

    Missing parent directories are created. A polynomial trajectory (e.g. TOPP-RA's or ruckig's output) writes
    its coefficients beside the samples in every format, so :func:`load_trajectory` gives back the same function.
    """
    from taplan.io.paths import output_path

    path = output_path(path, "path", suffixes=SUFFIXES)
    fields = _fields(trajectory)
    suffix = path.suffix.lower()
    if suffix == ".json":
        path.write_text(json.dumps({k: np.asarray(v).tolist() for k, v in fields.items()}))
    elif suffix == ".npz":
        with path.open("wb") as handle:  # np.savez would append .npz to a name in another case
            np.savez(handle, **{k: np.asarray(v) for k, v in fields.items()})
    else:
        _write_csv(path, trajectory, fields)
    return path


def _fields(trajectory: Trajectory) -> dict[str, Any]:
    out: dict[str, Any] = {
        "joint_names": list(trajectory.joint_names),
        "times": trajectory.times,
        "positions": trajectory.positions,
    }
    if trajectory.velocities is not None:
        out["velocities"] = trajectory.velocities
    if trajectory.accelerations is not None:
        out["accelerations"] = trajectory.accelerations
    if trajectory.interpolation == "polynomial":
        out["coefficients"] = trajectory.coefficients
    return out


def _write_csv(path: Path, trajectory: Trajectory, fields: dict[str, Any]) -> None:
    names = trajectory.joint_names
    header = ["time"]
    blocks = [trajectory.times[:, None]]
    for tag, field in (("pos", "positions"), ("vel", "velocities"), ("acc", "accelerations")):
        if field in fields:
            header += [f"{n}.{tag}" for n in names]
            blocks.append(fields[field])
    lines_numeric = np.hstack(blocks)
    rows = [",".join(format(x, ".17g") for x in row) for row in lines_numeric]
    if "coefficients" in fields:
        c = fields["coefficients"]  # (N-1, d+1, n)
        header += [f"{n}.c{k}" for k in range(c.shape[1]) for n in names]
        flat = c.reshape(c.shape[0], -1)  # k-major, joint-minor: matches the header
        rows = [row + "," + ",".join(format(x, ".17g") for x in flat[i]) for i, row in enumerate(rows[:-1])]
        rows.append(",".join(format(x, ".17g") for x in lines_numeric[-1]) + "," * flat.shape[1])
    path.write_text(",".join(header) + "\n" + "\n".join(rows) + "\n")


# -------------------------------------------------------------------------------------------------- waypoints
def read_waypoints(path: str | Path, joint_names: Sequence[str] | None = None) -> tuple[tuple[str, ...], np.ndarray]:
    """Joint names and waypoints (N, n) [rad] from a waypoint CSV or a trajectory file (its positions).

    A waypoint CSV has a header naming the joints (``l_joint1,l_joint2,...``, no ``time`` column) and one waypoint
    per row; N >= 2 rows of finite numbers. The same name rules as a trajectory file apply.
    """
    path = Path(path)
    if path.suffix.lower() != ".csv" or not path.is_file():
        trajectory = load_trajectory(path, joint_names)
        return trajectory.joint_names, np.array(trajectory.positions)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (UnicodeDecodeError, OSError) as exc:
        raise ConfigError(f"{str(path)!r}: cannot read as UTF-8 text ({_first_line(exc)})") from None
    rows = _csv_rows(path, text)
    if rows and rows[0][0].strip() == "time":
        trajectory = load_trajectory(path, joint_names)
        return trajectory.joint_names, np.array(trajectory.positions)
    if not rows:
        raise _FileError(path, "header", "an empty file", "a header of joint names and at least 2 waypoint rows")
    names = _joint_names(path, [cell.strip() for cell in rows[0]], joint_names)
    if len(rows) < 3:
        raise _FileError(path, "rows", f"{len(rows) - 1} waypoint row(s)", "at least 2 waypoints")
    table = np.empty((len(rows) - 1, len(names)))
    for r, row in enumerate(rows[1:]):
        if len(row) != len(names):
            raise _FileError(path, f"line {r + 2}", f"{len(row)} cells", f"{len(names)} cells, one per joint")
        for c, cell in enumerate(row):
            try:
                table[r, c] = float(cell)
            except ValueError:
                raise _FileError(path, f"line {r + 2}, column {names[c]!r}", repr(cell.strip()), "a number") from None
    _finite(path, "waypoints", table)
    return names, table
