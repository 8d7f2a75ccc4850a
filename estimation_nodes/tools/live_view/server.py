"""A live view of the graph for Foxglove: a Foxglove WebSocket server fed raw ROS 2 messages.

Each topic is a channel of the CDR bytes as DDS delivered them, with the
topic's ``ros2msg`` schema (the text the recorder writes) and message encoding
``cdr``, so the Foxglove app decodes them as ROS messages; nothing is
deserialized here. ``write`` has the signature of the MCAP recorder's, so the
demo's monitor feeds both alike. Needs the ``foxglove`` extra (foxglove-sdk),
imported only when a view starts.

foxglove-sdk's server speaks the WebSocket subprotocol ``foxglove.sdk.v1``
(the same messages as ``foxglove.websocket.v1``, which it refuses): the current
Foxglove app connects; clients that offer only the old name get HTTP 400.
"""

from __future__ import annotations

import re
import threading
from typing import Any

from estimation_nodes.params.specs import FOXGLOVE_HOST
from estimation_nodes.tools.recording.mcap import schema_text

#: Messages queued per client before the oldest is dropped (foxglove-sdk's default is 1024).
#: A client that stops reading costs this many messages of memory, never a blocked
#: ``write``: 64 is five steps of a tile-world run, enough for a reader that briefly lags,
#: while 1024 beliefs of a 1e5-cell world would hold 800 MB.
BACKLOG = 64
#: Seconds ``close`` waits for the server to stop. foxglove-sdk's stop waits until every
#: client has closed gracefully, and a client that does not read can hold it far longer than
#: a process should take to end (docs/benchmarks.md); past this grace the stop goes on in a
#: background thread and this process may end.
CLOSE_GRACE = 1.0
_ADDRESS = re.compile(r"(?:(?:\[(?P<ipv6>[^\]]+)\]|(?P<host>[^:\[\]\s]+)):)?(?P<port>\d{1,5})")


class LiveViewError(Exception):
    """A live view that cannot start; the message says why in one line."""


def parse_address(text: str) -> tuple[str, int]:
    """``[HOST:]PORT`` (an IPv6 host in brackets) as (host, port); port 0 takes a free one."""
    match = _ADDRESS.fullmatch(text.strip())
    if match is None or int(match["port"]) > 65535:
        raise LiveViewError(f"expected [HOST:]PORT with PORT in 0..65535 (8765, "
                            f"0.0.0.0:8765, [::1]:8765), got {text!r}")
    return match["ipv6"] or match["host"] or FOXGLOVE_HOST, int(match["port"])


def websocket_url(host: str, port: int) -> str:
    return f"ws://[{host}]:{port}" if ":" in host else f"ws://{host}:{port}"


class LiveView:
    """A Foxglove WebSocket server with one CDR channel per topic.

    ``topics`` maps each topic's name as clients should see it (resolved, with
    namespace and remaps) to its ROS type ('std_msgs/msg/Float64MultiArray').
    """

    def __init__(self, host: str, port: int, topics: dict[str, str],
                 name: str = "estimation_nodes") -> None:
        try:
            import foxglove
        except ImportError:
            raise LiveViewError("the live view needs the 'foxglove' extra: "
                                "pip install 'estimation_nodes[foxglove]'") from None
        # A context of our own: the SDK's global one would also serve channels that
        # other code in this process logs to. Kept: when it is dropped, the SDK closes
        # every channel made in it ("Cannot log on closed channel").
        self._context = context = foxglove.Context()
        try:
            self._server = foxglove.start_server(
                name=name, host=host, port=port, context=context, message_backlog_size=BACKLOG)
        except RuntimeError as error:
            reason = str(error).removeprefix("FoxgloveError: ")
            raise LiveViewError(f"cannot serve on {websocket_url(host, port)}: {reason}") from None
        self.url = websocket_url(host, self._server.port)
        self._channels = {topic: self._channel(foxglove, context, topic, type_name)
                          for topic, type_name in topics.items()}

    @staticmethod
    def _channel(foxglove: Any, context: Any, topic: str, type_name: str) -> Any:
        schema = foxglove.Schema(name=type_name, encoding="ros2msg",
                                 data=schema_text(type_name).encode())
        return foxglove.Channel(topic, schema=schema, message_encoding="cdr", context=context)

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int,
              sequence: int | None = None) -> None:
        """Hand one raw message to every client subscribed to ``topic``; never blocks.

        Clients see ``log_time_ns`` (when the message arrived here) as its time, which is
        Foxglove's "receive time". A topic without a channel is skipped: the view serves
        the topics it was made with.
        """
        channel = self._channels.get(topic)
        if channel is not None:
            channel.log(data, log_time=log_time_ns)

    def close(self) -> None:
        """Stop serving, waiting at most CLOSE_GRACE seconds for slow clients."""
        for channel in self._channels.values():
            channel.close()
        stopping = threading.Thread(target=self._server.stop, name="foxglove-stop", daemon=True)
        stopping.start()
        stopping.join(CLOSE_GRACE)
