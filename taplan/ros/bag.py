"""Record runs as rosbag2 MCAP files and read them back (``mcap`` + ``mcap-ros2-support``, no ROS needed).

A bag is what ``ros2 bag record -s mcap`` writes: profile ``ros2``, one channel per topic with ``cdr`` messages
and the ``.msg`` text as its ``ros2msg`` schema, log times in nanoseconds of the wall clock. ``ros2 bag info``
and ``ros2 bag play`` read taplan's bags, and taplan reads a real robot's bags of the same topics.

:func:`read_run` turns a bag into the streams ``taplan check`` reports on: the commanded and measured joint
streams per arm (in model joint order), the heartbeat times and the FSM states.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from taplan import api
from taplan.errors import ConfigError, InvalidInputError, UnknownNameError
from taplan.reference.replay import JointStateSamples
from taplan.ros.msg_definitions import FSM_STATE_TOPIC, MESSAGE_DEFINITIONS
from taplan.ros.sensor_fields import SENSOR_TYPES

__all__ = ["BagWriter", "RecordedRun", "read_messages", "read_recording", "read_run"]


def _ros_dict(msg_type: str, fields: dict[str, Any], stamp_ns: int) -> dict[str, Any]:
    if msg_type == api.JOINT_STATE:
        stamp = fields.get("stamp")
        seconds = stamp_ns * 1e-9 if stamp is None else float(stamp)
        sec = math.floor(seconds)
        return {
            "header": {"stamp": {"sec": int(sec), "nanosec": int((seconds - sec) * 1e9)}, "frame_id": ""},
            "name": list(fields.get("name", [])),
            "position": [float(v) for v in fields.get("position", [])],
            "velocity": [float(v) for v in fields.get("velocity", [])],
            "effort": [float(v) for v in fields.get("effort", [])],
        }
    if msg_type == api.FLOAT32_ARRAY:
        return {"layout": {"dim": [], "data_offset": 0}, "data": [float(v) for v in fields["data"]]}
    if msg_type in SENSOR_TYPES:
        return _sensor_ros_dict(msg_type, fields, stamp_ns)
    return dict(fields)


_ROI = ("x_offset", "y_offset", "height", "width", "do_rectify")


def _sensor_ros_dict(msg_type: str, fields: dict[str, Any], stamp_ns: int) -> dict[str, Any]:
    """The ROS dict of an Image, CameraInfo or PointCloud2 given as taplan's plain fields (header from ``stamp``
    [s], else the log time, and ``frame_id``)."""
    stamp = fields.get("stamp")
    seconds = stamp_ns * 1e-9 if stamp is None else float(stamp)
    sec = math.floor(seconds)
    out: dict[str, Any] = {
        "header": {
            "stamp": {"sec": int(sec), "nanosec": min(int(round((seconds - sec) * 1e9)), 999_999_999)},
            "frame_id": str(fields.get("frame_id", "")),
        },
        "height": int(fields.get("height", 0)),
        "width": int(fields.get("width", 0)),
    }
    if msg_type.endswith("/Image"):
        out.update(
            encoding=str(fields.get("encoding", "")),
            is_bigendian=int(bool(fields.get("is_bigendian", 0))),
            step=int(fields.get("step", 0)),
            data=bytes(fields.get("data", b"")),
        )
    elif msg_type.endswith("/CameraInfo"):
        roi = fields.get("roi") or {}
        out.update(
            distortion_model=str(fields.get("distortion_model", "")),
            d=[float(v) for v in fields.get("d", [])],
            k=[float(v) for v in fields.get("k", [0.0] * 9)],
            r=[float(v) for v in fields.get("r", [0.0] * 9)],
            p=[float(v) for v in fields.get("p", [0.0] * 12)],
            binning_x=int(fields.get("binning_x", 0)),
            binning_y=int(fields.get("binning_y", 0)),
            roi={k: roi.get(k, False if k == "do_rectify" else 0) for k in _ROI},
        )
    else:
        out.update(
            fields=[
                {
                    "name": str(f["name"]),
                    "offset": int(f["offset"]),
                    "datatype": int(f["datatype"]),
                    "count": int(f.get("count", 1)),
                }
                for f in fields.get("fields", [])
            ],
            is_bigendian=bool(fields.get("is_bigendian", False)),
            point_step=int(fields.get("point_step", 0)),
            row_step=int(fields.get("row_step", 0)),
            data=bytes(fields.get("data", b"")),
            is_dense=bool(fields.get("is_dense", False)),
        )
    return out


class BagWriter:
    """Writes every recorded message into a rosbag2 MCAP file (a :class:`taplan.ros.dds.Recorder`).

    Args:
        path: Output ``.mcap`` file (overwritten).
    """

    def __init__(self, path: str | Path) -> None:
        from mcap_ros2.writer import Writer

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = open(self.path, "wb")  # noqa: SIM115 (closed in close())
        self._writer = Writer(self._stream)
        self._schemas: dict[str, Any] = {}
        self.count = 0

    def record(self, topic: str, msg_type: str, fields: dict[str, Any], time_ns: int) -> None:
        """Append one message logged at ``time_ns`` (wall clock, nanoseconds)."""
        schema = self._schemas.get(msg_type)
        if schema is None:
            if msg_type not in MESSAGE_DEFINITIONS:
                raise ConfigError(f"cannot record {msg_type!r}; supported: {sorted(MESSAGE_DEFINITIONS)}")
            definition = MESSAGE_DEFINITIONS[msg_type]
            schema = self._schemas[msg_type] = self._writer.register_msgdef(msg_type, definition)
        self._writer.write_message(topic, schema, _ros_dict(msg_type, fields, time_ns), log_time=int(time_ns))
        self.count += 1

    def close(self) -> None:
        """Finish the MCAP file (its summary and index); the bag is unreadable before."""
        if not self._stream.closed:
            self._writer.finish()
            self._stream.close()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_messages(path: str | Path, topics: list[str] | None = None) -> list[tuple[str, int, Any]]:
    """``(topic, log time [ns], decoded message)`` of every message in the bag, in log-time order."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    path = Path(path)
    if not path.is_file():
        raise InvalidInputError("bag", str(path), "an existing .mcap file")
    try:
        with open(path, "rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            decoded = reader.iter_decoded_messages(topics=topics, log_time_order=True)
            return [(channel.topic, message.log_time, msg) for _, channel, message, msg in decoded]
    except Exception as exc:  # the mcap readers raise many kinds on a damaged file
        raise InvalidInputError(
            "bag", str(path), f"a readable rosbag2 MCAP file ({type(exc).__name__}: {exc})"
        ) from exc


@dataclass
class RecordedRun:
    """The joint streams and heartbeats of a recorded run, times in [s] from the first message.

    Attributes:
        commanded: Per side, the ``/api/{side}_arm/joint_cmd`` stream (positions in l/r_joint1..7 order).
        measured: Per side, the ``/{side}_arm/joint_states`` stream.
        heartbeats: Times of ``/api/fsm/enable`` messages with data > 0.
        disables: Times of ``/api/fsm/enable`` messages with data <= 0.
        fsm_states: ``(time, state)`` of ``/fsm_state``.
        rejected: Messages that could not be read as their arm's joint states (wrong names, lengths, NaN).
        start_ns: Log time of the first message [ns].
    """

    commanded: dict[str, JointStateSamples] = field(default_factory=dict)
    measured: dict[str, JointStateSamples] = field(default_factory=dict)
    heartbeats: np.ndarray = field(default_factory=lambda: np.zeros(0))
    disables: np.ndarray = field(default_factory=lambda: np.zeros(0))
    fsm_states: list[tuple[float, int]] = field(default_factory=list)
    rejected: int = 0
    start_ns: int = 0

    @property
    def heartbeat_gaps(self) -> np.ndarray:
        """Intervals between consecutive heartbeats [s]."""
        return np.diff(self.heartbeats)

    def stream(self, kind: str) -> JointStateSamples:
        """Both arms' ``"commanded"`` or ``"measured"`` stream on the first arm's times.

        Each message of the other arm is paired with the first arm's message nearest in log time (a client sends
        both arms' commands in the same tick); interpolating would add position noise from the log times' jitter.
        """
        streams = self.commanded if kind == "commanded" else self.measured
        if not streams:
            raise InvalidInputError("bag", f"no {kind} joint stream", "a bag with /api/*_arm/joint_cmd or joint_states")
        sides = [s for s in api.SIDES if s in streams]
        base = streams[sides[0]]
        positions = [base.positions]
        names: list[str] = list(base.joint_names or ())
        for side in sides[1:]:
            other = streams[side]
            positions.append(other.positions[_nearest(other.times, base.times)])
            names += list(other.joint_names or ())
        q = np.hstack(positions)
        return JointStateSamples(base.times, q, np.full_like(q, np.nan), base.rate, None, tuple(names))


def _nearest(times: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Index of the element of sorted ``times`` nearest to each of ``at``."""
    right = np.clip(np.searchsorted(times, at), 1, len(times) - 1)
    left = right - 1
    return np.where(np.abs(times[left] - at) <= np.abs(times[right] - at), left, right)


def _samples(times: list[float], positions: list[np.ndarray], side: str) -> JointStateSamples | None:
    if len(times) < 2:
        return None
    t = np.asarray(times)
    order = np.argsort(t, kind="stable")
    t = t[order]
    q = np.asarray(positions)[order]
    rate = 1.0 / float(np.median(np.diff(t))) if np.median(np.diff(t)) > 0 else 1.0
    names = tuple(api.ARM_JOINT_NAMES[side])
    return JointStateSamples(t, q, np.full_like(q, np.nan), rate, None, names)


def read_run(path: str | Path) -> RecordedRun:
    """The commanded and measured joint streams, heartbeats and FSM states of a recorded run."""
    messages = read_messages(path)
    if not messages:
        raise InvalidInputError("bag", str(path), "a bag with messages")
    start = messages[0][1]
    run = RecordedRun(start_ns=start)
    streams: dict[tuple[str, str], tuple[list[float], list[np.ndarray]]] = {}
    beats: list[float] = []
    offs: list[float] = []
    topics = {api.Topics.joint_cmd(s): ("commanded", s) for s in api.SIDES}
    topics.update({api.Topics.joint_states(s): ("measured", s) for s in api.SIDES})
    for topic, log_ns, msg in messages:
        t = (log_ns - start) * 1e-9
        if topic in topics:
            kind, side = topics[topic]
            try:
                q = api.parse_joint_state(side, list(msg.name), list(msg.position))
            except (InvalidInputError, UnknownNameError):
                run.rejected += 1
                continue
            entry = streams.setdefault((kind, side), ([], []))
            entry[0].append(t)
            entry[1].append(q)
        elif topic == api.Topics.ENABLE:
            (beats if float(msg.data) > 0 else offs).append(t)
        elif topic == FSM_STATE_TOPIC:
            run.fsm_states.append((t, int(msg.data)))
    for (kind, side), (times, positions) in streams.items():
        samples = _samples(times, positions, side)
        if samples is not None:
            (run.commanded if kind == "commanded" else run.measured)[side] = samples
    run.heartbeats = np.asarray(beats)
    run.disables = np.asarray(offs)
    return run


def read_recording(path: str | Path, stream: str = "measured") -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """A bag as a recorded demonstration: ``(times [s] from the first sample, positions [rad] (k, n), joint names)``
    of its ``"measured"`` (``/{side}_arm/joint_states``) or ``"commanded"`` (``/api/*_arm/joint_cmd``) stream, both
    arms on the first arm's log times (:meth:`RecordedRun.stream`); the input of
    :func:`taplan.timing.time_demonstration`, like :func:`taplan.timing.load_recording` for a CSV."""
    if stream not in ("measured", "commanded"):
        raise InvalidInputError("stream", stream, "'measured' or 'commanded'")
    samples = read_run(path).stream(stream)
    names = tuple(samples.joint_names or ())
    return samples.times - samples.times[0], np.asarray(samples.positions, dtype=float), names
