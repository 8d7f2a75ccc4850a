"""Record every topic of a run to MCAP until SIGINT: an observer the tests start as a process.

    python -m tests.graph.record_run OUT.mcap PARAMS.yaml [STEPS]

It is the demo's monitor and recorder without the demo, so it can run on
another (simulated) host than the estimator, as a recorder beside a sensor
would. The parameter file goes into the recording for estimation_replay.
Prints "recording" once its subscriptions exist. With STEPS, it also prints
"settled" once what it has recorded is complete: STEPS commands and readings,
and estimates that estimation_replay finds equal to the filter run offline over
them, STEPS of each. A test stops it then, not after a guessed time: until the
estimator has had every input, and its estimates have reached the recorder, the
recording cannot replay equal.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.serialization import deserialize_message

from estimation_nodes.params import topics
from estimation_nodes.tools.demo.monitor import RunMonitor, message_class
from estimation_nodes.tools.recording.mcap import McapRunWriter, Recording, _add_decoded
from estimation_nodes.tools.recording.run_record import RunRecord
from estimation_nodes.tools.replay.estimator import replay

#: How often (s) a recorder given STEPS looks whether its recording is complete...
CHECK_PERIOD_S = 0.25
#: ...waiting at least this many times as long as the last look took before the next.
CHECK_COST_FACTOR = 4.0


class Kept:
    """A sink that keeps every raw message, to replay what was recorded so far."""

    def __init__(self, recorded: dict[str, str]) -> None:
        self.types = {topic: message_class(name) for topic, name in recorded.items()}
        self.messages: list[tuple[int, int, str, bytes]] = []

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int,
              sequence: int | None = None) -> None:
        if topic in self.types:
            self.messages.append((publish_time_ns, log_time_ns, topic, data))

    def recording(self, metadata: dict[str, str]) -> Recording:
        """As read_recording reads the file: decoded, in publish-time order."""
        record, counts = RunRecord(), {}
        for publish_time, _log, topic, data in sorted(self.messages, key=lambda m: m[:2]):
            counts[topic] = counts.get(topic, 0) + 1
            _add_decoded(record, topic, deserialize_message(data, self.types[topic]),
                         publish_time)
        return Recording(record, metadata, counts)


def settled(kept: Kept, metadata: dict[str, str], steps: int) -> bool:
    recording = kept.recording(metadata)
    run = recording.record
    if len(run.commands) < steps or len(run.observations) < steps:
        return False
    comparison = replay(recording, metadata["parameters_yaml"], 1e-9)
    return comparison.equal and all(
        comparison.compared.get(topic) == steps for topic in (topics.BELIEF,
                                                              topics.BELIEF_PREDICTED))


def main() -> None:
    out, params = Path(sys.argv[1]), Path(sys.argv[2])
    steps = int(sys.argv[3]) if len(sys.argv) > 3 else None
    rclpy.init()
    recorded = {f"/{t}": n for t, n in topics.TOPIC_TYPES.items()}
    metadata = {"parameters_yaml": params.read_text(encoding="utf-8"),
                "parameters_file": str(params)}
    writer = McapRunWriter(out, recorded, metadata)
    kept = Kept(recorded)
    monitor = RunMonitor(quiet=True, sinks=[writer, kept])
    if steps is not None:
        checked_at = {"messages": -1, "next": 0.0}

        def check() -> None:
            # A check replays the whole recording: after a healed partition, thousands of
            # estimates. Checking only when something came in, and at most a fifth of the
            # time, keeps the recorder free to take the backlog: a recorder busy checking let
            # its socket overflow, and DDS's repairs then took a minute (the CI failure).
            now = time.monotonic()
            if len(kept.messages) == checked_at["messages"] or now < checked_at["next"]:
                return
            checked_at["messages"] = len(kept.messages)
            if settled(kept, metadata, steps):
                print("settled", flush=True)
                monitor.destroy_timer(timer)
            checked_at["next"] = now + CHECK_COST_FACTOR * (time.monotonic() - now)

        timer = monitor.create_timer(CHECK_PERIOD_S, check)
    print("recording", flush=True)
    try:
        rclpy.spin(monitor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        monitor.destroy_node()
        writer.close()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
