"""The QoS profiles of the graph's topics."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

#: Commands and readings: reliable, nothing dropped at the queue under bursts.
INPUT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

#: A laser's scans: best effort (takes best-effort and reliable publishers alike), and only
#: the newest kept, so a node busy with an update answers the latest scan next, never a
#: queue of stale ones (nodes/scan_gaps.py counts those it never saw).
NEWEST_SCAN_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)


def latched_qos(depth: int) -> QoSProfile:
    """Reliable and transient_local: a late subscriber still gets the last ``depth`` messages."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )
