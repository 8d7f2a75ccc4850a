"""The estimator in-process, driven by a test node, with a fresh Context per test."""

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovariance, PoseWithCovarianceStamped
from rclpy.parameter import Parameter
from std_msgs.msg import Float64, Float64MultiArray, Int32, String
from std_srvs.srv import Trigger

from estimation_nodes.core.kalman import linear as kalman
from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.models import HistogramModel
from estimation_nodes.nodes.estimator import Estimator
from estimation_nodes.nodes.parameters import ConfigurationError, warn_unknown_parameters
from estimation_nodes.nodes.qos import INPUT_QOS
from tests.conftest import spin_until

OUTPUTS = {
    "belief_predicted": Float64MultiArray,
    "belief": Float64MultiArray,
    "kalman_estimate": PoseWithCovariance,
    "kalman_estimate_stamped": PoseWithCovarianceStamped,
    "kalman_estimate_predicted": PoseWithCovariance,
    "kalman_estimate_predicted_stamped": PoseWithCovarianceStamped,
}


class Driver:
    """Publishes inputs to the estimator and waits for its outputs."""

    def __init__(self, context, executor, collector_factory, **overrides):
        self.executor = executor
        self.estimator = Estimator(
            context=context,
            parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()])
        executor.add_node(self.estimator)
        self.out = collector_factory(OUTPUTS)
        node = self.out.node
        self.cmd = node.create_publisher(Int32, "motion_cmd", INPUT_QOS)
        self.tile = node.create_publisher(String, "tile_observation", INPUT_QOS)
        self.z = node.create_publisher(Float64, "position_measurement", INPUT_QOS)
        assert spin_until(executor, lambda: all(
            p.get_subscription_count() >= 1 for p in (self.cmd, self.tile, self.z)), 10.0)

    def send(self, publisher, msg, topic=None, handled=None):
        """Publish and wait until the estimator has handled or rejected it."""
        before = sum(self.estimator.handled.values()) + sum(self.estimator.rejected.values())
        publisher.publish(msg)
        assert spin_until(self.executor, lambda: sum(self.estimator.handled.values())
                          + sum(self.estimator.rejected.values()) > before, 10.0)
        if topic is not None:
            assert spin_until(self.executor, lambda: self.out.count(topic) >= handled, 5.0)

    def belief(self, topic="belief", index=-1):
        return np.frombuffer(self.out.messages[topic][index].data, dtype=np.float64)

    def destroy(self):
        self.estimator.destroy_node()


@pytest.fixture
def driver(context, executor, collector_factory):
    made = []

    def make(**overrides):
        d = Driver(context, executor, collector_factory, **overrides)
        made.append(d)
        return d

    yield make
    for d in made:
        d.destroy()


def test_example_6_14_through_the_node(driver):
    d = driver()
    book = HistogramModel.book()
    expected = histogram.uniform(5)
    for step, observed in enumerate(["bright", "dark", "dark"], start=1):
        d.send(d.cmd, Int32(data=1), "belief_predicted", step)
        d.send(d.tile, String(data=observed), "belief", step)
        predicted = histogram.predict(expected, 1, book.kernel)
        expected, _ = histogram.correct(predicted, book.likelihood(observed))
        np.testing.assert_allclose(d.belief("belief_predicted"), predicted, atol=1e-12)
        np.testing.assert_allclose(d.belief(), expected, atol=1e-12)
    np.testing.assert_allclose(d.belief(), [0.048443, 0.063322, 0.244983, 0.528374, 0.114879],
                               atol=1e-6)
    dim = d.out.messages["belief"][-1].layout.dim[0]
    assert (dim.label, dim.size, dim.stride) == ("cells", 5, 5)


