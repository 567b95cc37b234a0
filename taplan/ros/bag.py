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
from taplan.ros.sensor_fields import SENSOR_TYPES, sensor_body

__all__ = ["BagWriter", "OFFERED_QOS", "RecordedRun", "bag_files", "read_messages", "read_recording", "read_run"]


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
        **sensor_body(msg_type, fields),
    }
    return out


# rclpy's default publisher QoS (reliable, volatile, keep-last 10), as ``ros2 bag record`` stores the offered
# profiles of a topic's publishers: rosbag2's YAML (history 1 = keep last, reliability 1 = reliable, durability 2 =
# volatile, liveliness 1 = automatic, durations "infinite")
_INFINITE = "\n    sec: 2147483647\n    nsec: 4294967295"
OFFERED_QOS = (
    "- history: 1\n  depth: 10\n  reliability: 1\n  durability: 2\n  deadline:"
    + _INFINITE
    + "\n  lifespan:"
    + _INFINITE
    + "\n  liveliness: 1\n  liveliness_lease_duration:"
    + _INFINITE
    + "\n  avoid_ros_namespace_conventions: false"
)
SPLIT_EVERY = 1.0  # [s] of log time per file of a bag directory: a killed recorder loses at most the last second


class _McapFile:
    """One rosbag2 MCAP file: profile ros2, ``ros2msg`` schemas, ``cdr`` channels with ``offered_qos_profiles``."""

    def __init__(self, path: Path) -> None:
        from mcap.writer import CompressionType, Writer

        self.path = path
        self._stream = open(path, "wb")  # noqa: SIM115 (closed in close())
        self._writer = Writer(self._stream, compression=CompressionType.NONE)
        self._writer.start(profile="ros2", library="taplan")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self.counts: dict[str, int] = {}
        self.start_ns: int | None = None
        self.end_ns = 0

    def write(self, topic: str, msg_type: str, data: bytes, time_ns: int) -> None:
        schema = self._schemas.get(msg_type)
        if schema is None:
            definition = MESSAGE_DEFINITIONS[msg_type].encode()
            schema = self._schemas[msg_type] = self._writer.register_schema(msg_type, "ros2msg", definition)
        channel = self._channels.get(topic)
        if channel is None:
            metadata = {"offered_qos_profiles": OFFERED_QOS}
            channel = self._channels[topic] = self._writer.register_channel(topic, "cdr", schema, metadata)
        self._writer.add_message(channel, log_time=time_ns, data=data, publish_time=time_ns)
        self.counts[topic] = self.counts.get(topic, 0) + 1
        self.start_ns = time_ns if self.start_ns is None else min(self.start_ns, time_ns)
        self.end_ns = max(self.end_ns, time_ns)

    def close(self) -> None:
        if not self._stream.closed:
            self._writer.finish()
            self._stream.close()


