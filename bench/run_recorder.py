"""A bench's recording of a node's run, checked by estimation_replay.

The bench's node subscribes raw to the inputs the node under test hears and the
outputs it publishes, and keeps each message with its publish (source) time, as
estimation_demo's recorder does; at the end the messages go to an MCAP file with
the node's parameters in its metadata, and ``estimation_replay`` runs on it: the
node's filter offline over the same inputs must publish the same outputs (EQUAL).
"""

from __future__ import annotations

import subprocess
import time
from pathlib import Path


class RunRecorder:
    """Raw subscriptions on ``node`` to ``topics`` ({topic: (message type name, QoS)})."""

    def __init__(self, node, topics: dict[str, tuple[str, object]]) -> None:
        from estimation_nodes.tools.demo.monitor import message_class

        self.types = {topic: name for topic, (name, _qos) in topics.items()}
        #: (topic, raw message, publish time in ns), in arrival order.
        self.recorded: list[tuple[str, bytes, int]] = []
        for topic, (name, qos) in topics.items():
            node.create_subscription(message_class(name), topic, self._keep(topic), qos,
                                     raw=True)

    def _keep(self, topic: str):
        from estimation_nodes.nodes.stamps import published_ns

        def keep(data: bytes, info) -> None:
            self.recorded.append((topic, data, published_ns(info)))
        return keep

    def sent(self, topic: str, type_name: str, msg, published_ns: int) -> None:
        """A message the bench itself published at ``published_ns`` (taken just before the
        publish call; its own subscription would not hear it)."""
        from rclpy.serialization import serialize_message

        self.types[topic] = type_name
        self.recorded.append((topic, serialize_message(msg), published_ns))

    def write_and_replay(self, path: Path, metadata: dict[str, str],
                         replay_executable: str) -> list[list[str]]:
        """Write the recording to ``path``, run estimation_replay on it; table rows."""
        from estimation_nodes.tools.recording.mcap import McapRunWriter

        writer = McapRunWriter(path, self.types, metadata)
        for topic, data, published_ns in self.recorded:
            writer.write(topic, data, published_ns, published_ns)
        writer.close()
        started = time.monotonic()
        replay = subprocess.run([replay_executable, str(path)], capture_output=True, text=True)
        print(replay.stdout + replay.stderr)
        verdict = (replay.stdout.strip().splitlines() or ["(no output)"])[-1]
        return [["recording", f"{path} ({len(self.recorded)} messages)"],
                ["estimation_replay", f"{verdict} (exit {replay.returncode}, "
                 f"{time.monotonic() - started:.0f} s)"]]
