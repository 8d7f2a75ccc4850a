"""The simulated robot: it moves on each command and reports the tile it sees.

On every ``motion_cmd`` it moves by the command plus an offset drawn from the
motion kernel, then publishes ``true_position``, one ``tile_observation``
drawn from the sensor model and one ``position_measurement`` with Gaussian
noise. In scripted mode (either script parameter set) it moves by exactly the
command and publishes the next scripted observation and measurement instead,
which is how the textbook's examples are replayed.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from rclpy.node import Node
from std_msgs.msg import Float64, Int32, Int64, String

from estimation_nodes.core.sim import draws as simulation
from estimation_nodes.nodes.held_publisher import HeldPublisher, subscribe_when_ready
from estimation_nodes.nodes.parameters import (
    declare_and_build,
)
from estimation_nodes.nodes.process import main_for
from estimation_nodes.nodes.qos import INPUT_QOS, latched_qos
from estimation_nodes.params import topics
from estimation_nodes.params.simulators import build_sensor_settings
from estimation_nodes.params.specs import SENSOR_SPECS


class TileSensor(Node):
    """Ground truth and simulated sensing for one robot on the cyclic world."""

    node_name = "tile_sensor"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.node_name, **kwargs)
        values, settings = declare_and_build(self, SENSOR_SPECS, build_sensor_settings)
        self._model = settings.model
        self._noise_std = settings.noise_std
        self._script_observations = settings.scripted_observations
        self._script_measurements = settings.scripted_measurements
        self._scripted = settings.scripted
        seed = values["seed"]
        self._rng = np.random.default_rng(None if seed < 0 else seed)
        # Unwrapped: it keeps counting past the world size, as the measurements do.
        self._position = int(values["initial_cell"])
        self._step = 0

        qos = latched_qos(100)
        self._truth_pub = self.create_publisher(Int64, topics.TRUE_POSITION, qos)
        hold = bool(values["hold_until_matched"])
        hold_for = values["hold_for_nodes"]
        self._tile_pub = HeldPublisher(self, String, topics.TILE_OBSERVATION, hold, hold_for)
        self._measurement_pub = HeldPublisher(self, Float64, topics.POSITION_MEASUREMENT, hold,
                                              hold_for)
        subscribe_when_ready(self, [self._tile_pub, self._measurement_pub], hold,
                             lambda: self.create_subscription(
                                 Int32, topics.MOTION_CMD, self._on_motion_cmd, INPUT_QOS))
        mode = "scripted" if self._scripted else f"random (seed {seed})"
        self.get_logger().info(f"ready: {self._model.size} cells, start cell "
                               f"{self._position % self._model.size}, {mode}")

    def _on_motion_cmd(self, msg: Int32) -> None:
        step, self._step = self._step, self._step + 1
        if self._scripted:
            self._position += msg.data
            observation = self._scripted_item(self._script_observations, step)
            measurement = self._scripted_item(self._script_measurements, step)
        else:
            self._position += msg.data + simulation.sample_offset(self._model.kernel, self._rng)
            true_class = self._model.cell_class_index(self._position)
            observed = simulation.sample_observation(
                self._model.sensor.probabilities, true_class, self._rng)
            observation = self._model.sensor.classes[observed]
            measurement = self._position + self._noise_std * float(self._rng.standard_normal())
        self._truth_pub.publish(Int64(data=self._position))
        if observation is not None:
            self._tile_pub.publish(String(data=observation))
        if measurement is not None:
            self._measurement_pub.publish(Float64(data=measurement))


    def _scripted_item(self, script: tuple, step: int) -> Any:
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
