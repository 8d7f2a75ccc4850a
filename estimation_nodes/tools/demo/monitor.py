"""The demo's observer: takes every topic of the run raw, records, prints, feeds raw sinks.

One raw subscription per topic: the CDR bytes go unchanged to each sink (the
MCAP recorder, the Foxglove live view) and are deserialized once for the
RunRecord and the display.
"""

from __future__ import annotations

import importlib
import os
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from typing import Protocol

import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message

from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos
from estimation_nodes.nodes.wire import from_state_message
from estimation_nodes.params import topics
from estimation_nodes.tools.demo.overrides import MONITOR
from estimation_nodes.tools.recording.run_record import RunRecord

BARS = " ▁▂▃▄▅▆▇█"


class RawSink(Protocol):
    """Where raw messages go: the MCAP recorder, the Foxglove live view."""

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int,
              sequence: int | None = None) -> None:
        """``topic`` as resolved; ``data`` the CDR bytes; receive and source times in ns;
        ``sequence`` the publisher's number for the message (None: not known)."""


def observer_qos(topic: str) -> QoSProfile | int:
    """The QoS to observe a topic of the graph with, as its publisher offers it.

    Inputs are volatile; the outputs are latched, and an observer that matches
    a publisher late still gets what it kept. /diagnostics is a plain depth-10
    publisher: a transient_local request would not match it.
    """
    if topic in topics.INPUTS:
        return INPUT_QOS
    if topic == topics.DIAGNOSTICS:
        return 10
    return latched_qos(1000)


def message_class(type_name: str) -> type:
    """The Python class of a ROS type named like 'std_msgs/msg/Int32'."""
    package, interface, name = type_name.split("/")
    return getattr(importlib.import_module(f"{package}.{interface}"), name)


def vector_of(msg) -> np.ndarray:
    return np.frombuffer(msg.data, dtype=np.float64).copy()


def input_value(msg) -> object:
    """A scalar input's value, or a vector input's values as a tuple."""
    return tuple(msg.data) if hasattr(msg, "layout") else msg.data


def bars(belief: np.ndarray) -> str:
    """One block character per cell, height by probability relative to the largest."""
    if belief.size > 60:
        top = np.argsort(belief)[::-1][:3]
        return "top cells " + ", ".join(f"{i}:{belief[i]:.3f}" for i in top)
    scaled = belief / max(float(belief.max()), 1e-300) * (len(BARS) - 1)
    blocks = "".join(BARS[int(round(v))] for v in scaled)
    if belief.size <= 12:
        return f"|{blocks}|  [" + " ".join(f"{v:.6f}" for v in belief) + "]"
    return f"|{blocks}|"


