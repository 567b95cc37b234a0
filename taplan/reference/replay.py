"""The result of replaying a plan through a controller model: the state at every controller update.

A :class:`Replay` is what the controller side would produce: ``times`` (m,) of every update, the state set at that
update (``positions``, ``velocities`` and, when the model knows them, ``accelerations``), the waypoints reached and
dropped, and optionally the :class:`JointStateSamples` a ``joint_states`` publisher would see at its own rate.
Velocities the controller does not report (an empty ``velocity`` list in ROS) are NaN.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from taplan.errors import InvalidInputError
from taplan.trajectory import Trajectory

__all__ = ["JointStateSamples", "Replay"]


@dataclass(frozen=True)
class JointStateSamples:
    """What a ``sensor_msgs/JointState`` publisher sampling the controller state would publish.

    Attributes:
        times: Publish times [s], shape (k,).
        positions: [rad], shape (k, n).
        velocities: [rad]/[s], shape (k, n); NaN where the message's velocity list would be empty.
        rate: Nominal publish rate [Hz].
        times_ns: Publish times in integer nanoseconds, shape (k,), or None.
        joint_names: n names, or None (``joint0..``).
    """

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    rate: float
    times_ns: np.ndarray | None = None
    joint_names: tuple[str, ...] | None = None

    def __len__(self) -> int:
        return int(self.times.shape[0])


@dataclass(frozen=True)
class Replay:
    """State stream of a controller model.

    Attributes:
        controller: Model name, e.g. ``"industrial_simulator[seed]"``.
        joint_names: n names.
        times: Update times [s] from the start of the replay, shape (m,), non-decreasing (a zero-length sleep gives
            two updates at the same time).
        positions: State after each update [rad], shape (m, n).
        velocities: Reported velocity after each update [rad]/[s], shape (m, n), NaN where not reported.
        accelerations: Reported acceleration [rad]/[s]², shape (m, n), or None when the model has none.
        rate: Nominal update rate [Hz].
        initial_positions: State before the first update [rad], shape (n,).
        initial_velocities: [rad]/[s], shape (n,).
        waypoint_indices: Input indices of the waypoints that were reached, shape (w,).
        waypoint_times: When each of them was reached [s], shape (w,).
        dropped: Input indices of waypoints the controller never reached.
        jumps: Indices into ``times`` of updates that move without interpolation.
        samples: ``joint_states`` samples, or None.
        times_ns: ``times`` in integer nanoseconds, or None for models that are not nanosecond-exact.
        events: Human-readable notes on what the model did (dropped waypoints, jumps, ...).
    """

    controller: str
    joint_names: tuple[str, ...]
    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray | None
    rate: float
    initial_positions: np.ndarray
    initial_velocities: np.ndarray
    waypoint_indices: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    waypoint_times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    dropped: tuple[int, ...] = ()
    jumps: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    samples: JointStateSamples | None = None
    times_ns: np.ndarray | None = None
    events: tuple[str, ...] = ()

    def __len__(self) -> int:
        return int(self.times.shape[0])

    def __repr__(self) -> str:
        return (
            f"Replay({self.controller}, updates={len(self)}, joints={self.n_joints}, duration={self.duration:.4f} s, "
            f"dropped={list(self.dropped)})"
        )

    @property
    def n_joints(self) -> int:
        return int(self.positions.shape[1])

    @property
    def duration(self) -> float:
        """Time of the last update [s] (0 when there is none)."""
        return float(self.times[-1]) if len(self) else 0.0

    @property
    def velocity_reported(self) -> np.ndarray:
        """Per update, whether the controller reported velocities, shape (m,)."""
        return np.all(np.isfinite(self.velocities), axis=1)

    def state(self, t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities held at time(s) ``t`` [s] (the latest update at or before ``t``)."""
        t_arr = np.atleast_1d(np.asarray(t, dtype=float))
        k = np.searchsorted(self.times, t_arr, side="right") - 1
        if len(self.times) == 0:  # no update at all (every waypoint dropped): the initial state is held
            q = np.repeat(self.initial_positions[None, :], t_arr.size, axis=0)
            v = np.repeat(self.initial_velocities[None, :], t_arr.size, axis=0)
            return (q[0], v[0]) if np.ndim(t) == 0 else (q, v)
        q = np.where((k < 0)[:, None], self.initial_positions, self.positions[np.maximum(k, 0)])
        v = np.where((k < 0)[:, None], self.initial_velocities, self.velocities[np.maximum(k, 0)])
        if np.ndim(t) == 0:
            return q[0], v[0]
        return q, v

    def to_trajectory(self) -> Trajectory:
        """The update stream as a linear :class:`Trajectory` (initial state at t=0 first; at repeated times the
        last update wins)."""
        t = np.concatenate([[0.0], self.times])
        q = np.vstack([self.initial_positions[None, :], self.positions])
        keep = np.append(np.diff(t) > 0, True)
        if keep.sum() < 2:
            raise InvalidInputError("replay", f"{len(self)} updates", "updates at two or more distinct times")
        return Trajectory(t[keep], q[keep], joint_names=self.joint_names)

    def to_dict(self) -> dict[str, Any]:
        """Plain lists for JSON (NaN becomes None)."""

        def clean(a: np.ndarray | None) -> Any:
            if a is None:
                return None
            obj = a.astype(object)
            obj[~np.isfinite(a)] = None
            return obj.tolist()

        out: dict[str, Any] = {
            "controller": self.controller,
            "joint_names": list(self.joint_names),
            "rate": self.rate,
            "times": self.times.tolist(),
            "positions": self.positions.tolist(),
            "velocities": clean(self.velocities),
            "accelerations": clean(self.accelerations),
            "initial_positions": self.initial_positions.tolist(),
            "initial_velocities": self.initial_velocities.tolist(),
            "waypoint_indices": self.waypoint_indices.tolist(),
            "waypoint_times": self.waypoint_times.tolist(),
            "dropped": list(self.dropped),
            "jumps": self.jumps.tolist(),
            "events": list(self.events),
        }
        if self.times_ns is not None:
            out["times_ns"] = self.times_ns.tolist()
        if self.samples is not None:
            out["samples"] = {
                "rate": self.samples.rate,
                "times": self.samples.times.tolist(),
                "positions": self.samples.positions.tolist(),
                "velocities": clean(self.samples.velocities),
            }
        return out

    def save(self, path: str | Path) -> list[Path]:
        """Write the streams: ``.json`` (everything), ``.npz`` (arrays) or ``.csv`` (two files: ``<stem>.csv`` with
        the updates and ``<stem>_joint_states.csv`` with the samples). Returns the paths written."""
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix == ".json":
            path.write_text(json.dumps(self.to_dict()))
            return [path]
        if suffix == ".npz":
            arrays: dict[str, np.ndarray] = {
                "joint_names": np.array(self.joint_names),
                "times": self.times,
                "positions": self.positions,
                "velocities": self.velocities,
                "initial_positions": self.initial_positions,
                "waypoint_indices": self.waypoint_indices,
                "waypoint_times": self.waypoint_times,
                "dropped": np.array(self.dropped, dtype=int),
            }
            if self.accelerations is not None:
                arrays["accelerations"] = self.accelerations
            if self.times_ns is not None:
                arrays["times_ns"] = self.times_ns
            if self.samples is not None:
                arrays["sample_times"] = self.samples.times
                arrays["sample_positions"] = self.samples.positions
                arrays["sample_velocities"] = self.samples.velocities
            np.savez(path, **arrays)
            return [path]
        if suffix == ".csv":
            written = [path]
            _write_csv(path, self.times, self.positions, self.velocities, self.joint_names, self.accelerations)
            if self.samples is not None:
                side = path.with_name(f"{path.stem}_joint_states.csv")
                _write_csv(side, self.samples.times, self.samples.positions, self.samples.velocities, self.joint_names)
                written.append(side)
            return written
        raise InvalidInputError("path", str(path), "a file ending in .csv, .json or .npz")


def _write_csv(
    path: Path,
    times: np.ndarray,
    q: np.ndarray,
    v: np.ndarray,
    names: Sequence[str],
    a: np.ndarray | None = None,
) -> None:
    columns = ["time"] + [f"{n}.pos" for n in names] + [f"{n}.vel" for n in names]
    blocks = [times[:, None], q, v]
    if a is not None:
        columns += [f"{n}.acc" for n in names]
        blocks.append(a)
    np.savetxt(path, np.hstack(blocks), delimiter=",", header=",".join(columns), comments="", fmt="%.17g")