def test_example_6_18_through_the_node(driver):
    d = driver(**{"kalman.x0": 3.0, "kalman.P0": 100.0, "frame_id": "odom"})
    for step, (u, z) in enumerate(zip([2, 3, 2, 1, 1], [2.0, 5.0, 7.0, 8.0, 9.0]), start=1):
        d.send(d.cmd, Int32(data=u))
        d.send(d.z, Float64(data=z), "kalman_estimate_stamped", step)
    xs = [m.pose.position.x for m in d.out.messages["kalman_estimate"]]
    variances = [m.covariance[0] for m in d.out.messages["kalman_estimate"]]
    np.testing.assert_allclose(xs, [2.113208, 5.045977, 7.021958, 8.010857, 9.005414], atol=1e-6)
    np.testing.assert_allclose(variances, [3.849057, 2.375479, 2.089661, 2.022167, 2.005526],
                               atol=1e-6)
    stamped = d.out.messages["kalman_estimate_stamped"][-1]
    assert stamped.header.frame_id == "odom"
    assert stamped.pose.pose.position.x == xs[-1]


def test_bad_messages_are_dropped_counted_and_leave_state_alone(driver):
    d = driver()
    d.send(d.cmd, Int32(data=1), "belief_predicted", 1)
    d.send(d.tile, String(data="dark"), "belief", 1)
    belief_before = d.belief().copy()
    kalman_before = d.estimator._kalman.estimate
    d.send(d.tile, String(data="purple"))
    d.send(d.tile, String(data=""))
    for bad in (math.nan, math.inf, -math.inf):
        d.send(d.z, Float64(data=bad))
    assert d.estimator.rejected == {"unknown_class": 2, "non_finite_measurement": 3}
    assert d.out.count("belief") == 1 and d.out.count("kalman_estimate") == 0
    np.testing.assert_array_equal(d.estimator._histogram.belief, belief_before)
    assert d.estimator._kalman.estimate == kalman_before
    # Later good messages are processed as if the bad ones never came.
    d.send(d.tile, String(data="bright"), "belief", 2)
    expected, _ = histogram.correct(belief_before, HistogramModel.book().likelihood("bright"))
    np.testing.assert_allclose(d.belief(), expected, atol=1e-15)


def test_zero_evidence_observation_is_rejected_without_nan(driver):
    # A sensor that never mistakes dark for bright, and a prior certain of a bright cell.
    d = driver(sensor_model=[1.0, 0.0, 0.0, 1.0], initial_belief=[1.0, 0.0, 0.0, 0.0, 0.0],
               motion_kernel=[1.0])
    d.send(d.tile, String(data="dark"))
    assert d.estimator.rejected["zero_evidence"] == 1
    assert d.out.count("belief") == 0
    np.testing.assert_array_equal(d.estimator._histogram.belief, [1.0, 0, 0, 0, 0])


def test_huge_command_wraps_exactly(driver):
    d = driver(motion_kernel=[0.0, 1.0, 0.0], initial_belief=[1.0, 0.0, 0.0, 0.0, 0.0])
    d.send(d.cmd, Int32(data=2**31 - 1), "belief_predicted", 1)
    np.testing.assert_array_equal(d.belief("belief_predicted"),
                                  histogram.one_hot(5, (2**31 - 1) % 5))


def test_reset_service_restores_initial_state(driver, executor):
    d = driver()
    d.send(d.cmd, Int32(data=1), "belief_predicted", 1)
    d.send(d.tile, String(data="dark"), "belief", 1)
    d.send(d.z, Float64(data=4.0), "kalman_estimate", 1)
    client = d.out.node.create_client(Trigger, "/estimator/reset")
    assert client.wait_for_service(timeout_sec=10.0)
    future = client.call_async(Trigger.Request())
    assert spin_until(executor, future.done, 10.0)
    assert future.result().success
    np.testing.assert_array_equal(d.estimator._histogram.belief, histogram.uniform(5))
    assert d.estimator._kalman.estimate == (0.0, 100.0)
    # ...and says so on every output, so a late subscriber gets the state after the reset.
    for topic in ("belief_predicted", "belief"):
        assert spin_until(executor, lambda t=topic: d.out.count(t) == 2, 5.0)
        np.testing.assert_array_equal(d.belief(topic), histogram.uniform(5))
    for topic in ("kalman_estimate", "kalman_estimate_predicted"):
        assert spin_until(executor, lambda t=topic: d.out.count(t) == 2, 5.0)
        estimate = d.out.messages[topic][-1]
        assert (estimate.pose.position.x, estimate.covariance[0]) == (0.0, 100.0)


