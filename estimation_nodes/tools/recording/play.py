"""estimation_play: a recording's messages published again, with their recorded timing.

    estimation_play RECORDING [--rate R] [--topics /scan /odom ...] [--clock] [--loop]
                    [--wait-for-subscribers SECONDS] [--delay SECONDS]

RECORDING is one of the package's MCAP recordings, a robot's ROS 1 bag (``.bag``) or a
rosbag2 folder (MCAP or sqlite3): bags are read with the ``rosbags`` library and their
messages published as this ROS 2's types (tools/recording/bags.py), ``/tf`` and
``/tf_static`` included (``/tf_static`` latched, as its publishers do). ``--loop`` plays
it again and again until Ctrl-C, as ``ros2 bag play --loop``: with ``--clock`` the time
then jumps back at each pass (and stands there LOOP_JUMP_PAUSE_S before the pass), which a
node under ``use_sim_time`` must take as a restart.

Each message goes out at its recorded time (the log time, scaled by 1/R), as its
recorded CDR bytes, with the QoS its driver would use: a laser scan best effort
(sensor data), the rest reliable (a map latched). ``--clock`` also publishes
/clock at each message's time, for nodes run with ``use_sim_time:=true``.
``ros2 bag play`` does this where rosbag2 is installed; it is not on PyPI, and this
is the package's stand-in (the recordings stay readable by ros2 bag and Foxglove).

DDS matches the two ends of a topic each on its own: a publisher can count a
subscriber before that subscriber knows the publisher, and a message sent in between
is lost to it. ``--delay`` (as ``ros2 bag play --delay``) leaves time for that after
the wait. Before it ends, the play waits (up to ``ACK_TIMEOUT_S``) until every reliable
message was acknowledged, as ``ros2 bag play --wait-for-all-acked`` does: a process
that ends at once can take its last unacknowledged messages with it.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from estimation_nodes.tools.recording.mcap import RecordingError

#: Types whose publishers a driver makes best effort (sensor data): a late scan is no use.
BEST_EFFORT_TYPES = {"sensor_msgs/msg/LaserScan"}
#: Types a publisher keeps for late subscribers.
LATCHED_TYPES = {"nav_msgs/msg/OccupancyGrid"}
#: How long a play waits, at most, between two /clock messages (wall s) in a long gap.
CLOCK_TICK_S = 0.05
#: --loop --clock: how long (wall s) the clock stands at a new pass's start before its
#: messages. /clock and the data come on different topics, in no order a subscriber is
#: promised: a node that took the pass's first /tf before the jump back would clear it
#: with the previous pass's.
LOOP_JUMP_PAUSE_S = 0.5
#: How long a play waits, at most, for its reliable messages to be acknowledged (s).
ACK_TIMEOUT_S = 5.0


@dataclass(frozen=True)
class Recorded:
    log_time_ns: int
    topic: str
    type_name: str
    data: bytes


def read_raw(path: Path, only: set[str] | None = None) -> list[Recorded]:
    """Every message of a recording or bag (or of the topics ``only``), as CDR bytes, in
    log-time order."""
    from estimation_nodes.tools.recording.bags import is_bag

    if is_bag(path):
        return _read_bag(path, only)
    try:
        from mcap.exceptions import McapError
        from mcap.reader import make_reader
    except ImportError:
        raise RecordingError("playing recordings needs the 'record' extra: "
                             "pip install 'estimation_nodes[record]'") from None
    if not path.is_file():
        raise RecordingError(f"{path} is not a file")
    try:
        with path.open("rb") as stream:
            reader = make_reader(stream)
            found = [Recorded(message.log_time, channel.topic, schema.name, message.data)
                     for schema, channel, message in reader.iter_messages(log_time_order=True)
                     if schema is not None and (only is None or channel.topic in only)]
    except (McapError, ValueError, EOFError) as error:
        raise RecordingError(f"{path} is not a readable MCAP recording: {error}") from None
    return found


def _read_bag(path: Path, only: set[str] | None) -> list[Recorded]:
    from rclpy.serialization import serialize_message

    from estimation_nodes.tools.recording.bags import bag_messages, left_out_notes

    if not path.exists():
        raise RecordingError(f"{path}: no such bag")
    left_out: dict[str, str] = {}
    messages = [Recorded(stamp, topic, type_name, serialize_message(msg))
                for stamp, topic, type_name, msg in bag_messages(path, only, left_out=left_out)]
    for note in left_out_notes(left_out):
        print(f"estimation_play: {note}", file=sys.stderr)
    return messages


def qos_for(type_name: str, topic: str = ""):
    from rclpy.qos import qos_profile_sensor_data

    from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos

    if type_name in BEST_EFFORT_TYPES:
        return qos_profile_sensor_data
    if topic == "/tf_static":
        from estimation_nodes.nodes.tf import TF_STATIC_PUBLISHER_QOS

        return TF_STATIC_PUBLISHER_QOS
    if type_name in LATCHED_TYPES:
        return latched_qos(1)
    return INPUT_QOS


class Player:
    """Publishers for the recording's topics on ``node``, and the timed play."""

    def __init__(self, node, messages: list[Recorded], clock: bool) -> None:
        from estimation_nodes.tools.demo.monitor import message_class

        self._node = node
        self._messages = messages
        self._publishers = {}
        for message in messages:
            if message.topic not in self._publishers:
                self._publishers[message.topic] = node.create_publisher(
                    message_class(message.type_name), message.topic,
                    qos_for(message.type_name, message.topic))
        self._clock = None
        if clock:
            from rosgraph_msgs.msg import Clock

            self._clock_msg = Clock()
            self._clock = node.create_publisher(Clock, "/clock", 10)

    def unmatched(self) -> list[str]:
        """The played topics (and /clock, when played) that have no subscriber yet."""
        publishers = dict(self._publishers)
        if self._clock is not None:
            publishers["/clock"] = self._clock
        return sorted(topic for topic, publisher in publishers.items()
                      if publisher.get_subscription_count() == 0)

    def _publish_clock(self, log_time_ns: int) -> None:
        if self._clock is not None:
            self._clock_msg.clock.sec, self._clock_msg.clock.nanosec = divmod(
                log_time_ns, 1_000_000_000)
            self._clock.publish(self._clock_msg)

    def rewind(self) -> None:
        """Before a pass again: the clock back at the recording's start, alone for a moment
        (LOOP_JUMP_PAUSE_S)."""
        if self._clock is not None and self._messages:
            self._publish_clock(self._messages[0].log_time_ns)
            time.sleep(LOOP_JUMP_PAUSE_S)

    def play(self, rate: float) -> int:
        """Publish every message at its time; the number published."""
        if not self._messages:
            return 0
        first = self._messages[0].log_time_ns
        started = time.monotonic()
        for message in self._messages:
            due = started + (message.log_time_ns - first) / 1e9 / rate
            self._wait_until(due, first, rate, started)
            self._publish_clock(message.log_time_ns)
            self._publishers[message.topic].publish(message.data)
        return len(self._messages)

    def wait_for_acknowledgements(self, timeout_s: float) -> list[str]:
        """Wait until the reliable topics' subscribers acknowledged every message; the
        topics still waiting after ``timeout_s``."""
        from rclpy.duration import Duration
        from rclpy.qos import ReliabilityPolicy

        deadline = time.monotonic() + timeout_s
        waiting = []
        for topic, publisher in self._publishers.items():
            if publisher.qos_profile.reliability != ReliabilityPolicy.RELIABLE:
                continue
            left = max(0.0, deadline - time.monotonic())
            if not publisher.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))):
                waiting.append(topic)
        return waiting

    def _wait_until(self, due: float, first: int, rate: float, started: float) -> None:
        """Sleep until ``due`` (monotonic s), ticking /clock through a long gap so that a
        use_sim_time node's timers keep running."""
        while (left := due - time.monotonic()) > 0:
            time.sleep(min(left, CLOCK_TICK_S))
            if self._clock is not None and due - time.monotonic() > 0:
                now_ns = first + int((time.monotonic() - started) * rate * 1e9)
                self._publish_clock(now_ns)


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="estimation_play", description=__doc__.split("\n")[0])
    parser.add_argument("recording", type=Path)
    parser.add_argument("--rate", type=float, default=1.0,
                        help="play R times as fast as recorded (default: %(default)s)")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC",
                        help="play only these topics (default: all)")
    parser.add_argument("--clock", action="store_true",
                        help="publish /clock with the recorded time (for use_sim_time)")
    parser.add_argument("--loop", action="store_true",
                        help="play the recording again and again until Ctrl-C")
    parser.add_argument("--wait-for-subscribers", type=float, default=0.0, metavar="SECONDS",
                        help="before the first message, wait up to SECONDS for every "
                             "played topic to have a subscriber (default: start at once)")
    parser.add_argument("--delay", type=float, default=0.0, metavar="SECONDS",
                        help="sleep SECONDS before the first message, after the wait for "
                             "subscribers (default: %(default)s)")
    args = parser.parse_args(argv)
    if not (math.isfinite(args.rate) and args.rate > 0):
        parser.error("--rate must be a finite number > 0")
    if not (math.isfinite(args.wait_for_subscribers) and args.wait_for_subscribers >= 0):
        parser.error("--wait-for-subscribers must be a finite number >= 0")
    if not (math.isfinite(args.delay) and args.delay >= 0):
        parser.error("--delay must be a finite number >= 0")
    return args


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(argv)
    try:
        only = {t if t.startswith("/") else f"/{t}" for t in args.topics} if args.topics \
            else None
        messages = read_raw(args.recording, only)
    except RecordingError as error:
        print(f"estimation_play: {error}", file=sys.stderr)
        sys.exit(2)
    if not messages:
        print(f"estimation_play: {args.recording}: no message on the topics asked for",
              file=sys.stderr)
        sys.exit(2)
    sys.exit(_run(args, messages))