class BagWriter:
    """Writes every recorded message into a rosbag2 bag (a :class:`taplan.ros.dds.Recorder`).

    ``path`` ending in ``.mcap``: one MCAP file (readable once closed). Any other ``path``: a rosbag2 *directory*
    as ``ros2 bag record -s mcap`` writes it (``metadata.yaml`` + ``<name>_<i>.mcap``, storage ``mcap``,
    serialization ``cdr``, ``offered_qos_profiles`` per topic), split every ``split`` seconds of log time: each
    finished file is complete and listed in ``metadata.yaml`` at once, so a recorder killed with SIGKILL leaves a
    bag that ROS 2 tools and rosbags open, up to its last finished second.

    Messages are stored as the CDR bytes that went on the wire when the transport passes them (``data``), with the
    log time the transport stamped them with; otherwise ``fields`` are serialised here.

    Args:
        path: ``.mcap`` file or bag directory (created; an existing directory must be empty).
        split: Seconds of log time per file of a bag directory.
    """

    def __init__(self, path: str | Path, *, split: float = SPLIT_EVERY) -> None:
        self.path = Path(path)
        self.directory = self.path.suffix.lower() != ".mcap"
        if not (isinstance(split, (int, float)) and math.isfinite(split) and split > 0):
            raise InvalidInputError("split", split, "a positive duration [s]")
        self.split_ns = int(split * 1e9)
        if self.directory:
            if self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir())):
                raise InvalidInputError("bag", str(self.path), "a new or empty directory (or a .mcap file)")
            self.path.mkdir(parents=True, exist_ok=True)
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        self._done: list[_McapFile] = []
        self._file: _McapFile | None = None
        self._types: dict[str, str] = {}
        self._encoders: dict[str, Any] = {}
        self.count = 0
        if self.directory:
            self._write_metadata()

    def _next_file(self) -> _McapFile:
        if self.directory:
            return _McapFile(self.path / f"{self.path.name}_{len(self._done)}.mcap")
        return _McapFile(self.path)

    def _encode(self, msg_type: str, fields: dict[str, Any], time_ns: int) -> bytes:
        encoder = self._encoders.get(msg_type)
        if encoder is None:
            from mcap_ros2._dynamic import serialize_dynamic

            encoder = self._encoders[msg_type] = serialize_dynamic(msg_type, MESSAGE_DEFINITIONS[msg_type])[msg_type]
        return encoder(_ros_dict(msg_type, fields, time_ns))

    def record(
        self, topic: str, msg_type: str, fields: dict[str, Any], time_ns: int, data: bytes | None = None
    ) -> None:
        """Append one message logged at ``time_ns`` (wall clock [ns]): its wire bytes ``data``, else ``fields``."""
        if msg_type not in MESSAGE_DEFINITIONS:
            raise ConfigError(f"cannot record {msg_type!r}; supported: {sorted(MESSAGE_DEFINITIONS)}")
        payload = self._encode(msg_type, fields, time_ns) if data is None else bytes(data)
        current = self._file
        if (
            current is not None
            and self.directory
            and current.start_ns is not None
            and time_ns - current.start_ns >= self.split_ns
        ):
            current.close()
            self._done.append(current)
            self._write_metadata()
            current = None
        if current is None:
            current = self._file = self._next_file()
        current.write(topic, msg_type, payload, int(time_ns))
        self._types[topic] = msg_type
        self.count += 1

    def _write_metadata(self) -> None:
        """``metadata.yaml`` of the finished files (rosbag2 format version 5), written atomically."""
        files = [f for f in self._done if f.start_ns is not None]
        counts: dict[str, int] = {}
        for f in files:
            for topic, n in f.counts.items():
                counts[topic] = counts.get(topic, 0) + n
        start = min((f.start_ns for f in files), default=0)  # type: ignore[type-var]
        end = max((f.end_ns for f in files), default=0)
        lines = [
            "rosbag2_bagfile_information:",
            "  version: 5",
            "  storage_identifier: mcap",
            f"  duration:\n    nanoseconds: {max(0, end - start)}",
            f"  starting_time:\n    nanoseconds_since_epoch: {start}",
            f"  message_count: {sum(counts.values())}",
            "  topics_with_message_count:" + ("" if counts else " []"),
        ]
        qos = OFFERED_QOS.replace("\n", "\\n").replace('"', '\\"')
        for topic, n in counts.items():
            lines += [
                "    - topic_metadata:",
                f"        name: {topic}",
                f"        type: {self._types[topic]}",
                "        serialization_format: cdr",
                f'        offered_qos_profiles: "{qos}"',
                f"      message_count: {n}",
            ]
        lines += ['  compression_format: ""', '  compression_mode: ""']
        lines.append("  relative_file_paths:" + ("" if files else " []"))
        lines += [f"    - {f.path.name}" for f in files]
        lines.append("  files:" + ("" if files else " []"))
        for f in files:
            lines += [
                f"    - path: {f.path.name}",
                f"      starting_time:\n        nanoseconds_since_epoch: {f.start_ns}",
                f"      duration:\n        nanoseconds: {f.end_ns - (f.start_ns or 0)}",
                f"      message_count: {sum(f.counts.values())}",
            ]
        temporary = self.path / "metadata.yaml.tmp"
        temporary.write_text("\n".join(lines) + "\n")
        temporary.replace(self.path / "metadata.yaml")

    def close(self) -> None:
        """Finish the current file (its summary and index) and, for a directory, ``metadata.yaml``."""
        if self._file is not None:
            self._file.close()
            self._done.append(self._file)
            self._file = None
        elif not self.directory and not self._done:  # an empty .mcap file is still a valid bag
            empty = self._next_file()
            empty.close()
            self._done.append(empty)
        if self.directory:
            self._write_metadata()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def bag_files(path: str | Path) -> list[Path]:
    """The MCAP files of a bag: the file itself, or those ``metadata.yaml`` of a bag directory lists."""
    path = Path(path)
    if path.is_dir():
        metadata = path / "metadata.yaml"
        if not metadata.is_file():
            raise InvalidInputError("bag", str(path), "a rosbag2 directory with metadata.yaml, or a .mcap file")
        import yaml

        info = yaml.safe_load(metadata.read_text()).get("rosbag2_bagfile_information", {})
        return [path / name for name in info.get("relative_file_paths") or []]
    if not path.is_file():
        raise InvalidInputError("bag", str(path), "an existing .mcap file or rosbag2 directory")
    return [path]


def read_messages(path: str | Path, topics: list[str] | None = None) -> list[tuple[str, int, Any]]:
    """``(topic, log time [ns], decoded message)`` of every message in the bag, in log-time order."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out: list[tuple[str, int, Any]] = []
    for file in bag_files(path):
        try:
            with open(file, "rb") as stream:
                reader = make_reader(stream, decoder_factories=[DecoderFactory()])
                decoded = reader.iter_decoded_messages(topics=topics, log_time_order=True)
                out += [(channel.topic, message.log_time, msg) for _, channel, message, msg in decoded]
        except Exception as exc:  # the mcap readers raise many kinds on a damaged file
            raise InvalidInputError(
                "bag", str(file), f"a readable rosbag2 MCAP file ({type(exc).__name__}: {exc})"
            ) from exc
    out.sort(key=lambda m: m[1])
    return out


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

        Each message of the other arm is paired with the first arm's message sent in the same tick: in order when
        both arms have the same number of messages (±1) at matching times (a client sends both arms' commands in one
        tick), else the one nearest in log time; interpolating would add position noise from the log times' jitter.
        """
        streams = self.commanded if kind == "commanded" else self.measured
        if not streams:
            raise InvalidInputError("bag", f"no {kind} joint stream", "a bag with /api/*_arm/joint_cmd or joint_states")
        sides = [s for s in api.SIDES if s in streams]
        base = streams[sides[0]]
        positions = [base.positions]
        names: list[str] = list(base.joint_names or ())
        times = base.times
        for side in sides[1:]:
            other = streams[side]
            n = min(len(times), len(other.times))
            offsets = np.abs(other.times[:n] - times[:n])
            if abs(len(other.times) - len(times)) <= 1 and np.median(offsets) < 0.25 / base.rate:
                # sent in pairs (one tick, both arms): pair them in order. Nearest log time mispairs them when a
                # loaded sender is preempted between the two writes for more than half a period
                positions = [p[:n] for p in positions]
                times = times[:n]
                positions.append(other.positions[:n])
            else:
                positions.append(other.positions[_nearest(other.times, times)])
            names += list(other.joint_names or ())
        q = np.hstack(positions)
        return JointStateSamples(times, q, np.full_like(q, np.nan), base.rate, None, tuple(names))


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