@pytest.mark.parametrize("matrix", [False, True])
def test_extreme_measurements_never_make_the_estimate_non_finite(driver, matrix):
    d = driver(**{"kalman.mode": "matrix"} if matrix else {})
    d.send(d.z, Float64(data=4.0), "kalman_estimate", 1)
    before = d.estimator._kalman.estimate
    for extreme in (1.0e308, -1.0e308, 1.0e200, -1.0e308):
        d.send(d.z, Float64(data=extreme))
    assert d.estimator.rejected == {"numerical_overflow": 4}
    assert d.out.count("kalman_estimate") == 1
    assert d.estimator._kalman.estimate == before
    d.send(d.z, Float64(data=5.0), "kalman_estimate", 2)   # later ones as if none came
    x, var, _ = kalman.correct_scalar(before.x, before.var, 5.0, 4.0)
    pose = d.out.messages["kalman_estimate"][-1]
    np.testing.assert_allclose([pose.pose.position.x, pose.covariance[0]], [x, var], rtol=1e-12)


def test_the_kalman_prediction_is_published(driver):
    """Example 6.18's predictions (Algorithm 4): x0 3, P0 100, var_u 2, u 2 then 3."""
    d = driver(**{"kalman.x0": 3.0})
    d.send(d.cmd, Int32(data=2), "kalman_estimate_predicted", 1)
    d.send(d.z, Float64(data=2.0), "kalman_estimate", 1)
    d.send(d.cmd, Int32(data=3), "kalman_estimate_predicted", 2)
    predicted = [(m.pose.position.x, m.covariance[0])
                 for m in d.out.messages["kalman_estimate_predicted"]]
    np.testing.assert_allclose(predicted, [(5.0, 102.0), (5.113208, 5.849057)], atol=1e-6)
    stamped = d.out.messages["kalman_estimate_predicted_stamped"]
    assert spin_until(d.executor, lambda: len(stamped) == 2, 5.0)
    assert stamped[-1].header.frame_id == "map"


def test_a_misspelled_parameter_is_named_with_the_closest_known_one(context):
    estimator = Estimator(context=context, parameter_overrides=[
        Parameter("motion_kernal", value=[0.1, 0.8, 0.1]), Parameter("seed", value=3)])
    try:
        # seed is the tile sensor's: given to every node by a shared section, no mistake.
        assert warn_unknown_parameters(estimator) == ["motion_kernal"]
    finally:
        estimator.destroy_node()


def test_diagnostics_before_the_first_event_show_no_nan_or_negative_zero(driver, executor):
    d = driver(initial_belief=[0.0, 1.0, 0.0, 0.0, 0.0], diagnostics_period=0.05)
    seen = d.out.node.create_subscription(
        DiagnosticArray, "/diagnostics", lambda msg: received.append(msg), 10)
    received: list = []
    assert spin_until(executor, lambda: received, 5.0), seen
    values = {kv.key: kv.value for kv in received[-1].status[0].values}
    assert values["belief_entropy_bits"] == "0"
    assert "last_evidence" not in values and "kalman_nis" not in values
    assert not [k for k, v in values.items() if v in ("nan", "-0")]


