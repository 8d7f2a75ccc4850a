"""The motion commander and the tile sensor in-process."""

import numpy as np
import pytest
from rclpy.parameter import Parameter
from std_msgs.msg import Float64, Int32, Int64, String

from estimation_nodes.core.sim import draws as simulation
from estimation_nodes.core.tiles.models import HistogramModel
from estimation_nodes.nodes.motion_commander import MotionCommander
from estimation_nodes.nodes.parameters import ConfigurationError
from estimation_nodes.nodes.qos import INPUT_QOS
from estimation_nodes.nodes.tile_sensor import TileSensor
from tests.conftest import spin_until


def params(**values):
    return [Parameter(k, value=v) for k, v in values.items()]


def test_commander_waits_for_subscribers_then_sends_the_sequence(context, executor):
    commander = MotionCommander(context=context, parameter_overrides=params(
        commands=[2, -1], repeat=True, max_commands=5, rate_hz=50.0, required_subscribers=1,
        required_nodes=["motion_commander"], start_delay=0.0))
    executor.add_node(commander)
    try:
        # Nobody listens: nothing may be sent, however long it spins.
        spin_until(executor, lambda: False, 0.5)
        assert commander.sent == 0
        received = []
        commander.create_subscription(Int32, "motion_cmd", lambda m: received.append(m.data),
                                      INPUT_QOS)
        assert spin_until(executor, lambda: len(received) == 5, 10.0)
        spin_until(executor, lambda: False, 0.2)
        assert received == [2, -1, 2, -1, 2]
    finally:
        commander.destroy_node()


def test_commander_without_commands_is_a_configuration_error(context):
    with pytest.raises(ConfigurationError, match="commands"):
        MotionCommander(context=context, parameter_overrides=[
            Parameter("commands", Parameter.Type.INTEGER_ARRAY, [])])


def sensor_outputs(context, executor, collector_factory, overrides, commands):
    sensor = TileSensor(context=context, parameter_overrides=params(
        hold_for_nodes=["test_collector"], **overrides))
    executor.add_node(sensor)
    out = collector_factory({"tile_observation": (String, INPUT_QOS),
                             "position_measurement": (Float64, INPUT_QOS),
                             "true_position": Int64})
    pub = out.node.create_publisher(Int32, "motion_cmd", INPUT_QOS)
    assert spin_until(executor, lambda: pub.get_subscription_count() == 1, 10.0)
    for u in commands:
        pub.publish(Int32(data=u))
    assert spin_until(executor, lambda: out.count("true_position") == len(commands), 10.0)
    spin_until(executor, lambda: False, 0.2)
    sensor.destroy_node()
    return out.messages


def test_scripted_sensor_replays_its_script(context, executor, collector_factory):
    got = sensor_outputs(context, executor, collector_factory, dict(
        scripted_observations=["bright", "dark", "dark"], initial_cell=0), [1, 1, 1, 1])
    assert [m.data for m in got["tile_observation"]] == ["bright", "dark", "dark"]
    assert [m.data for m in got["true_position"]] == [1, 2, 3, 4]
    assert got["position_measurement"] == []


def test_seeded_sensor_is_reproducible_and_follows_the_models(context, executor,
                                                              collector_factory):
    got = sensor_outputs(context, executor, collector_factory,
                         dict(seed=11, measurement_variance=0.25), [1] * 20)
    # The same draws, made here with the core's samplers, give the same run.
    model, rng, position = HistogramModel.book(), np.random.default_rng(11), 0
    for step in range(20):
        position += 1 + simulation.sample_offset(model.kernel, rng)
        observed = simulation.sample_observation(model.sensor.probabilities,
                                                model.cell_class_index(position), rng)
        z = position + 0.5 * rng.standard_normal()
        assert got["true_position"][step].data == position
        assert got["tile_observation"][step].data == model.sensor.classes[observed]
        assert got["position_measurement"][step].data == pytest.approx(z, abs=1e-12)


def test_sensor_rejects_unknown_scripted_class(context):
    with pytest.raises(ConfigurationError, match="unknown tile class 'grey'"):
        TileSensor(context=context, parameter_overrides=params(scripted_observations=["grey"]))