def _run(args: argparse.Namespace, messages: list[Recorded]) -> int:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions

    from estimation_nodes.tools.demo.graph_runtime import spin_until

    node = executor = None
    code = 0
    try:
        # Ctrl-C raises KeyboardInterrupt here instead of shutting the context down under us.
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        node = Node("estimation_play")
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        player = Player(node, messages, args.clock)
        if args.wait_for_subscribers:
            if not spin_until(executor, lambda: not player.unmatched(),
                              args.wait_for_subscribers):
                print(f"estimation_play: no subscriber yet on {', '.join(player.unmatched())};"
                      f" playing anyway", file=sys.stderr)
        time.sleep(args.delay)
        span = (messages[-1].log_time_ns - messages[0].log_time_ns) / 1e9
        print(f"estimation_play: {len(messages)} messages on "
              f"{len({m.topic for m in messages})} topics, {span:.1f} s of recording at "
              f"rate {args.rate:g}", flush=True)
        passes = 0
        while True:
            published = player.play(args.rate)
            passes += 1
            if not args.loop:
                break
            print(f"estimation_play: pass {passes}: {published} messages published; again",
                  flush=True)
            player.rewind()
        print(f"estimation_play: {published} messages published", flush=True)
        unacknowledged = player.wait_for_acknowledgements(ACK_TIMEOUT_S)
        if unacknowledged:
            print(f"estimation_play: not every message was acknowledged on "
                  f"{', '.join(unacknowledged)} within {ACK_TIMEOUT_S:g} s", file=sys.stderr)
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)   # the end has begun
        print("estimation_play: interrupted", file=sys.stderr)
        code = 130
    finally:
        if node is not None:
            node.destroy_node()
        if executor is not None:
            executor.shutdown()
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    main()