@pytest.mark.parametrize("name, value, reason", [
    ("motion_kernel", [0.5, 0.5], "odd number"),
    ("motion_kernel", [0.2, -0.1, 0.9], r"[0, 1]"),
    ("motion_kernel", [0.1, 0.8, 0.2], "summing to 1"),
    ("sensor_model", [0.8, 0.3, 0.4, 0.6], "summing to 1"),
    ("sensor_model", [0.5, 0.5, 1.0], "square"),
    ("world", [""], "non-empty"),
    ("initial_belief", [0.0] * 5, "positive sum"),
    ("kalman.var_u", 0.0, "var_u"),
    ("kalman.var_u", 1.0e308, "kalman.var_u"),
    ("kalman.var_z", math.nan, "var_z"),
    ("kalman.P0", -1.0, "P0"),
    ("kalman.x0", 1.0e300, "kalman.x0"),
    ("frame_id", "", "frame_id"),
])
def test_runtime_parameter_change_rejected_and_filter_untouched(driver, name, value, reason):
    d = driver()
    d.send(d.cmd, Int32(data=1), "belief_predicted", 1)
    d.send(d.tile, String(data="dark"), "belief", 1)
    before = d.estimator._histogram.belief.copy()
    [result] = d.estimator.set_parameters([Parameter(name, value=value)])
    assert not result.successful
    assert name.split(".")[-1] in result.reason and reason in result.reason
    d.send(d.cmd, Int32(data=0), "belief_predicted", 2)
    book = HistogramModel.book()
    np.testing.assert_allclose(d.belief("belief_predicted"),
                               histogram.predict(before, 0, book.kernel), atol=1e-15)


@pytest.mark.parametrize("name, value, reason", [
    ("world", ["bright", "purple"], "purple"),
    ("initial_belief", [0.5, 0.5], "expected 5 values"),
    ("classes", ["bright", "dark", "grey"], "sensor_model"),
])
def test_a_change_that_does_not_fit_the_others_is_held_and_the_filter_untouched(
        driver, name, value, reason):
    d = driver()
    d.send(d.cmd, Int32(data=1), "belief_predicted", 1)
    d.send(d.tile, String(data="dark"), "belief", 1)
    before = d.estimator._histogram.belief.copy()
    [result] = d.estimator.set_parameters([Parameter(name, value=value)])
    # rclpy drops the reason of a successful change: the node logs it and /diagnostics
    # carries it.
    assert result.successful
    assert "held" in d.estimator.held_reason and reason in d.estimator.held_reason
    d.send(d.cmd, Int32(data=0), "belief_predicted", 2)
    book = HistogramModel.book()
    np.testing.assert_allclose(d.belief("belief_predicted"),
                               histogram.predict(before, 0, book.kernel), atol=1e-15)


@pytest.mark.parametrize("order, held", [
    ((0, 1, 2), (True, True, False)),
    ((2, 0, 1), (True, True, False)),
    # A 3 x 3 sensor model and three classes agree with the old two-class world.
    ((1, 2, 0), (True, False, False)),
])
def test_changes_of_several_parameters_apply_once_they_agree(driver, order, held):
    """Three classes need a new sensor model and world: held until the last one is set,
    in any order, as `ros2 param set` one at a time and `ros2 param load` do."""
    d = driver()
    changes = [("world", ["grey", "dark", "bright", "grey"]),
               ("sensor_model", [0.8, 0.1, 0.1, 0.1, 0.8, 0.1, 0.1, 0.1, 0.8]),
               ("classes", ["bright", "dark", "grey"])]
    for index, expect_held in zip(order, held):
        name, value = changes[index]
        [result] = d.estimator.set_parameters([Parameter(name, value=value)])
        assert result.successful
        assert (d.estimator.held_reason is not None) == expect_held, name
    assert d.estimator._histogram.belief.size == 4
    d.send(d.tile, String(data="grey"), "belief", 2)   # 1: the reset of the new world
    np.testing.assert_allclose(d.belief(), [0.8 / 1.8, 0.1 / 1.8, 0.1 / 1.8, 0.8 / 1.8])