class RunMonitor(Node):
    """Subscribes to every topic of the run; keeps a RunRecord; prints each estimate.

    Every raw message goes to each of ``sinks``; ``sink_only_topics`` (name ->
    ROS type) are taken for the sinks alone, neither recorded nor printed.
    """

    def __init__(self, quiet: bool = False, sinks: Sequence[RawSink] = (),
                 sink_only_topics: Mapping[str, str] | None = None,
                 run_started_ns: int | None = None, **kwargs) -> None:
        super().__init__(MONITOR, **kwargs)
        self.record = RunRecord()
        # With ``run_started_ns`` (the demo's: every node of its run starts after it), a
        # sample published before it (a latched one of a graph still running in the
        # domain) is not of this run; without, every sample is (a monitor that joins late).
        self._started_ns = run_started_ns if run_started_ns is not None else 0
        #: Topic -> samples left out as published before the run began.
        self.foreign: Counter[str] = Counter()
        self._quiet = quiet
        self._sinks = tuple(sinks)
        observed = {**topics.TOPIC_TYPES, **(sink_only_topics or {})}
        self._types = {topic: message_class(name) for topic, name in observed.items()}
        handlers: dict[str, Callable[[object], None] | None] = {
            topics.TRUE_POSITION: lambda msg: self.record.truth.append(msg.data),
            topics.BELIEF_PREDICTED: self._on_predicted,
            topics.BELIEF: self._on_corrected,
            topics.KALMAN_ESTIMATE: self._on_kalman,
            topics.KALMAN_ESTIMATE_STAMPED: lambda msg: None,
            topics.KALMAN_ESTIMATE_PREDICTED: lambda msg: self.record.kalman_predicted.append(
                (msg.pose.position.x, msg.covariance[0])),
            topics.KALMAN_ESTIMATE_PREDICTED_STAMPED: lambda msg: None,
            topics.KALMAN_STATE: self._on_state,
            topics.KALMAN_STATE_PREDICTED: lambda msg: self.record.states_predicted.append(
                from_state_message(msg)),
            topics.TRUE_STATE: lambda msg: self.record.true_states.append(vector_of(msg)),
        }
        for topic in topics.INPUTS:
            handlers[topic] = lambda msg, t=topic: self.record.add_event(t, input_value(msg))
        self._subscriptions_by_topic = {}
        for topic, msg_type in self._types.items():
            self._subscriptions_by_topic[topic] = self.create_subscription(
                msg_type, topic,
                self._raw_handler(topic, handlers[topic] if topic in topics.TOPIC_TYPES else None),
                observer_qos(topic), raw=True)

    def publishers_matched(self, published: tuple[str, ...]) -> bool:
        """Whether each of the ``published`` topics has a matched publisher.

        Volatile readings published before the match would be lost to the monitor.
        """
        return all(self._subscriptions_by_topic[topic].get_publisher_count() >= 1
                   for topic in published)

    def _raw_handler(self, topic: str, handle: Callable[[object], None] | None):
        msg_type = self._types[topic]
        resolved = self.resolve_topic_name(topic)

        def on_raw(data: bytes, info: dict) -> None:
            received = time.time_ns()
            published = info.get("source_timestamp") or received
            if published < self._started_ns:
                self._leave_out_foreign(resolved)
                return
            sequence = info.get("publication_sequence_number")
            for sink in self._sinks:
                sink.write(resolved, data, received, published, sequence)
            if handle is not None:
                handle(deserialize_message(data, msg_type))
                self.record.stamp(topic, published)

        return on_raw

    def _leave_out_foreign(self, topic: str) -> None:
        if not self.foreign[topic]:
            self.get_logger().warning(
                f"{topic}: a sample published before this run began left out (another "
                f"graph in ROS domain {os.environ.get('ROS_DOMAIN_ID', '0')}?)")
        self.foreign[topic] += 1

    def _say(self, text: str) -> None:
        if not self._quiet:
            print(text, flush=True)

    def _truth_note(self, size: int) -> str:
        """The step's truth: the last one published before the estimate being shown (the
        estimator can republish an estimate, so counting estimates would drift)."""
        truth = self.record.truth
        return f"(true cell {truth[-1] % size})" if truth else ""

    def _on_predicted(self, msg) -> None:
        belief = np.frombuffer(msg.data, dtype=np.float64).copy()
        self.record.predicted.append(belief)
        self._say(f"step {len(self.record.predicted):3d}  predicted  {bars(belief)}")

    def _on_corrected(self, msg) -> None:
        belief = np.frombuffer(msg.data, dtype=np.float64).copy()
        self.record.corrected.append(belief)
        self._say(f"step {len(self.record.truth):3d}  corrected  {bars(belief)}  most likely "
                  f"cell {int(np.argmax(belief))} {self._truth_note(belief.size)}")

    def _on_state(self, msg) -> None:
        x, P = from_state_message(msg)
        self.record.states.append((x, P))
        if x.size == 1:   # the 1-D filter: kalman_estimate says it all
            return
        truth = self.record.true_states
        note = f"true {np.array2string(truth[-1], precision=3)}" if truth else ""
        self._say(f"step {len(truth):3d}  kalman     x = {np.array2string(x, precision=3)}  "
                  f"std = {np.array2string(np.sqrt(np.diag(P)), precision=3)}  {note}")

    def _on_kalman(self, msg) -> None:
        x, var = msg.pose.position.x, msg.covariance[0]
        self.record.kalman.append((x, var))
        if self.record.true_states:
            return   # a matrix run: printed from kalman_state
        truth = self.record.truth
        note = f"(true position {truth[-1]})" if truth else ""
        self._say(f"step {len(truth):3d}  kalman     x = {x:.6f}  var = {var:.6f}  "
                  f"std = {np.sqrt(var):.6f}  {note}")
