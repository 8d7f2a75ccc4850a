"""The estimator's matrix mode with several inputs and outputs, and its simulated system."""

import numpy as np
import pytest
from geometry_msgs.msg import PoseWithCovariance
from rclpy.parameter import Parameter
from std_msgs.msg import Float64, Float64MultiArray, Int32

from estimation_nodes.core.kalman import linear as kalman
from estimation_nodes.core.kalman.filter import KalmanFilter
from estimation_nodes.core.kalman.models import GaussianState
from estimation_nodes.core.sim import draws as simulation
from estimation_nodes.nodes.estimator import Estimator
from estimation_nodes.nodes.linear_system import LinearSystem
from estimation_nodes.nodes.motion_commander import MotionCommander
from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos
from estimation_nodes.nodes.wire import from_state_message
from estimation_nodes.params.estimator import build_kalman_settings
from tests.conftest import spin_until
from tests.node.message_objects import (
    to_multiarray,
    to_pose_with_covariance,
    to_state_message,
)
from tests.unit.test_matrix_settings import TRACKING, values

OUTPUTS = {
    "kalman_state": Float64MultiArray,
    "kalman_state_predicted": Float64MultiArray,
    "kalman_estimate": PoseWithCovariance,
    "kalman_estimate_predicted": PoseWithCovariance,
}


@pytest.fixture
def tracker(context, executor, collector_factory):
    estimator = Estimator(context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in TRACKING.items()])
    executor.add_node(estimator)
    out = collector_factory(OUTPUTS)
    publishers = {topic: out.node.create_publisher(msg_type, topic, INPUT_QOS)
                  for topic, msg_type in (("kalman_input", Float64MultiArray),
                                          ("kalman_measurement", Float64MultiArray),
                                          ("motion_cmd", Int32),
                                          ("position_measurement", Float64))}
    assert spin_until(executor, lambda: all(
        p.get_subscription_count() >= 1 for p in publishers.values()), 10.0)

    def send(topic, msg):
        before = sum(estimator.handled.values()) + sum(estimator.rejected.values())
        publishers[topic].publish(msg)
        assert spin_until(executor, lambda: sum(estimator.handled.values())
                          + sum(estimator.rejected.values()) > before, 10.0)

    yield estimator, out, send
    estimator.destroy_node()


def vector(*values):
    return to_multiarray(np.array(values, dtype=float), "v")


def test_inputs_and_measurements_of_several_values_drive_the_filter(tracker, executor):
    estimator, out, send = tracker
    settings = build_kalman_settings(values())
    offline = KalmanFilter(settings.initial, settings.model)
    rng = np.random.default_rng(3)
    for step in range(1, 6):
        u, z = rng.normal(size=2), rng.normal(size=2) + step
        send("kalman_input", vector(*u))
        send("kalman_measurement", vector(*z))
        offline.predict(u)
        offline.correct(z)
    assert spin_until(executor, lambda: out.count("kalman_state") == 5
                      and out.count("kalman_estimate") == 5, 5.0)
    x, P = from_state_message(out.messages["kalman_state"][-1])
    np.testing.assert_allclose(x, offline.x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P, offline.P, rtol=1e-12, atol=1e-12)
    assert out.count("kalman_state_predicted") == 5
    pose = out.messages["kalman_estimate"][-1]
    assert (pose.pose.position.x, pose.pose.position.y) == (offline.x[0], offline.x[1])
    covariance = np.array(pose.covariance).reshape(6, 6)
    np.testing.assert_array_equal(covariance[:2, :2], offline.P[:2, :2])
    assert not covariance[2:, :].any() and not covariance[:, 2:].any()


@pytest.mark.parametrize("topic, values_sent, reason", [
    ("kalman_input", (1.0,), "wrong_size.kalman_input"),
    ("kalman_input", (1.0, 2.0, 3.0), "wrong_size.kalman_input"),
    ("kalman_measurement", (float("nan"), 1.0), "non_finite.kalman_measurement"),
    ("kalman_measurement", (1.0e308, -1.0e308), "numerical_overflow"),
])
def test_a_bad_vector_is_dropped_counted_and_changes_nothing(tracker, topic, values_sent,
                                                              reason):
    estimator, out, send = tracker
    before = (estimator._kalman.x.copy(), estimator._kalman.P.copy())
    send(topic, vector(*values_sent))
    assert estimator.rejected == {reason: 1}
    np.testing.assert_array_equal(estimator._kalman.x, before[0])
    np.testing.assert_array_equal(estimator._kalman.P, before[1])
    assert out.count("kalman_state") == 0 and out.count("kalman_state_predicted") == 0


