"""The estimator applies events in the order they happened, not the order they arrived in.

DDS cannot be made to deliver out of order on demand, so these tests hand the
estimator's subscription callbacks the messages with the message info DDS would
give them (source timestamps), in the order a partition or a late match
delivers them. The graph tests show the same over real transports.
"""

import numpy as np
import pytest
from rclpy.parameter import Parameter
from std_msgs.msg import Float64, Int32, String

from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.models import HistogramModel
from estimation_nodes.nodes.estimator import Estimator
from estimation_nodes.tools.replay.estimator import align
from tests.conftest import spin_until
from tests.node.test_estimator_node import OUTPUTS

SECOND = 10**9
#: Example 6.14's events with the times they happened: each move, then its reading.
EXAMPLE_6_14 = [
    (1 * SECOND, "motion_cmd", Int32(data=1)),
    (1 * SECOND + 5000, "tile_observation", String(data="bright")),
    (2 * SECOND, "motion_cmd", Int32(data=1)),
    (2 * SECOND + 5000, "tile_observation", String(data="dark")),
    (3 * SECOND, "motion_cmd", Int32(data=1)),
    (3 * SECOND + 5000, "tile_observation", String(data="dark")),
]
PREDICTED = [[0.2] * 5, [0.2375, 0.25, 0.2375, 0.1375, 0.1375],
             [0.1, 0.130714, 0.168571, 0.363571, 0.237143]]
CORRECTED = [[0.25, 0.25, 0.125, 0.125, 0.25],
             [0.135714, 0.142857, 0.407143, 0.235714, 0.078571],
             [0.048443, 0.063322, 0.244983, 0.528374, 0.114879]]


def make_estimator(context, executor, collector_factory, **overrides):
    estimator = Estimator(context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in overrides.items()])
    executor.add_node(estimator)
    out = collector_factory(OUTPUTS)
    assert spin_until(executor, lambda: all(
        s.get_publisher_count() >= 1 for s in out.subscriptions.values()), 10.0)
    return estimator, out


def deliver(estimator, events):
    """Hand each (stamp, topic, msg) to the estimator's callback for its topic."""
    callbacks = {s.topic_name.lstrip("/"): s.callback for s in estimator.subscriptions}
    for stamp, topic, msg in events:
        callbacks[topic](msg, {"source_timestamp": stamp, "received_timestamp": stamp + 1})


def beliefs(out, topic):
    return [np.frombuffer(m.data, dtype=np.float64) for m in out.messages[topic]]


@pytest.mark.parametrize("arrival", [
    (1, 0, 3, 2, 5, 4),        # every reading before the move that caused it
    (1, 3, 5, 0, 2, 4),        # all readings first (a partition healing), then the moves
    (0, 1, 2, 3, 4, 5),        # in order: nothing to reorder
])
def test_example_6_14_in_any_arrival_order_settles_on_the_book(context, executor,
                                                               collector_factory, arrival):
    estimator, out = make_estimator(context, executor, collector_factory, history_depth=100)
    deliver(estimator, [EXAMPLE_6_14[i] for i in arrival])
    assert spin_until(executor, lambda: len(out.messages["belief"]) >= 3
                      and np.allclose(beliefs(out, "belief")[-1], CORRECTED[-1], atol=1e-6), 10.0)
    spin_until(executor, lambda: False, 0.3)
    np.testing.assert_allclose(estimator._histogram.belief, CORRECTED[-1], atol=1e-6)
    # Every step of the book was published once it was settled, in order, and every
    # provisional estimate is followed by those that replace it.
    for topic, book in (("belief", CORRECTED), ("belief_predicted", PREDICTED)):
        alignment = align(beliefs(out, topic), book, 1e-6)
        assert alignment.matched == 3, topic
        assert all(i < alignment.last_match for i in alignment.superseded), topic
    reordered = estimator.reordering["reordered"]
    assert (reordered == 0) == (arrival == (0, 1, 2, 3, 4, 5))
    assert estimator.handled["motion_cmd"] == 3 and estimator.handled["tile_observation"] == 3