def test_sensor_takes_commands_once_its_readings_reach_the_estimator_and_holds_after(
        context, executor, collector_factory):
    """No command before the readings can go out at once (a reading held and sent later
    would carry a later time than the moves after it); an estimator that leaves later
    gets what was read meanwhile when it is back."""
    sensor = TileSensor(context=context, parameter_overrides=params(
        scripted_observations=["bright", "dark", "dark"], hold_for_nodes=["late"]))
    executor.add_node(sensor)
    driver = collector_factory({"true_position": Int64}, name="driver")
    pub = driver.node.create_publisher(Int32, "motion_cmd", INPUT_QOS)
    spin_until(executor, lambda: False, 0.5)
    assert pub.get_subscription_count() == 0       # nobody hears the readings yet
    late = collector_factory({"tile_observation": (String, INPUT_QOS),
                              "position_measurement": (Float64, INPUT_QOS)}, name="late")
    assert spin_until(executor, lambda: pub.get_subscription_count() == 1, 10.0)
    pub.publish(Int32(data=1))
    assert spin_until(executor, lambda: late.count("tile_observation") == 1, 10.0)
    # The estimator leaves: readings are held, then sent in order when one is back.
    late.node.destroy_subscription(late.subscriptions.pop("tile_observation"))
    assert spin_until(executor, lambda: sensor._tile_pub._publisher.get_subscription_count()
                      == 0, 10.0)
    for _ in range(2):
        pub.publish(Int32(data=1))
    assert spin_until(executor, lambda: driver.count("true_position") == 3, 10.0)
    assert sensor._tile_pub.held == 2
    back = collector_factory({"tile_observation": (String, INPUT_QOS),
                              "position_measurement": (Float64, INPUT_QOS)}, name="late")
    assert spin_until(executor, lambda: back.count("tile_observation") == 2, 10.0)
    assert [m.data for m in back.messages["tile_observation"]] == ["dark", "dark"]
    assert sensor._tile_pub.held == 0
    sensor.destroy_node()


def test_sensor_holds_readings_for_the_estimator_not_for_a_recorder(context, executor,
                                                                   collector_factory):
    """A recorder that matches first does not let the sensor start: it takes commands
    once a subscriber named as in hold_for_nodes (estimator by default) hears it."""
    sensor = TileSensor(context=context, parameter_overrides=params(
        scripted_observations=["bright", "dark", "dark"]))
    executor.add_node(sensor)
    recorder = collector_factory({"tile_observation": (String, INPUT_QOS),
                                  "true_position": Int64}, name="recorder")
    pub = recorder.node.create_publisher(Int32, "motion_cmd", INPUT_QOS)
    assert spin_until(executor, lambda: sensor._tile_pub._publisher.get_subscription_count()
                      == 1, 10.0)
    spin_until(executor, lambda: False, 0.5)
    assert pub.get_subscription_count() == 0
    estimator = collector_factory({"tile_observation": (String, INPUT_QOS),
                                   "position_measurement": (Float64, INPUT_QOS)},
                                  name="estimator")
    assert spin_until(executor, lambda: pub.get_subscription_count() == 1, 10.0)
    for _ in range(3):
        pub.publish(Int32(data=1))
    assert spin_until(executor, lambda: estimator.count("tile_observation") == 3
                      and recorder.count("tile_observation") == 3, 10.0)
    assert [m.data for m in estimator.messages["tile_observation"]] == ["bright", "dark", "dark"]
    sensor.destroy_node()


def test_commander_waits_for_its_required_nodes_not_for_any_subscriber(context, executor,
                                                                      collector_factory):
    commander = MotionCommander(context=context, parameter_overrides=params(
        commands=[1], max_commands=1, rate_hz=50.0, required_subscribers=1, start_delay=0.0))
    executor.add_node(commander)
    try:
        recorder = collector_factory({"motion_cmd": (Int32, INPUT_QOS)}, name="recorder")
        spin_until(executor, lambda: False, 0.5)
        assert commander.sent == 0            # the default: estimator and tile_sensor
        collector_factory({"motion_cmd": (Int32, INPUT_QOS)}, name="estimator")
        spin_until(executor, lambda: False, 0.5)
        assert commander.sent == 0
        sensor = collector_factory({"motion_cmd": (Int32, INPUT_QOS)}, name="tile_sensor")
        assert spin_until(executor, lambda: sensor.count("motion_cmd") == 1
                          and recorder.count("motion_cmd") == 1, 10.0)
    finally:
        commander.destroy_node()