@pytest.mark.parametrize("topic", ["kalman_input", "kalman_measurement"])
def test_bytes_that_are_no_vector_are_dropped_counted_and_change_nothing(tracker, executor,
                                                                          topic):
    """The vector inputs are read from their raw bytes: a publisher that sends bytes of
    its own (publish accepts them) is refused, not a crash, and the next vector works."""
    estimator, out, send = tracker
    before = (estimator._kalman.x.copy(), estimator._kalman.P.copy())
    send(topic, b"\x00\x01\x00\x00\x05\x00\x00\x00")   # five dimensions, then nothing
    assert estimator.rejected == {f"malformed.{topic}": 1}
    np.testing.assert_array_equal(estimator._kalman.x, before[0])
    np.testing.assert_array_equal(estimator._kalman.P, before[1])
    send(topic, vector(0.5, 0.25))
    assert estimator.handled[topic] == 1
    answer = "kalman_state_predicted" if topic == "kalman_input" else "kalman_state"
    assert spin_until(executor, lambda: out.count(answer) == 1, 5.0)


def test_scalar_topics_do_not_drive_a_filter_of_other_sizes(tracker):
    estimator, out, send = tracker
    send("motion_cmd", Int32(data=1))   # predicts the histogram only: m = 2
    send("position_measurement", Float64(data=1.0))
    assert estimator.rejected == {"wrong_size.position_measurement": 1}
    assert out.count("kalman_state_predicted") == 0


def test_example_6_18_through_matrix_mode_and_vector_topics(context, executor,
                                                              collector_factory):
    """Eq. 6.34 with A = B = C = F = 1 is Algorithm 4: the book's numbers, through topics."""
    estimator = Estimator(context=context, parameter_overrides=[
        Parameter("kalman.mode", value="matrix"),
        Parameter("kalman.matrix.x0", value=[3.0]),
        Parameter("kalman.matrix.P0", value=[100.0])])
    executor.add_node(estimator)
    out = collector_factory(OUTPUTS)
    u_pub = out.node.create_publisher(Float64MultiArray, "kalman_input", INPUT_QOS)
    z_pub = out.node.create_publisher(Float64MultiArray, "kalman_measurement", INPUT_QOS)
    try:
        assert spin_until(executor, lambda: u_pub.get_subscription_count()
                          and z_pub.get_subscription_count(), 10.0)
        for step, (u, z) in enumerate(zip([2, 3, 2, 1, 1], [2, 5, 7, 8, 9]), start=1):
            u_pub.publish(vector(u))
            assert spin_until(executor, lambda s=step: out.count("kalman_state_predicted") == s,
                              10.0)
            z_pub.publish(vector(z))
            assert spin_until(executor, lambda s=step: out.count("kalman_state") == s, 10.0)
        states = [from_state_message(m) for m in out.messages["kalman_state"]]
        np.testing.assert_allclose([x[0] for x, _ in states],
                                   [2.113208, 5.045977, 7.021958, 8.010857, 9.005414],
                                   atol=1e-6)
        np.testing.assert_allclose([P[0, 0] for _, P in states],
                                   [3.849057, 2.375479, 2.089661, 2.022167, 2.005526],
                                   atol=1e-6)
    finally:
        estimator.destroy_node()


def test_the_full_state_message_says_which_values_are_x_and_which_p():
    x, P = np.array([1.0, 2.0, 3.0]), np.arange(9.0).reshape(3, 3)
    msg = to_state_message(x, P)
    assert [d.label for d in msg.layout.dim] == ["row 0: x, rows 1-3: P", "state component"]
    assert [(d.size, d.stride) for d in msg.layout.dim] == [(4, 12), (3, 3)]
    assert list(msg.data) == [1.0, 2.0, 3.0, *range(9)]
    back = from_state_message(msg)
    np.testing.assert_array_equal(back[0], x)
    np.testing.assert_array_equal(back[1], P)


