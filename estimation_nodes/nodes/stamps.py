"""Header stamps as integer nanoseconds, the one unit the nodes and tools compare them in."""

from __future__ import annotations

import time
from typing import Any

NS_PER_S = 1_000_000_000


def stamp_ns(stamp: Any) -> int:
    """A builtin_interfaces/Time in ns."""
    return stamp.sec * NS_PER_S + stamp.nanosec


def stamp_or_none(stamp: Any) -> int | None:
    """A stamp in ns; None for an unset (zero) one."""
    return stamp_ns(stamp) or None


def set_stamp(header: Any, ns: int, frame_id: str) -> None:
    """Stamp ``header`` with ``ns`` and name its frame."""
    header.stamp.sec, header.stamp.nanosec = divmod(ns, NS_PER_S)
    header.frame_id = frame_id


def published_ns(info: dict) -> int:
    """When the publisher wrote a message, from a subscription callback's message info: its
    DDS source timestamp (the order of events across topics and hosts), else when it was
    received, else now."""
    return info.get("source_timestamp") or info.get("received_timestamp") or time.time_ns()
