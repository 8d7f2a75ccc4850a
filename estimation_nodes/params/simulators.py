"""The simulators' settings: the tile sensor, the motion commander and the linear system."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from estimation_nodes.core.kalman.models import LinearGaussianModel
from estimation_nodes.core.tiles.models import HistogramModel
from estimation_nodes.core.validation import FloatArray, check_finite
from estimation_nodes.params.models import build_histogram_model, build_matrix_model
from estimation_nodes.params.specs import UNSET
from estimation_nodes.params.values import bounded, entries, with_columns


@dataclass(frozen=True)
class SensorSettings:
    """The simulated sensor's world and noise, and its script when it replays one."""

    model: HistogramModel
    noise_std: float
    scripted_observations: tuple[str, ...]
    scripted_measurements: tuple[float, ...]

    @property
    def scripted(self) -> bool:
        """Whether the sensor replays a script instead of sampling."""
        return bool(self.scripted_observations or self.scripted_measurements)

def build_sensor_settings(values: Mapping[str, Any]) -> SensorSettings:
    """The tile sensor's settings; scripted classes must be classes of the model."""
    model = build_histogram_model(values)
    noise_std = float(np.sqrt(bounded("measurement_variance",
                                      values["measurement_variance"])))
    observations = tuple(values["scripted_observations"] or ())
    for name in observations:
        try:
            model.sensor.index_of(name)
        except ValueError as error:
            raise ValueError(f"scripted_observations: {error}") from None
    measurements = tuple(check_finite("scripted_measurements", z)
                         for z in values["scripted_measurements"] or ())
    return SensorSettings(model, noise_std, observations, measurements)

@dataclass(frozen=True)
class CommanderSettings:
    """The motion commander's sequence and how many commands a run sends."""

    commands: tuple[int, ...]
    #: Commands to send in all; None repeats without end.
    limit: int | None
    #: When given, the sequence is these input vectors (kalman_input) instead of commands.
    vectors: tuple[tuple[float, ...], ...] = ()
    #: Nodes that must be matched subscribers before a command goes out.
    required_nodes: tuple[str, ...] = ()

    @property
    def length(self) -> int:
        return len(self.vectors or self.commands)

#: motion_cmd is std_msgs/Int32.
INT32_RANGE = (-(2**31), 2**31 - 1)

def build_commander_settings(values: Mapping[str, Any]) -> CommanderSettings:
    vectors = _input_vectors(values)
    given = values["commands"]
    if not vectors and (given is UNSET or not hasattr(given, "__len__")
                        or isinstance(given, (str, bytes)) or len(given) == 0):
        raise ValueError("commands: expected a list of at least one integer, got none")
    commands = tuple(int(c) for c in given or ())
    low, high = INT32_RANGE
    outside = [c for c in commands if not low <= c <= high]
    if outside:
        raise ValueError(f"commands: {outside[0]} does not fit motion_cmd (std_msgs/Int32: "
                         f"{low}..{high})")
    length = len(vectors or commands)
    limit = values["max_commands"] or None
    if not values["repeat"]:
        limit = min(limit or length, length)
    return CommanderSettings(commands, limit, vectors, _required_nodes(values, bool(vectors)))

#: Who must hear the commander, unless told: the estimator and the simulator it drives.
DEFAULT_REQUIRED_NODES = {False: ("estimator", "tile_sensor"),
                          True: ("estimator", "linear_system")}

def _required_nodes(values: Mapping[str, Any], vectors: bool) -> tuple[str, ...]:
    if not values["required_subscribers"]:
        return ()
    given = values.get("required_nodes", UNSET)
    if given is UNSET:
        return DEFAULT_REQUIRED_NODES[vectors]
    names = tuple(str(name).strip() for name in given)
    return tuple(name for name in names if name)

def _input_vectors(values: Mapping[str, Any]) -> tuple[tuple[float, ...], ...]:
    given = values.get("input_vectors")
    if given is UNSET or len(given) == 0:
        return ()
    flat = entries("input_vectors", given)
    size = int(values["input_size"])
    rows = with_columns("input_vectors", flat, size, f"input_size = {size} values a command")
    return tuple(tuple(float(v) for v in row) for row in rows)

@dataclass(frozen=True)
class LinearSystemSettings:
    """The simulated system of Eq. 6.34 and its true initial state."""

    model: LinearGaussianModel
    initial_state: FloatArray

def build_linear_system_settings(values: Mapping[str, Any]) -> LinearSystemSettings:
    initial, model = build_matrix_model(values, "kalman.matrix.")
    given = values.get("true_initial_state")
    if given is UNSET or len(given) == 0:
        return LinearSystemSettings(model, initial.x)
    state = entries("true_initial_state", given)
    if state.size != model.state_size:
        raise ValueError(f"true_initial_state: expected {model.state_size} values (n), "
                         f"got {state.size}")
    return LinearSystemSettings(model, state)