def test_a_heading_component_becomes_the_pose_orientation():
    x = np.array([1.0, 2.0, np.pi / 2])
    P = np.diag([0.1, 0.2, 0.3])
    pose = to_pose_with_covariance(x, P, [0, 1, -1, -1, -1, 2])
    q = pose.pose.orientation
    np.testing.assert_allclose([q.x, q.y, q.z, q.w], [0, 0, np.sqrt(0.5), np.sqrt(0.5)],
                               atol=1e-15)
    covariance = np.array(pose.covariance).reshape(6, 6)
    np.testing.assert_array_equal(np.diag(covariance), [0.1, 0.2, 0, 0, 0, 0.3])


def test_commander_and_simulated_system_close_the_loop(context, executor, collector_factory):
    settings = build_kalman_settings(values())
    params = [Parameter(k, value=v) for k, v in TRACKING.items() if k != "kalman.mode"
              and k != "kalman.pose_components"]
    system = LinearSystem(context=context, parameter_overrides=[
        *params, Parameter("seed", value=5),
        Parameter("hold_for_nodes", value=["test_collector"])])
    commander = MotionCommander(context=context, parameter_overrides=[
        Parameter("input_vectors", value=[0.5, 0.0, 0.0, 0.5]),
        Parameter("input_size", value=2), Parameter("required_subscribers", value=2),
        Parameter("required_nodes", value=["linear_system"]),
        Parameter("start_delay", value=0.0), Parameter("rate_hz", value=20.0)])
    seen = collector_factory({"kalman_input": (Float64MultiArray, INPUT_QOS),
                              "kalman_measurement": (Float64MultiArray, INPUT_QOS),
                              "true_state": (Float64MultiArray, latched_qos(100))})
    for node in (system, commander):
        executor.add_node(node)
    try:
        assert spin_until(executor, lambda: seen.count("kalman_measurement") == 2
                          and seen.count("true_state") == 2, 20.0)
        assert [list(m.data) for m in seen.messages["kalman_input"]] == [[0.5, 0.0],
                                                                        [0.0, 0.5]]
        rng = np.random.default_rng(5)
        x = GaussianState(np.array(TRACKING["kalman.matrix.x0"]), np.eye(4)).x
        for index, u in enumerate(([0.5, 0.0], [0.0, 0.5])):
            x, z = simulation.linear_system_step(x, np.array(u), settings.model, rng)
            np.testing.assert_array_equal(seen.messages["true_state"][index].data, x)
            np.testing.assert_array_equal(seen.messages["kalman_measurement"][index].data, z)
    finally:
        system.destroy_node()
        commander.destroy_node()


def test_the_scalar_kalman_still_agrees_with_algorithm_4():
    x, var = kalman.predict_scalar(3.0, 100.0, 2.0, 2.0)
    assert (x, var) == (5.0, 102.0)


def test_the_simulated_system_drops_an_input_it_cannot_follow(context, executor,
                                                              collector_factory):
    params = [Parameter(k, value=v) for k, v in TRACKING.items()
              if k.startswith("kalman.matrix.")]
    # No measurement subscriber here: it takes inputs without waiting for one.
    system = LinearSystem(context=context, parameter_overrides=[
        *params, Parameter("hold_until_matched", value=False)])
    executor.add_node(system)
    out = collector_factory({"true_state": (Float64MultiArray, latched_qos(100))})
    inputs = out.node.create_publisher(Float64MultiArray, "kalman_input", INPUT_QOS)
    try:
        assert spin_until(executor, lambda: inputs.get_subscription_count() >= 1, 10.0)
        for bad in (vector(1.0), vector(float("nan"), 0.0)):
            inputs.publish(bad)
        # Accelerations of 1e308 push the velocity past what a double holds by the
        # fourth step: from then on each such input is dropped, never published as inf.
        for _ in range(6):
            inputs.publish(vector(1.0e308, 1.0e308))
        assert spin_until(executor, lambda: system.rejected + out.count("true_state") == 8,
                          10.0)
        assert system.rejected == 2 + 3 and out.count("true_state") == 3
        assert all(np.isfinite(m.data).all() for m in out.messages["true_state"])
        [result] = system.set_parameters([Parameter("kalman.matrix.A", value=[1.0] * 16)])
        assert not result.successful   # read-only: the simulation runs one model
    finally:
        system.destroy_node()
