"""The simulated robot: it moves on each command and reports the tile it sees.

On every ``motion_cmd`` it moves by the command plus an offset drawn from the
motion kernel, then publishes ``true_position``, one ``tile_observation``
drawn from the sensor model and one ``position_measurement`` with Gaussian
noise. In scripted mode (either script parameter set) it moves by exactly the
command and publishes the next scripted observation and measurement instead,
which is how the textbook's examples are replayed.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np
from rclpy.node import Node
from std_msgs.msg import Float64, Int32, Int64, String

from estimation_nodes.core import histogram
from estimation_nodes.core.config import check_finite, check_positive
from estimation_nodes.nodes.ros_common import (
    INPUT_QOS,
    ConfigurationError,
    declare_parameters,
    latched_qos,
    main_for,
    parameter_values,
)
from estimation_nodes.settings import UNSET, WORLD_SPECS, ParamSpec, build_histogram_model

SENSOR_SPECS = WORLD_SPECS + (
    ParamSpec("initial_cell", 0, "True starting cell of the robot (index, 0-based).",
              read_only=True),
    ParamSpec("seed", -1, "Seed of the random motion and sensor noise; -1 draws one from the "
              "operating system.", read_only=True),
    ParamSpec("measurement_variance", 4.0,
              "Variance of the Gaussian noise on position_measurement (cells^2, > 0).",
              read_only=True),
    ParamSpec("scripted_observations", UNSET,
              "Scripted mode: tile classes to publish, one per command, instead of sampling.",
              read_only=True, type_name="string_array"),
    ParamSpec("scripted_measurements", UNSET,
              "Scripted mode: position measurements to publish, one per command.",
              read_only=True, type_name="double_array"),
    ParamSpec("hold_until_matched", True,
              "Keep readings (up to 1000 per topic) while no subscriber is matched on their "
              "topic and send them, in order, once one is: a sensor (re)started before the "
              "estimator has discovered it loses nothing.", read_only=True),
)

#: How often held readings are checked for a matched subscriber.
FLUSH_PERIOD_S = 0.02
#: Readings kept per topic while nobody listens; the oldest go first beyond that.
HOLD_LIMIT = 1000


class HeldPublisher:
    """A publisher that keeps its messages while no subscription is matched."""

    def __init__(self, publisher, hold: bool) -> None:
        self._publisher = publisher
        self._hold = hold
        self._held: deque = deque(maxlen=HOLD_LIMIT)

    @property
    def held(self) -> int:
        return len(self._held)

    def publish(self, msg) -> None:
        if self._hold and (self._held or self._publisher.get_subscription_count() == 0):
            self._held.append(msg)
            return
        self._publisher.publish(msg)

    def flush(self) -> None:
        """Send what was held, in order, once a subscription is matched."""
        if self._held and self._publisher.get_subscription_count() > 0:
            while self._held:
                self._publisher.publish(self._held.popleft())


class TileSensor(Node):
    """Ground truth and simulated sensing for one robot on the cyclic world."""

    node_name = "tile_sensor"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.node_name, **kwargs)
        declare_parameters(self, SENSOR_SPECS)
        values = parameter_values(self, SENSOR_SPECS)
        try:
            self._model = build_histogram_model(values)
            self._noise_std = float(np.sqrt(check_positive(
                "measurement_variance", values["measurement_variance"])))
            self._script_observations = [
                self._checked_class(name) for name in values["scripted_observations"] or []]
            self._script_measurements = [
                check_finite("scripted_measurements", z)
                for z in values["scripted_measurements"] or []]
        except ValueError as error:
            raise ConfigurationError(str(error)) from None
        self._scripted = bool(self._script_observations or self._script_measurements)
        seed = values["seed"]
        self._rng = np.random.default_rng(None if seed < 0 else seed)
        # Unwrapped: it keeps counting past the world size, as the measurements do.
        self._position = int(values["initial_cell"])
        self._step = 0

        qos = latched_qos(100)
        self._truth_pub = self.create_publisher(Int64, "true_position", qos)
        hold = bool(values["hold_until_matched"])
        self._tile_pub = HeldPublisher(
            self.create_publisher(String, "tile_observation", INPUT_QOS), hold)
        self._measurement_pub = HeldPublisher(
            self.create_publisher(Float64, "position_measurement", INPUT_QOS), hold)
        self.create_timer(FLUSH_PERIOD_S, self._flush_held)
        self.create_subscription(Int32, "motion_cmd", self._on_motion_cmd, INPUT_QOS)
        mode = "scripted" if self._scripted else f"random (seed {seed})"
        self.get_logger().info(f"ready: {self._model.size} cells, start cell "
                               f"{self._position % self._model.size}, {mode}")

    def _checked_class(self, name: str) -> str:
        self._model.sensor.index_of(name)
        return name

    def _on_motion_cmd(self, msg: Int32) -> None:
        step, self._step = self._step, self._step + 1
        if self._scripted:
            self._position += msg.data
            observation = self._scripted_item(self._script_observations, step)
            measurement = self._scripted_item(self._script_measurements, step)
        else:
            self._position += msg.data + histogram.sample_offset(self._model.kernel, self._rng)
            true_class = self._model.cell_class_index(self._position)
            observed = histogram.sample_observation(
                self._model.sensor.probabilities, true_class, self._rng)
            observation = self._model.sensor.classes[observed]
            measurement = self._position + self._noise_std * float(self._rng.standard_normal())
        self._truth_pub.publish(Int64(data=self._position))
        if observation is not None:
            self._tile_pub.publish(String(data=observation))
        if measurement is not None:
            self._measurement_pub.publish(Float64(data=measurement))

    def _flush_held(self) -> None:
        for publisher in (self._tile_pub, self._measurement_pub):
            publisher.flush()

    def _scripted_item(self, script: list, step: int) -> Any:
        """The script's entry for this step; None once the script (or an empty one) ends."""
        if step < len(script):
            return script[step]
        if script and step == len(script):
            self.get_logger().warning(f"script of {len(script)} entries ended; "
                                      "publishing no more of it")
        return None


main = main_for(TileSensor)

if __name__ == "__main__":
    main()