def test_a_held_histogram_change_does_not_hold_up_the_kalman_filter(driver):
    d = driver()
    [result] = d.estimator.set_parameters([Parameter("classes", value=["a", "b", "c"])])
    assert result.successful and "sensor_model" in d.estimator.held_reason
    [result] = d.estimator.set_parameters([Parameter("kalman.var_z", value=9.0)])
    assert result.successful
    assert d.estimator._settings.kalman.model.var_z == 9.0
    assert "sensor_model" in d.estimator.held_reason   # the histogram part still waits


def test_in_scalar_mode_a_matrix_value_is_checked_alone_and_never_holds(driver):
    d = driver()
    [result] = d.estimator.set_parameters([Parameter("kalman.matrix.x0", value=[0.0, 0.0])])
    assert result.successful and d.estimator.held_reason is None
    [result] = d.estimator.set_parameters([Parameter("kalman.matrix.Q", value=[1.0, 2.0])])
    assert not result.successful and "kalman.matrix.Q" in result.reason


def test_a_new_state_size_restarts_the_matrix_filter(driver, executor):
    d = driver(**{"kalman.mode": "matrix"})
    d.send(d.z, Float64(data=4.0), "kalman_estimate", 1)
    for name, value in (("kalman.matrix.x0", [1.0, 0.0]),
                        ("kalman.matrix.P0", [1.0, 0.0, 0.0, 1.0]),
                        ("kalman.matrix.A", [1.0, 1.0, 0.0, 1.0]),
                        ("kalman.matrix.B", [0.0, 1.0]), ("kalman.matrix.C", [1.0, 0.0]),
                        ("kalman.matrix.F", [0.0, 1.0]), ("kalman.matrix.Q", [0.1])):
        [result] = d.estimator.set_parameters([Parameter(name, value=value)])
        assert result.successful, result.reason
    assert d.estimator.held_reason is None
    np.testing.assert_array_equal(d.estimator._kalman.x, [1.0, 0.0])   # restarted from x0
    assert spin_until(executor, lambda: d.out.count("kalman_estimate") == 2, 5.0)
    d.send(d.cmd, Int32(data=2), "kalman_estimate_predicted", 2)
    np.testing.assert_allclose(d.estimator._kalman.x, [1.0, 2.0])   # A x + B u
    assert not d.estimator.rejected


def test_a_parameter_cannot_be_deleted(driver):
    # rclpy refuses to undeclare a statically typed parameter (`ros2 param delete`): the
    # way back to a uniform prior is N equal values (next test).
    d = driver(initial_belief=[1.0, 0.0, 0.0, 0.0, 0.0])
    [result] = d.estimator.set_parameters([Parameter("initial_belief")])
    assert not result.successful and "cannot be undeclared" in result.reason
    assert d.estimator.has_parameter("initial_belief")


def test_the_prior_back_to_uniform(driver):
    d = driver(initial_belief=[1.0, 0.0, 0.0, 0.0, 0.0])
    [result] = d.estimator.set_parameters([Parameter("initial_belief", value=[1.0] * 5)])
    assert result.successful and not result.reason
    np.testing.assert_array_equal(d.estimator._histogram.belief, histogram.uniform(5))


def test_valid_runtime_change_applies_at_next_event(driver):
    d = driver()
    [result] = d.estimator.set_parameters([Parameter("motion_kernel", value=[0.0, 1.0, 0.0])])
    assert result.successful
    [result] = d.estimator.set_parameters(
        [Parameter("world", value=["dark", "bright", "bright"])])
    assert result.successful
    d.send(d.cmd, Int32(data=1), "belief_predicted", 1)
    np.testing.assert_allclose(d.belief("belief_predicted"), [1 / 3] * 3)
    d.send(d.tile, String(data="dark"), "belief", 2)   # 1: the new world's reset belief
    np.testing.assert_allclose(d.belief(), [0.6, 0.2, 0.2])


def test_read_only_parameter_cannot_change(driver):
    d = driver()
    [result] = d.estimator.set_parameters([Parameter("kalman.mode", value="matrix")])
    assert not result.successful


