"""Header stamps as integer nanoseconds, the one unit the nodes and tools compare them in."""

from __future__ import annotations

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
