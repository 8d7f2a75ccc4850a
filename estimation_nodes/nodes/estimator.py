"""The estimator node: histogram and Kalman filters over the core, fed by topics.

``motion_cmd`` predicts both filters, ``tile_observation`` corrects the
histogram, and ``position_measurement`` corrects the Kalman filter. Events are
applied in the order they happened, by their source timestamps, not in the
order DDS delivered them (core/causal_order.py): a reading that arrives before
the move that caused it is applied at once, and when the move comes the
filters go back, apply it, apply the reading again and republish. A bad
message, or one whose result would not be finite, is dropped with a
throttled warning and counted; the filters are left untouched. A rejected
event still keeps its place in the reorder history: a reading of zero evidence
that came before its move is tried again when the move comes (counted once, in
``rejected``; in ``events.taken_on_retry`` when taken then).

A parameter change that is right on its own but does not fit the others yet
(three classes with a 2 x 2 sensor model, a 20-cell world with a 5-cell prior)
is accepted and held: the filters keep the last consistent configuration until
the parameters agree again, so changes that need several parameters work with
``ros2 param set`` one at a time and with ``ros2 param load``.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovariance, PoseWithCovarianceStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.event_handler import (
    PublisherEventCallbacks,
    QoSMessageLostInfo,
    QoSRequestedIncompatibleQoSInfo,
    SubscriptionEventCallbacks,
)
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_policy_name_from_kind
from std_msgs.msg import Float64, Float64MultiArray, Int32, String
from std_srvs.srv import Trigger

from estimation_nodes.core import errors
from estimation_nodes.core.causal_order import CausalOrder, Submission
from estimation_nodes.core.kalman.filter import KalmanFilter
from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.filter import HistogramFilter
from estimation_nodes.nodes import wire
from estimation_nodes.nodes.diagnostics import status_array
from estimation_nodes.nodes.parameters import (
    declare_and_build,
    overlay,
    rejection,
)
from estimation_nodes.nodes.process import main_for
from estimation_nodes.nodes.process_memory import keep_freed_memory
from estimation_nodes.nodes.stamps import published_ns
from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos
from estimation_nodes.nodes.rclpy_internals import (
    INCOMPATIBLE_QOS,
    MESSAGE_LOST,
    SubscriptionEvents,
)
from estimation_nodes.nodes.throttled import ThrottledWarnings
from estimation_nodes.params import topics
from estimation_nodes.params.estimator import (
    HISTOGRAM_KEYS,
    EstimatorUpdate,
    build_estimator_settings,
    check_estimator_value,
    reorder_max_events,
    update_estimator_settings,
)
from estimation_nodes.params.specs import ESTIMATOR_SPECS
from estimation_nodes.params.wording import plural

#: Order of events stamped at the same instant: a move before the readings after it.
MOVE, READING = 0, 1
#: How often the estimator looks for move publishers it has not matched yet, and how long
#: at most it holds readings for one (a publisher it can never match: incompatible QoS).
MATCH_CHECK_PERIOD_S = 0.05
MATCH_WAIT_LIMIT_S = 2.0


class Estimator(Node):
    """Histogram belief and Kalman estimate of a robot on a cyclic world of tiles."""

    node_name = "estimator"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.node_name, **kwargs)
        self._values, settings = declare_and_build(self, ESTIMATOR_SPECS, build_estimator_settings)
        # The settings in force and the histogram values they were built from; self._values
        # may run ahead of them while a change is held (see the module docstring).
        self._settings = settings
        self._histogram_values = {key: self._values[key] for key in HISTOGRAM_KEYS}
        self.held_reason: str | None = None
        horizon_ns = round(self._values["reorder_horizon"] * 1e9)
        # Saved states must stay as they were: with a history, corrections make new arrays.
        self._histogram = HistogramFilter(
            settings.histogram, settings.initial_belief, self._values["compiled_kernels"],
            in_place=horizon_ns == 0)
        self._kalman = KalmanFilter(settings.kalman.initial, settings.kalman.model)
        self._order: CausalOrder | None = CausalOrder(self, horizon_ns, reorder_max_events(
            self._values["reorder_memory_mb"], settings.histogram.size,
            settings.kalman.initial.x.size)) if horizon_ns else None
        #: When the event being applied happened (ns): the stamp of the stamped outputs.
        self._event_stamp_ns = 0
        self.handled: Counter[str] = Counter()
        #: What the reorder history did: events put in their place, applied again, ...
        self.reordering: Counter[str] = Counter()
        self.rejected: Counter[str] = Counter()
        self._warnings = ThrottledWarnings(self.get_logger())
        self._proposed: tuple[dict[str, Any], EstimatorUpdate] | None = None
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._on_parameters_set)

        latched = latched_qos(self._values["history_depth"])
        self._belief_predicted_pub = self._output(
            Float64MultiArray, topics.BELIEF_PREDICTED, latched)
        self._belief_pub = self._output(Float64MultiArray, topics.BELIEF, latched)
        self._kalman_pubs = self._pose_outputs(
            topics.KALMAN_ESTIMATE, topics.KALMAN_ESTIMATE_STAMPED, latched)
        self._kalman_predicted_pubs = self._pose_outputs(
            topics.KALMAN_ESTIMATE_PREDICTED, topics.KALMAN_ESTIMATE_PREDICTED_STAMPED, latched)
        self._state_pub = self._output(Float64MultiArray, topics.KALMAN_STATE, latched)
        self._state_predicted_pub = self._output(
            Float64MultiArray, topics.KALMAN_STATE_PREDICTED, latched)
        self._diagnostics_pub = self._output(DiagnosticArray, "/diagnostics", 10)
        # motion_cmd first: when a command and the reading it caused are ready
        # together, the executor takes them in subscription order.
        self.qos_incompatible: Counter[str] = Counter()
        self._input_events = SubscriptionEvents(self.default_callback_group)
        inputs = [
            (Int32, topics.MOTION_CMD, self._on_motion_cmd, MOVE),
            (String, topics.TILE_OBSERVATION, self._on_tile_observation, READING),
            (Float64, topics.POSITION_MEASUREMENT, self._on_position_measurement, READING),
        ]
        # The vector inputs only in matrix mode (read-only): every subscription costs the
        # executor time on each message, and the scalar filter takes single numbers.
        if settings.kalman.mode == "matrix":
            inputs += [
                (Float64MultiArray, topics.KALMAN_INPUT, self._on_kalman_input, MOVE),
                (Float64MultiArray, topics.KALMAN_MEASUREMENT, self._on_kalman_measurement,
                 READING),
            ]
        self._move_subscriptions = []
        for msg_type, topic, handler, rank in inputs:
            # Vectors are taken raw and read by a wire.MultiarrayReader: rclpy's message
            # object, layout and all, cost more than the filter's use of the numbers.
            raw = msg_type is Float64MultiArray
            subscription = self.create_subscription(
                msg_type, topic, self._arrival(handler, rank, topic if raw else None),
                INPUT_QOS, raw=raw,
                event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False))
            self._watch_input_events(subscription, topic)
            if rank == MOVE:
                self._move_subscriptions.append(subscription)
        # Readings held while a move publisher is in the graph but not matched yet: its
        # first moves are on their way, and a reading applied before them would only be
        # provisional (republished once they come).
        self._held_readings: list[tuple[int, int, Any]] = []
        self._moves_unmatched_since: float | None = None
        self._unmatchable = False
        if self._order is not None:
            self.create_timer(MATCH_CHECK_PERIOD_S, self._check_move_publishers)
        self.add_waitable(self._input_events)
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_timer(self._values["diagnostics_period"], self._publish_diagnostics)
        self.get_logger().info(
            f"ready: {settings.histogram.size} cells"
            f"{' (compiled histogram kernels)' if self._histogram.compiled else ''},"
            f" Kalman mode {settings.kalman.mode}")

    # --- parameters -------------------------------------------------------------------------

    def _on_set_parameters(self, changes: list[Parameter]) -> SetParametersResult:
        """Refuse a value that is wrong on its own; accept the rest, applied or held."""
        try:
            for change in changes:
                check_estimator_value(change.name, change.value)
            proposed = overlay(self._values, changes)
            update = update_estimator_settings(proposed, self._settings, self._histogram_values)
        except ValueError as error:
            return rejection(str(error))
        self._proposed = (proposed, update)
        return SetParametersResult(successful=True)

    def _on_parameters_set(self, _changes: list[Parameter]) -> None:
        """The one place a parameter change takes effect: right after rclpy has set it.

        Callbacks of one node never run concurrently here (one executor, one
        callback group), so no event sees a half-applied configuration.
        """
        if self._proposed is None:
            return
        (self._values, update), self._proposed = self._proposed, None
        was_held = self.held_reason is not None
        self.held_reason = (f"held, not applied yet: {'; '.join(update.held)}; that part "
                            f"keeps its last consistent parameters until the others agree"
                            if update.held else None)
        if self.held_reason is not None:
            self.get_logger().warning(f"parameters {self.held_reason}")
        elif was_held:
            self.get_logger().info("parameters agree again: the held change is applied")
        self._settings, self._histogram_values = update.settings, update.histogram_values
        settings = update.settings
        # Past events were applied with the previous parameters: a late one cannot be put
        # in its place among them any more.
        if self._order is not None:
            self._order.clear()
        histogram_reset = self._histogram.reconfigure(settings.histogram,
                                                      settings.initial_belief)
        kalman_reset = self._kalman.reconfigure(settings.kalman.initial, settings.kalman.model)
        if histogram_reset or kalman_reset:
            self.get_logger().info("new world size, prior or Kalman state size: "
                                   "that filter restarts from its initial state")
            self._publish_everything()

    # --- events -----------------------------------------------------------------------------

    def _arrival(self, handler: Any, rank: int, raw_vector_topic: str | None = None) -> Any:
        """The subscription callback of one input: the message with when it happened, to
        the causal order (or straight to ``handler`` when there is none). For a raw
        subscription (``raw_vector_topic``), the message is the numbers its bytes hold."""

        read_vector = wire.MultiarrayReader() if raw_vector_topic is not None else None

        def on_message(msg: Any, info: dict) -> None:
            if read_vector is not None:
                try:
                    msg = read_vector(msg)
                except wire.MalformedMessageError as error:
                    self._reject(f"malformed.{raw_vector_topic}",
                                 f"{raw_vector_topic} dropped: {error}")
                    return
            # The publisher's clock: the order of events across topics and hosts.
            stamp = published_ns(info)
            if self._order is None:
                self._event_stamp_ns = stamp
                handler(msg, True)
            else:
                event = (stamp, rank, (stamp, handler, msg))
                if self._held_readings or (rank == READING
                                           and self._moves_unmatched_since is not None):
                    self._held_readings.append(event)
                    return
                self._account(self._order.submit(*event))
            # The answer is out: while the next input is on its way, work out what it
            # will do to the Kalman covariance, so that its answer goes out sooner.
            self._kalman.prepare()

        return on_message

    def _check_move_publishers(self) -> None:
        """Note a move publisher the graph shows but this node has not matched; once none is
        left (or after MATCH_WAIT_LIMIT_S: one it cannot match), apply the readings held."""
        unmatched = any(self.count_publishers(sub.topic_name) > sub.get_publisher_count()
                        for sub in self._move_subscriptions)
        if not unmatched:
            self._unmatchable = False
        if unmatched and not self._unmatchable:
            now = time.monotonic()
            if self._moves_unmatched_since is None:
                self._moves_unmatched_since = now
            if now - self._moves_unmatched_since <= MATCH_WAIT_LIMIT_S:
                return
            self._unmatchable = True
            self._warn("unmatched_move_publisher", "a move publisher stays unmatched (its QoS?):"
                       " readings no longer wait for it")
        self._moves_unmatched_since = None
        held, self._held_readings = self._held_readings, []
        assert self._order is not None
        for event in held:
            self._account(self._order.submit(*event))

    # Replayable, for the causal order: the state of both filters, and one event.

    def snapshot(self) -> tuple[Any, Any]:
        return self._histogram.snapshot(), self._kalman.snapshot()

    def restore(self, state: tuple[Any, Any]) -> None:
        histogram_state, kalman_state = state
        self._histogram.restore(histogram_state)
        self._kalman.restore(kalman_state)

    def apply(self, event: tuple[int, Any, Any], first_time: bool) -> bool:
        self._event_stamp_ns, handler, msg = event
        return handler(msg, first_time)

    def _account(self, submission: Submission) -> None:
        if submission.reordered:
            self.reordering["reordered"] += 1
            self.reordering["reapplied"] += submission.reapplied
        if submission.dropped_on_reapply:
            self.reordering["dropped_on_reapply"] += submission.dropped_on_reapply
        # Counted in rejected.* when they arrived, and not again: taken now, they show here.
        if submission.taken_on_retry:
            self.reordering["taken_on_retry"] += submission.taken_on_retry
        if submission.too_late:
            self.reordering["too_late"] += 1
            self._warn("too_late", "an event older than the reorder history arrived: applied "
                       "now, out of order (raise reorder_horizon or reorder_memory_mb; events "
                       f"so far: {self.reordering['too_late']})")

    def _on_motion_cmd(self, msg: Int32, first_time: bool) -> bool:
        self._histogram.predict(msg.data)
        if first_time:
            self.handled["motion_cmd"] += 1
        self._belief_predicted_pub.publish(wire.vector(self._histogram.belief, "cells"))
        # A filter with m = 1 input takes the command as u; a larger one takes kalman_input.
        if self._kalman.input_size == 1:
            self._kalman_step(True, float(msg.data), topics.MOTION_CMD, first_time)
        return True

    def _on_kalman_input(self, u: np.ndarray, first_time: bool) -> bool:
        return self._kalman_step(True, u, topics.KALMAN_INPUT, first_time)

    def _on_tile_observation(self, msg: String, first_time: bool) -> bool:
        try:
            self._histogram.correct(msg.data)
        except errors.ZeroEvidenceError as error:
            self._reject("zero_evidence", f"tile_observation {msg.data!r} dropped: {error}",
                         counted=first_time)
            return False
        except ValueError as error:
            self._reject("unknown_class", f"tile_observation dropped: {error}",
                         counted=first_time)
            return False
        if first_time:
            self.handled["tile_observation"] += 1
        self._belief_pub.publish(wire.vector(self._histogram.belief, "cells"))
        return True

    def _on_position_measurement(self, msg: Float64, first_time: bool) -> bool:
        return self._kalman_step(False, msg.data, topics.POSITION_MEASUREMENT, first_time)

    def _on_kalman_measurement(self, z: np.ndarray, first_time: bool) -> bool:
        return self._kalman_step(False, z, topics.KALMAN_MEASUREMENT, first_time)

    def _kalman_step(self, predicted: bool, value: Any, topic: str, first_time: bool) -> bool:
        """One Kalman prediction (or correction) from ``topic``; the result published, or
        the input dropped (and counted, the first time) with the filter untouched."""
        try:
            (self._kalman.predict if predicted else self._kalman.correct)(value)
        except errors.NonFiniteResultError as error:
            self._reject("numerical_overflow", f"{topic} {value!r} dropped: {error}",
                         counted=first_time)
            return False
        except errors.InputSizeError as error:
            self._reject(f"wrong_size.{topic}", f"{topic} dropped: {error}", counted=first_time)
            return False
        except ValueError as error:   # NaN or inf
            reason = "non_finite_measurement" if topic == topics.POSITION_MEASUREMENT \
                else f"non_finite.{topic}"
            self._reject(reason, f"{topic} dropped: {error}", counted=first_time)
            return False
        if first_time and topic != topics.MOTION_CMD:
            self.handled[topic] += 1
        self._publish_kalman(predicted)
        return True

    def _publish_everything(self) -> None:
        """Every output, after a restart of the filters: a late subscriber then gets the
        state after it, not an estimate from before."""
        self._event_stamp_ns = self.get_clock().now().nanoseconds
        belief = wire.vector(self._histogram.belief, "cells")
        self._belief_predicted_pub.publish(belief)
        self._belief_pub.publish(belief)
        for predicted in (True, False):
            self._publish_kalman(predicted)

    def _publish_kalman(self, predicted: bool) -> None:
        """The estimate as a pose (with its stamped twin) and the full state, x with P,
        each serialized here (wire.py: a message object costs rclpy more than the step)."""
        state_pub, (pose_pub, stamped_pub) = (
            (self._state_predicted_pub, self._kalman_predicted_pubs) if predicted
            else (self._state_pub, self._kalman_pubs))
        x, P = self._kalman.x, self._kalman.P
        # The full state first: it is the whole estimate, so it reaches subscribers soonest.
        state_pub.publish(wire.state(x, P))
        pose = wire.pose_numbers(x, P, self._settings.kalman.pose_components)
        pose_pub.publish(wire.pose_with_covariance(pose))
        # Stamped when the event this estimate follows from happened, as ROS estimators do.
        stamped_pub.publish(wire.pose_with_covariance_stamped(
            self._event_stamp_ns, self._values["frame_id"], pose))

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """Back to the initial state, published on every output so that a late subscriber
        gets the state after the reset, not an estimate from before it."""
        self._histogram.reset()
        self._kalman.reset()
        if self._order is not None:
            self._order.clear()
        self.handled["reset"] += 1
        self._publish_everything()
        response.success = True
        response.message = "histogram belief and Kalman estimate back to their initial state"
        self.get_logger().info(response.message)
        return response

    # Every QoS event handler is a Python waitable that rclpy's executor visits on
    # each iteration, whether or not it fires: rclpy gives each publisher and
    # subscription two by default, 21 in all for this node, which made its idle
    # spin cost far more than a one-subscription node's. Only the events worth it
    # are kept, the inputs' six in one waitable (rclpy_internals.py; figures in
    # docs/benchmarks.md).

    def _output(self, msg_type: type, topic: str, qos: Any):
        """A publisher without rclpy's default QoS event handlers.

        Our outputs offer reliable + transient_local, which satisfies every
        request, and a subscriber with the wrong type or QoS is warned by its
        own side's handlers.
        """
        return self.create_publisher(
            msg_type, topic, qos,
            event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))

    def _pose_outputs(self, topic: str, stamped_topic: str, qos: Any) -> tuple[Any, Any]:
        return (self._output(PoseWithCovariance, topic, qos),
                self._output(PoseWithCovarianceStamped, stamped_topic, qos))

    def _watch_input_events(self, subscription: Any, topic: str) -> None:
        """Count messages DDS reports lost, and warn of publishers we cannot hear."""

        def on_lost(info: QoSMessageLostInfo) -> None:
            self._reject(f"lost.{topic}", f"{plural(info.total_count_change, topic + ' message')} "
                         "lost",
                         count=info.total_count_change)

        def on_incompatible_qos(info: QoSRequestedIncompatibleQoSInfo) -> None:
            self.qos_incompatible[topic] += info.total_count_change
            self.get_logger().warning(
                f"a publisher on {topic} offers QoS this node cannot accept (policy "
                f"{qos_policy_name_from_kind(info.last_policy_kind)}): its messages are not "
                f"received; publish reliable")

        self._input_events.watch(subscription, MESSAGE_LOST, on_lost)
        self._input_events.watch(subscription, INCOMPATIBLE_QOS, on_incompatible_qos)

    def destroy_node(self) -> None:
        # The event handles refer to the subscriptions: release them first.
        self.remove_waitable(self._input_events)
        self._input_events.destroy()
        super().destroy_node()

    def _reject(self, reason: str, message: str, count: int = 1, counted: bool = True) -> None:
        """Count (unless ``counted`` is False: an event applied again, counted the first
        time) and warn, at most once per WARN_THROTTLE_S for each reason."""
        if not counted:
            return
        self.rejected[reason] += count
        self._warn(reason, f"{message} (rejected so far: {self.rejected[reason]})")

    def _warn(self, reason: str, message: str) -> None:
        self._warnings.warn(reason, message)

    # --- health -----------------------------------------------------------------------------

    def _publish_diagnostics(self) -> None:
        belief = self._histogram.belief
        values: dict[str, Any] = {
            "cells": belief.size,
            "most_likely_cell": histogram.most_likely_cell(belief),
            "belief_entropy_bits": f"{histogram.entropy(belief):.6g}",
            "kalman_x": f"{self._kalman.estimate.x:.9g}",
            "kalman_var": f"{self._kalman.estimate.var:.9g}",
        }
        # Only once there is one: "nan" before the first correction reads as a fault.
        if math.isfinite(self._histogram.last_evidence):
            values["last_evidence"] = f"{self._histogram.last_evidence:.6g}"
        if math.isfinite(self._kalman.last_nis):
            values["kalman_nis"] = f"{self._kalman.last_nis:.6g}"
        values.update({f"handled.{k}": v for k, v in sorted(self.handled.items())})
        values.update({f"rejected.{k}": v for k, v in sorted(self.rejected.items())})
        values.update({f"events.{k}": v for k, v in sorted(self.reordering.items())})
        values.update({f"incompatible_publishers.{k}": v
                       for k, v in sorted(self.qos_incompatible.items())})
        problems = []
        if self.rejected:
            problems.append(f"{plural(sum(self.rejected.values()), 'message')} rejected")
        if self.held_reason is not None:
            values["parameters_held"] = self.held_reason
            problems.append("parameter change held")
        self._diagnostics_pub.publish(status_array(self, "filters", values, problems))


def main(args: list[str] | None = None) -> None:
    # A process-wide choice, so it is made here and not in the node (process_memory.py);
    # inside run()'s handling, where a Ctrl-C during it ends the node quietly.
    main_for(Estimator, prepare=keep_freed_memory)(args)


if __name__ == "__main__":
    main()