def test_invalid_start_up_parameter_is_a_configuration_error(context):
    with pytest.raises(ConfigurationError, match="motion_kernel: expected an odd number"):
        Estimator(context=context,
                  parameter_overrides=[Parameter("motion_kernel", value=[0.5, 0.5])])


def test_matrix_mode_constant_velocity(driver):
    # State (position, velocity); the command nudges the velocity's estimate not at all:
    # B = [1, 0]' adds u to the position as the scalar filter does.
    d = driver(**{
        "kalman.mode": "matrix",
        "kalman.matrix.x0": [3.0, 0.0], "kalman.matrix.P0": [100.0, 0.0, 0.0, 1.0],
        "kalman.matrix.A": [1.0, 0.0, 0.0, 1.0], "kalman.matrix.B": [1.0, 0.0],
        "kalman.matrix.C": [1.0, 0.0], "kalman.matrix.F": [1.0, 0.0, 0.0, 1.0],
        "kalman.matrix.Q": [2.0, 0.0, 0.0, 0.0], "kalman.matrix.R": [4.0],
    })
    for step, (u, z) in enumerate(zip([2, 3, 2, 1, 1], [2.0, 5.0, 7.0, 8.0, 9.0]), start=1):
        d.send(d.cmd, Int32(data=u))
        d.send(d.z, Float64(data=z), "kalman_estimate", step)
    xs = [m.pose.position.x for m in d.out.messages["kalman_estimate"]]
    np.testing.assert_allclose(xs, [2.113208, 5.045977, 7.021958, 8.010857, 9.005414], atol=1e-6)


def test_kalman_change_reuses_the_histogram_model_and_a_world_change_rebuilds_it(driver):
    d = driver()
    model = d.estimator._settings.histogram
    [result] = d.estimator.set_parameters([Parameter("kalman.var_z", value=9.0)])
    assert result.successful
    assert d.estimator._settings.histogram is model
    assert d.estimator._settings.kalman.model.var_z == 9.0
    [result] = d.estimator.set_parameters([Parameter("motion_kernel", value=[0.2, 0.6, 0.2])])
    assert result.successful
    assert d.estimator._settings.histogram is not model
    np.testing.assert_array_equal(d.estimator._settings.histogram.kernel.weights,
                                  [0.2, 0.6, 0.2])


@pytest.mark.parametrize("compiled", [True, False])
def test_large_world_on_either_histogram_code_path(driver, compiled):
    size = histogram.COMPILED_MIN_CELLS
    rng = np.random.default_rng(4)
    world = [str(c) for c in np.where(rng.random(size) < 0.5, "dark", "bright")]
    d = driver(world=world, compiled_kernels=compiled)
    assert d.estimator._histogram.compiled is compiled
    model = d.estimator._settings.histogram
    expected = histogram.uniform(size)
    for step, (u, observed) in enumerate([(1, "bright"), (3, "dark"), (-2, "dark")], start=1):
        d.send(d.cmd, Int32(data=u), "belief_predicted", step)
        d.send(d.tile, String(data=observed), "belief", step)
        # The reference always takes numpy's path.
        predicted = histogram.predict(expected, u, model.kernel, compiled=False)
        expected, _ = histogram.correct(predicted, model.likelihood(observed), compiled=False)
        np.testing.assert_allclose(d.belief("belief_predicted"), predicted, rtol=1e-12)
        np.testing.assert_allclose(d.belief(), expected, rtol=1e-12)


def test_a_publisher_with_incompatible_qos_is_reported(driver, executor):
    # A best-effort publisher cannot reach the estimator's reliable inputs; the
    # estimator's input-event waitable must hear of it and count it.
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    d = driver()
    best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
    d.out.node.create_publisher(String, "tile_observation", best_effort)
    assert spin_until(executor, lambda: d.estimator.qos_incompatible["tile_observation"] >= 1,
                      10.0)
    assert d.estimator.qos_incompatible["motion_cmd"] == 0
