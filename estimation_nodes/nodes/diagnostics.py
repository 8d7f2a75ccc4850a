"""The one status a node publishes on /diagnostics."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node


def status_array(node: Node, title: str, values: Mapping[str, Any],
                 problems: Sequence[str], error: bool = False) -> DiagnosticArray:
    """``node``'s status named ``<node name>: title``: WARN with the problems as its message
    when there are any (ERROR with ``error``: the node cannot do its job), OK otherwise; the
    values as key-value pairs; stamped now."""
    level = DiagnosticStatus.ERROR if error else \
        DiagnosticStatus.WARN if problems else DiagnosticStatus.OK
    status = DiagnosticStatus(
        level=level,
        name=f"{node.get_name()}: {title}",
        message="; ".join(problems) or "ok",
        hardware_id=node.get_fully_qualified_name(),
        values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])
    array = DiagnosticArray(status=[status])
    array.header.stamp = node.get_clock().now().to_msg()
    return array
