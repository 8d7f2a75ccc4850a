"""Robots' own bags (ROS 1 ``.bag``, rosbag2 folders in MCAP or sqlite3) read through the
``rosbags`` library, as messages of this ROS 2's own types.

A ROS 1 message differs from its ROS 2 namesake in small ways (``Header.seq``, ``time`` as
secs/nsecs): each message is copied field by field, by name, into the rclpy class of its
ROS 2 type, and fields the ROS 2 type lacks are left out. ``estimation_play`` then
publishes them as any recording (tools/recording/play.py), and ``estimation_fuse`` reads
the same messages (tools/fusion/offline.py).
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from estimation_nodes.tools.recording.mcap import RecordingError


def is_bag(path: Path) -> bool:
    """A ROS 1 bag or a rosbag2 folder (one with metadata.yaml), which rosbags reads."""
    return path.suffix == ".bag" or (path.is_dir() and (path / "metadata.yaml").is_file())


def rclpy_class(type_name: str) -> type:
    """The rclpy class of 'pkg/msg/Name'; ``RecordingError`` when this install lacks it."""
    package, interface, name = type_name.split("/")
    try:
        return getattr(importlib.import_module(f"{package}.{interface}"), name)
    except (ImportError, AttributeError):
        raise RecordingError(f"message type {type_name} is not installed here") from None


def to_rclpy(source: Any, cls: type) -> Any:
    """``source`` (a rosbags message) as an instance of ``cls``, field by field."""
    msg = cls()
    for field, type_text in cls.get_fields_and_field_types().items():
        if not hasattr(source, field):
            continue
        value = getattr(source, field)
        setattr(msg, field, _converted(value, getattr(msg, field), type_text))
    return msg


def _converted(value: Any, current: Any, type_text: str) -> Any:
    if hasattr(current, "get_fields_and_field_types"):
        return to_rclpy(value, type(current))
    if type_text.startswith("sequence<") or "[" in type_text:
        element = type_text.removeprefix("sequence<").split(",")[0].split("[")[0].rstrip(">")
        if "/" in element:
            cls = rclpy_class(_with_msg(element))
            return [to_rclpy(item, cls) for item in value]
        if isinstance(value, np.ndarray):
            return value.tolist() if isinstance(current, list) else value
        return list(value)
    return value


def _with_msg(element: str) -> str:
    package, name = element.split("/")[0], element.split("/")[-1]
    return f"{package}/msg/{name}"


def bag_messages(path: Path, topics: set[str] | None = None, as_rclpy: bool = True,
                 left_out: dict[str, str] | None = None
                 ) -> Iterator[tuple[int, str, str, Any]]:
    """(receive time ns, topic, ROS 2 type name, rclpy message) in recorded order.

    A topic whose type this install lacks (a robot's own messages) is left out, not the
    bag: noted in ``left_out`` (topic -> type) where given. With ``as_rclpy`` False, each
    message as ``rosbags`` decoded it: the same field names and values (and a ROS 1
    message's extra fields), for a reader that reads fields by name and never publishes,
    which then skips the copy into rclpy's classes, the most costly part of reading
    (estimation_fuse)."""
    try:
        from rosbags.highlevel import AnyReader
    except ImportError:
        raise RecordingError("reading bags needs the rosbags library: pip install rosbags") \
            from None
    try:
        with AnyReader([path]) as reader:
            connections = [c for c in reader.connections
                           if topics is None or c.topic in topics]
            classes = _installed_classes(connections, left_out) if as_rclpy else {}
            if as_rclpy:
                connections = [c for c in connections if c.msgtype in classes]
            for connection, timestamp, raw in reader.messages(connections=connections):
                decoded = reader.deserialize(raw, connection.msgtype)
                yield (timestamp, connection.topic, connection.msgtype,
                       to_rclpy(decoded, classes[connection.msgtype]) if as_rclpy
                       else decoded)
    except RecordingError:
        raise
    except Exception as error:  # rosbags' own errors: a file that is not a bag it reads
        raise RecordingError(f"{path} is not a bag rosbags can read: {error}") from None


def left_out_notes(left_out: dict[str, str]) -> list[str]:
    """A line per topic ``bag_messages`` left out (``left_out``: topic -> type)."""
    return [f"{topic} left out: its type {type_name} is not installed here"
            for topic, type_name in sorted(left_out.items())]


def _installed_classes(connections: list, left_out: dict[str, str] | None) -> dict[str, type]:
    """The rclpy class of each connection's type that this install has; the others'
    topics noted in ``left_out``."""
    classes = {}
    for connection in connections:
        try:
            classes[connection.msgtype] = rclpy_class(connection.msgtype)
        except RecordingError:
            if left_out is not None:
                left_out[connection.topic] = connection.msgtype
    return classes