def test_the_kalman_filter_follows_the_causal_order_and_stamps_with_it(context, executor,
                                                                       collector_factory):
    """Example 6.18: each measurement arrives before the command it follows."""
    estimator, out = make_estimator(context, executor, collector_factory, history_depth=100,
                                    **{"kalman.x0": 3.0, "kalman.P0": 100.0,
                                       "kalman.var_u": 2.0, "kalman.var_z": 4.0})
    events = []
    for step, (u, z) in enumerate(zip([2, 3, 2, 1, 1], [2.0, 5.0, 7.0, 8.0, 9.0]), start=1):
        events += [(step * SECOND + 10, "position_measurement", Float64(data=z)),
                   (step * SECOND, "motion_cmd", Int32(data=u))]
    deliver(estimator, events)
    assert spin_until(executor, lambda: np.isclose(estimator._kalman.x[0], 9.005414,
                                                   atol=1e-6), 5.0)
    assert estimator._kalman.P[0, 0] == pytest.approx(2.005526, abs=1e-6)
    # Each measurement is published twice: provisional (before its move), then settled.
    assert spin_until(executor, lambda: len(out.messages["kalman_estimate_stamped"]) == 10, 5.0)
    assert {(m.header.stamp.sec, m.header.stamp.nanosec)
            for m in out.messages["kalman_estimate_stamped"]} == {(k, 10) for k in range(1, 6)}
    # The last estimate stamped at step k's measurement is the book's estimate k.
    settled = {}
    for m in out.messages["kalman_estimate_stamped"]:
        settled[m.header.stamp.sec] = m.pose.pose.position.x
    np.testing.assert_allclose([settled[k] for k in range(1, 6)],
                               [2.113208, 5.045977, 7.021958, 8.010857, 9.005414], atol=1e-6)


def test_an_event_older_than_the_horizon_is_applied_at_once_and_counted(
        context, executor, collector_factory):
    estimator, _ = make_estimator(context, executor, collector_factory,
                                  reorder_horizon=1.0)
    deliver(estimator, [(10 * SECOND, "motion_cmd", Int32(data=1)),
                        (20 * SECOND, "motion_cmd", Int32(data=1)),
                        (5 * SECOND, "tile_observation", String(data="bright"))])
    assert estimator.reordering["too_late"] == 1
    assert estimator.handled["tile_observation"] == 1


def test_horizon_zero_applies_in_arrival_order(context, executor, collector_factory):
    estimator, _ = make_estimator(context, executor, collector_factory, reorder_horizon=0.0)
    deliver(estimator, [EXAMPLE_6_14[i] for i in (1, 0, 3, 2, 5, 4)])
    assert estimator.reordering["reordered"] == 0
    assert not np.allclose(estimator._histogram.belief, CORRECTED[-1], atol=1e-3)


def test_a_rejected_late_event_leaves_the_estimate_and_counts_once(context, executor,
                                                                   collector_factory):
    estimator, _ = make_estimator(context, executor, collector_factory)
    deliver(estimator, EXAMPLE_6_14[:4])
    before = estimator._histogram.belief.copy()
    deliver(estimator, [(1 * SECOND + 10, "tile_observation", String(data="grey"))])
    np.testing.assert_array_equal(estimator._histogram.belief, before)
    assert estimator.rejected["unknown_class"] == 1
    assert estimator.reordering["reordered"] == 0


def test_a_reading_of_zero_evidence_before_its_move_is_taken_when_the_move_comes(
        context, executor, collector_factory):
    """One bright cell of eight, a sensor that never reads dark as bright: the second bright
    reading arrives before the move that brought the robot back to the bright cell."""
    world = ["bright"] + ["dark"] * 7
    classes, sensor_model = ["bright", "dark"], [0.8, 0.2, 0.0, 1.0]
    estimator, out = make_estimator(context, executor, collector_factory, history_depth=100,
                                    world=world, classes=classes, sensor_model=sensor_model)
    deliver(estimator, [(1 * SECOND, "tile_observation", String(data="bright")),
                        (2 * SECOND, "motion_cmd", Int32(data=2)),
                        (4 * SECOND, "tile_observation", String(data="bright"))])
    assert estimator.rejected["zero_evidence"] == 1
    deliver(estimator, [(3 * SECOND, "motion_cmd", Int32(data=6))])
    model = HistogramModel.from_lists(world, classes, sensor_model, [0.1, 0.8, 0.1])
    belief = histogram.uniform(model.size)
    belief, _ = histogram.correct(belief, model.likelihood("bright"))
    belief = histogram.predict(histogram.predict(belief, 2, model.kernel), 6, model.kernel)
    belief, _ = histogram.correct(belief, model.likelihood("bright"))
    np.testing.assert_allclose(estimator._histogram.belief, belief, rtol=0, atol=1e-12)
    # Published, and counted once: rejected when it came, taken on its retry.
    assert spin_until(executor, lambda: len(out.messages["belief"]) == 2, 5.0)
    np.testing.assert_allclose(beliefs(out, "belief")[-1], belief, rtol=0, atol=1e-12)
    assert estimator.rejected["zero_evidence"] == 1
    assert estimator.reordering["taken_on_retry"] == 1
    assert estimator.handled["tile_observation"] == 1
