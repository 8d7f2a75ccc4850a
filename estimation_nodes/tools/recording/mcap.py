"""Runs kept as ROS 2 MCAP files: every topic's CDR bytes with its .msg schema.

The files follow the layout rosbag2's MCAP storage writes (profile ``ros2``,
schemas in ``ros2msg`` encoding, messages in ``cdr``), so ``ros2 bag info``,
Foxglove and the ``mcap`` tools open them. The estimator's parameters of the
run are kept as MCAP metadata (``estimation_nodes``), so a replay needs
nothing but the file. Needs the ``record`` extra (mcap, mcap-ros2-support).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from estimation_nodes.params import topics
from estimation_nodes.tools.installed import share_dirs
from estimation_nodes.tools.recording.completeness import SequenceGaps
from estimation_nodes.tools.recording.run_record import RunRecord

METADATA_NAME = "estimation_nodes"
_SEPARATOR = "=" * 80
_PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
    "uint32", "int64", "uint64", "string", "wstring",
}


class RecordingError(Exception):
    """A recording that cannot be written or read; the message says why in one line."""


def _msg_text(package: str, name: str) -> str:
    for share in share_dirs():
        path = share / package / "msg" / f"{name}.msg"
        if path.is_file():
            return path.read_text(encoding="utf-8")
    raise RecordingError(f"no definition of {package}/msg/{name} under {share_dirs()}")


def _field_types(text: str, package: str) -> list[tuple[str, str]]:
    """(package, name) of every non-primitive field type in a .msg text."""
    found = []
    for line in text.splitlines():
        tokens = line.split("#", 1)[0].split()
        if len(tokens) < 2:
            continue
        # "int32[] data", "string<=8 name", "Pose pose"; array and bound suffixes go.
        type_text = re.split(r"[\[<]", tokens[0], maxsplit=1)[0]
        if type_text in _PRIMITIVES:
            continue
        package_name, _, name = type_text.rpartition("/")
        found.append((package_name.split("/")[0] or package, name))
    return found


def schema_text(type_name: str) -> str:
    """The ros2msg schema of a type: its .msg text, then each type it uses, once."""
    package, _, name = type_name.split("/")
    text = _msg_text(package, name)
    parts, seen = [text], {(package, name)}
    pending = _field_types(text, package)
    while pending:
        dep = pending.pop(0)
        if dep in seen:
            continue
        seen.add(dep)
        dep_text = _msg_text(*dep)
        parts.append(f"{_SEPARATOR}\nMSG: {dep[0]}/{dep[1]}\n{dep_text}")
        pending.extend(_field_types(dep_text, dep[0]))
    return "\n".join(parts)


class McapRunWriter:
    """Writes raw CDR messages of the run's topics into one MCAP file."""

    def __init__(self, path: Path, topics: dict[str, str], metadata: dict[str, str]) -> None:
        try:
            from mcap.writer import Writer
        except ImportError:
            raise RecordingError("recording needs the 'record' extra: "
                                 "pip install 'estimation_nodes[record]'") from None
        if path.suffix != ".mcap":
            raise RecordingError(f"--record: {path} should end in .mcap")
        if not path.parent.is_dir():
            raise RecordingError(f"--record: folder {path.parent} does not exist")
        try:
            self._stream = path.open("wb")
        except OSError as error:
            raise RecordingError(f"--record: cannot write {path}: {error}") from None
        self._writer = Writer(self._stream)
        self._writer.start(profile="ros2", library="estimation_nodes")
        self._channels: dict[str, int] = {}
        self._sequence = 0
        #: What the recording lacks of what its publishers sent (completeness.py).
        self.gaps = SequenceGaps()
        for topic, type_name in topics.items():
            schema = self._writer.register_schema(
                name=type_name, encoding="ros2msg", data=schema_text(type_name).encode())
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding="cdr", schema_id=schema)
        self._writer.add_metadata(METADATA_NAME, metadata)

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int,
              sequence: int | None = None) -> None:
        """Add one raw message, ``sequence`` its publisher's number for it (None: unknown);
        a topic the file was not made with (/diagnostics, which only the live view serves)
        is skipped."""
        channel = self._channels.get(topic)
        if channel is None:
            return
        self.gaps.note(topic, sequence)
        self._sequence += 1
        self._writer.add_message(channel, log_time=log_time_ns, data=data,
                                 publish_time=publish_time_ns, sequence=self._sequence)

    def close(self) -> None:
        self._writer.finish()
        self._stream.close()


@dataclass
class Recording:
    """A recording read back: the run, and the metadata of estimation_nodes."""

    record: RunRecord
    metadata: dict[str, str]
    counts: dict[str, int]


def _base(topic: str) -> str:
    return topic.rsplit("/", 1)[-1]


def _add_decoded(record: RunRecord, topic: str, msg: Any, publish_time_ns: int) -> None:
    base = _base(topic)
    record.stamp(base, publish_time_ns)
    if base in topics.INPUTS:
        record.add_event(base, tuple(msg.data) if hasattr(msg, "layout") else msg.data)
    elif base == topics.TRUE_POSITION:
        record.truth.append(msg.data)
    elif base == topics.TRUE_STATE:
        record.true_states.append(np.asarray(msg.data, dtype=np.float64))
    elif base in (topics.BELIEF_PREDICTED, topics.BELIEF):
        values = np.asarray(msg.data, dtype=np.float64)
        (record.predicted if base == topics.BELIEF_PREDICTED else record.corrected).append(values)
    elif base in (topics.KALMAN_ESTIMATE, topics.KALMAN_ESTIMATE_PREDICTED):
        estimate = (msg.pose.position.x, msg.covariance[0])
        (record.kalman if base == topics.KALMAN_ESTIMATE else record.kalman_predicted).append(
            estimate)
    elif base in (topics.KALMAN_STATE, topics.KALMAN_STATE_PREDICTED):
        n = msg.layout.dim[1].size
        values = np.asarray(msg.data, dtype=np.float64)
        state = (values[:n], values[n:].reshape(n, n))
        (record.states if base == topics.KALMAN_STATE else record.states_predicted).append(
            state)


def read_recording(path: Path) -> Recording:
    """Decode every message of an MCAP recording into a RunRecord, in publish-time order.

    Publish time (the writer's source timestamp) rather than the time the
    recorder received it: under load the recorder can take a command after
    the observation it caused, and the replay must see them as they happened.
    """
    try:
        from mcap.exceptions import McapError
        from mcap.reader import make_reader
        from mcap_ros2.decoder import DecoderFactory
    except ImportError:
        raise RecordingError("reading recordings needs the 'record' extra: "
                             "pip install 'estimation_nodes[record]'") from None
    if not path.is_file():
        raise RecordingError(f"{path} is not a file")
    record = RunRecord()
    counts: dict[str, int] = {}
    metadata: dict[str, str] = {}
    try:
        with path.open("rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            messages = [(message.publish_time, message.log_time, channel.topic, decoded)
                        for _schema, channel, message, decoded
                        in reader.iter_decoded_messages(log_time_order=True)]
            messages.sort(key=lambda item: item[:2])
            for publish_time, _log, topic, decoded in messages:
                counts[topic] = counts.get(topic, 0) + 1
                _add_decoded(record, topic, decoded, publish_time)
            for entry in reader.iter_metadata():
                if entry.name == METADATA_NAME:
                    metadata = dict(entry.metadata)
    except (McapError, ValueError, EOFError) as error:
        raise RecordingError(f"{path} is not a readable MCAP recording: {error}") from None
    return Recording(record, metadata, counts)
