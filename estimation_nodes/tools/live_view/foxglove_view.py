"""foxglove_view: serve the package's topics of a running graph live to Foxglove.

For a graph started by hand (ros2 run, a launch file) rather than by
estimation_demo, which has ``--foxglove`` for its own runs. The node
subscribes raw to the topics by their relative names, so a namespace
(``--ros-args -r __ns:=/robot1``) and remaps apply as they do to the nodes it
watches, and hands the CDR bytes, untouched, to a Foxglove WebSocket server
(tools/live_view/server.py) under the names they resolved to.

It is one more subscriber on each topic: the commander's
``required_subscribers`` and the sensors' ``hold_until_matched`` count it.
"""

from __future__ import annotations

import importlib.util
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

from rclpy.node import Node

from estimation_nodes.nodes.parameters import ConfigurationError, declare_and_build
from estimation_nodes.nodes.process import main_for
from estimation_nodes.params import topics
from estimation_nodes.params.specs import FOXGLOVE_VIEW_SPECS
from estimation_nodes.tools.demo.monitor import message_class, observer_qos
from estimation_nodes.tools.live_view.server import LiveView, LiveViewError


class FoxgloveView(Node):
    """Subscribes raw to every topic of the package and serves them to Foxglove clients."""

    node_name = "foxglove_view"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.node_name, **kwargs)
        self._view: LiveView | None = None
        values, _ = declare_and_build(self, FOXGLOVE_VIEW_SPECS, lambda values: None)
        resolved = {topic: self.resolve_topic_name(topic) for topic in topics.LIVE_TOPIC_TYPES}
        try:
            view = LiveView(values["host"], values["port"],
                            {resolved[t]: n for t, n in topics.LIVE_TOPIC_TYPES.items()},
                            name=self.get_fully_qualified_name())
        except LiveViewError as error:
            raise ConfigurationError(f"host, port: {error}") from None
        self._view = view
        for topic, type_name in topics.LIVE_TOPIC_TYPES.items():
            self.create_subscription(message_class(type_name), topic,
                                     forwarder(view, resolved[topic]), observer_qos(topic),
                                     raw=True)
        self.get_logger().info(
            f"serving {len(resolved)} topics on {view.url} (in Foxglove: Open connection, "
            f"Foxglove WebSocket)")

    def destroy_node(self) -> None:
        if self._view is not None:
            self._view.close()
            self._view = None
        super().destroy_node()


def forwarder(view: LiveView, topic: str) -> Callable[[bytes, dict], None]:
    """A raw subscription's callback: each message to ``view`` as ``topic``, stamped with
    its arrival and its source time."""

    def on_raw(data: bytes, info: dict) -> None:
        received = time.time_ns()
        view.write(topic, data, received, info.get("source_timestamp") or received)

    return on_raw


def main(args: Sequence[str] | None = None) -> None:
    # Checked before rclpy starts: without the extra there is nothing to serve with.
    if importlib.util.find_spec("foxglove") is None:
        print("[FATAL] [foxglove_view]: needs the 'foxglove' extra: "
              "pip install 'estimation_nodes[foxglove]'", file=sys.stderr)
        sys.exit(2)
    main_for(FoxgloveView)(args)


if __name__ == "__main__":
    main()
