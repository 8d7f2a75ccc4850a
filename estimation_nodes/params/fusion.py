"""robot_localization's parameters for ``ekf_node`` / ``ukf_node``, read from a dict.

The names and meanings are the peer's, so a robot_localization YAML works unchanged;
``FusionConfig.unsupported`` lists each parameter given that this package does not act
on yet (the node says each in one warning line), never silently ignored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from estimation_nodes.core.fusion.control import CONTROL_NAMES, CONTROL_SIZE, ControlSettings
from estimation_nodes.core.fusion.filter import FusionSettings
from estimation_nodes.core.fusion.inputs import Mount
from estimation_nodes.core.fusion.sensors import SensorConfig, SensorInputs
from estimation_nodes.core.fusion.state import AX, GYRO_BIAS_SIZE, STATE_SIZE
from estimation_nodes.core.fusion.steps import UnscentedWeights

#: The control term's parameters (core/fusion/control.py).
CONTROL_PARAMETERS = ("use_control", "stamped_control", "control_timeout", "control_config",
                      "acceleration_limits", "acceleration_gains", "deceleration_limits",
                      "deceleration_gains")
#: Parameters read and acted on (beyond the per-sensor ones).
SUPPORTED = {
    "frequency", "sensor_timeout", "two_d_mode", "map_frame", "odom_frame",
    "base_link_frame", "world_frame", "publish_tf", "transform_time_offset",
    "transform_timeout", "process_noise_covariance", "initial_estimate_covariance",
    "initial_state", "predict_to_current_time", "dynamic_process_noise_covariance",
    "gravitational_acceleration", "alpha", "kappa", "beta", "filter_type",
    "print_diagnostics", "use_sim_time", "smooth_lagged_data", "history_length",
    *CONTROL_PARAMETERS,
}
#: Parameters that change nothing a run computes (logging, the peer's launch helpers).
#: And every rclpy node's own (rclpy declares it; the node reads it from the overrides).
HARMLESS = {"clear_params", "debug", "debug_out_file", "start_type_description_service"}
SENSOR_KINDS = ("odom", "pose", "twist", "imu")
#: This package's own per-IMU parameters (beyond the peer): estimate the gyro's bias as 3
#: state entries, with this initial variance ((rad/s)^2) and random walk ((rad/s)^2 / s).
GYRO_BIAS_SUFFIXES = ("_gyro_bias", "_gyro_bias_variance", "_gyro_bias_process_noise")
GYRO_BIAS_VARIANCE = 1e-3
GYRO_BIAS_PROCESS_NOISE = 1e-8
_TOPIC = {"", "_config", "_queue_size"}
#: Per-input suffixes read and acted on, by kind: the peer's names (a pose or twist
#: topic has one ``_rejection_threshold``, an odometry or IMU one per part).
SENSOR_SUFFIXES = {
    "odom": _TOPIC | {"_differential", "_relative", "_pose_rejection_threshold",
                      "_twist_rejection_threshold"},
    "pose": _TOPIC | {"_differential", "_relative", "_rejection_threshold"},
    "twist": _TOPIC | {"_rejection_threshold"},
    "imu": _TOPIC | {"_differential", "_relative", "_remove_gravitational_acceleration",
                     "_pose_rejection_threshold", "_twist_rejection_threshold",
                     "_linear_acceleration_rejection_threshold", *GYRO_BIAS_SUFFIXES},
}


class FusionConfigError(ValueError):
    """A parameter that cannot be used: the message names it and the expected form."""


@dataclass(frozen=True)
class FusionConfig:
    settings: FusionSettings
    sensors: dict[str, SensorConfig]
    frequency: float = 30.0
    world_frame: str = "odom"
    base_link_frame: str = "base_link"
    odom_frame: str = "odom"
    map_frame: str = "map"
    publish_tf: bool = True
    #: Added to the filter's time in the stamp of the transform it publishes (the peer's
    #: ``transform_time_offset``, s).
    transform_time_offset_ns: int = 0
    gravity: float = 9.80665
    two_d_mode: bool = False
    #: Publish /diagnostics (the peer's ``print_diagnostics``, off by default as there).
    print_diagnostics: bool = False
    #: The velocity command is geometry_msgs/TwistStamped (else Twist, taken at its
    #: arrival): the peer's ``stamped_control``.
    stamped_control: bool = False
    unsupported: tuple[str, ...] = field(default_factory=tuple)
    #: Lines to warn of: what the configuration asked that the filter changed (as the
    #: peer says them).
    notes: tuple[str, ...] = field(default_factory=tuple)

    def sensor_inputs(self, mounts: dict[str, Mount] | None = None) -> SensorInputs:
        """The inputs of this configuration, with the mounts known so far by frame."""
        return SensorInputs(dict(self.sensors), dict(mounts or {}), self.base_link_frame,
                            self.gravity, two_d=self.two_d_mode, world_frame=self.world_frame)


def _matrix(params: dict[str, Any], name: str, default: np.ndarray) -> np.ndarray:
    if name not in params:
        return default
    values = np.asarray(params[name], dtype=float)
    if values.size != STATE_SIZE * STATE_SIZE or not np.all(np.isfinite(values)):
        raise FusionConfigError(f"{name}: expected {STATE_SIZE * STATE_SIZE} finite numbers "
                                f"(a {STATE_SIZE}x{STATE_SIZE} matrix, row-major), "
                                f"got {values.size}")
    return values.reshape(STATE_SIZE, STATE_SIZE)


def _update_vector(params: dict[str, Any], name: str) -> tuple[bool, ...]:
    values = params.get(f"{name}_config", [False] * STATE_SIZE)
    if len(values) != STATE_SIZE:
        raise FusionConfigError(f"{name}_config: expected {STATE_SIZE} booleans "
                                f"(x y z roll pitch yaw vx vy vz vroll vpitch vyaw ax ay az), "
                                f"got {len(values)}")
    return tuple(bool(v) for v in values)


def _threshold(params: dict[str, Any], name: str) -> float:
    value = float(params.get(name, math.inf))
    if not value > 0:
        raise FusionConfigError(f"{name}: expected a positive number of standard deviations")
    return value


def _sensors(params: dict[str, Any]) -> dict[str, SensorConfig]:
    sensors: dict[str, SensorConfig] = {}
    next_bias = STATE_SIZE
    for kind in SENSOR_KINDS:
        index = 0
        while f"{kind}{index}" in params:
            name = f"{kind}{index}"
            update = _update_vector(params, name)
            if kind == "pose":
                # The peer takes only a pose topic's pose entries.
                update = tuple(flag and i < 6 for i, flag in enumerate(update))
            differential = bool(params.get(f"{name}_differential", False))
            sensors[name] = SensorConfig(
                name=name, kind=kind, topic=str(params[name]), update=update,
                pose_threshold=_threshold(params, f"{name}_rejection_threshold"
                                          if kind == "pose" else
                                          f"{name}_pose_rejection_threshold"),
                twist_threshold=_threshold(params, f"{name}_rejection_threshold"
                                           if kind == "twist" else
                                           f"{name}_twist_rejection_threshold"),
                acceleration_threshold=_threshold(
                    params, f"{name}_linear_acceleration_rejection_threshold"),
                remove_gravity=bool(params.get(f"{name}_remove_gravitational_acceleration",
                                               False)),
                # Both set: the peer says so in an error line and takes the differential.
                relative=bool(params.get(f"{name}_relative", False)) and not differential,
                differential=differential,
                queue_size=int(params.get(f"{name}_queue_size", 10)),
                gyro_bias=next_bias if kind == "imu" and _flag(params, f"{name}_gyro_bias")
                else None)
            if sensors[name].gyro_bias is not None:
                next_bias += GYRO_BIAS_SIZE
            index += 1
    return sensors


def _flag(params: dict[str, Any], name: str) -> bool:
    value = params.get(name, False)
    if not isinstance(value, (bool, np.bool_)):
        raise FusionConfigError(f"{name}: expected true or false, got {value!r}")
    return bool(value)


def _positive(params: dict[str, Any], name: str, default: float) -> float:
    try:
        value = float(params.get(name, default))
    except (TypeError, ValueError):
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise FusionConfigError(f"{name}: expected a positive number, got "
                                f"{params.get(name)!r}")
    return value


def _with_gyro_biases(settings: FusionSettings, params: dict[str, Any],
                      sensors: dict[str, SensorConfig]) -> FusionSettings:
    """The settings grown by 3 entries per IMU whose gyro bias is estimated: 0 at the
    start, with its ``_gyro_bias_variance``, and its ``_gyro_bias_process_noise`` as a
    random walk; nothing correlated with the 15 at the start."""
    variances, noises = [], []
    for sensor in sensors.values():
        if sensor.kind != "imu":
            continue
        # Checked whether or not the bias is estimated: a typo fails either way.
        variance = _positive(params, f"{sensor.name}_gyro_bias_variance", GYRO_BIAS_VARIANCE)
        noise = _positive(params, f"{sensor.name}_gyro_bias_process_noise",
                          GYRO_BIAS_PROCESS_NOISE)
        if sensor.gyro_bias is not None:
            variances += [variance] * GYRO_BIAS_SIZE
            noises += [noise] * GYRO_BIAS_SIZE
    if not variances:
        return settings

    def grown(matrix: np.ndarray, diagonal: list[float]) -> np.ndarray:
        size = STATE_SIZE + len(diagonal)
        out = np.zeros((size, size))
        out[:STATE_SIZE, :STATE_SIZE] = matrix
        out[STATE_SIZE:, STATE_SIZE:] = np.diag(diagonal)
        return out

    weights = settings.weights
    return replace(
        settings, process_noise=grown(settings.process_noise, noises),
        initial_covariance=grown(settings.initial_covariance, variances),
        initial_state=np.concatenate([settings.initial_state, np.zeros(len(variances))]),
        weights=UnscentedWeights(weights.alpha, weights.kappa, weights.beta,
                                 STATE_SIZE + len(variances)))


def _is_sensor_parameter(name: str, sensors: dict[str, SensorConfig]) -> bool:
    return any(name == sensor + suffix for sensor, config in sensors.items()
               for suffix in SENSOR_SUFFIXES[config.kind])


def fusion_config(params: dict[str, Any], kind: str | None = None) -> FusionConfig:
    """The configuration of a robot_localization parameter dict (``ros__parameters``)."""
    kind = kind or str(params.get("filter_type", "ekf"))
    frequency = float(params.get("frequency", 30.0))
    if not frequency > 0:
        raise FusionConfigError("frequency: expected a positive rate in Hz")
    timeout = float(params.get("sensor_timeout", 1.0 / frequency))
    sensors = _sensors(params)
    unsupported = sorted(name for name in params
                         if name not in SUPPORTED | HARMLESS
                         and not _is_sensor_parameter(name, sensors))
    initial_state = np.asarray(params.get("initial_state", [0.0] * STATE_SIZE), dtype=float)
    if initial_state.size != STATE_SIZE:
        raise FusionConfigError(f"initial_state: expected {STATE_SIZE} numbers")
    control, notes = _control(params, sensors, timeout)
    history_ns, history_notes = _history(params)
    settings = FusionSettings(
        kind=kind,
        control=control,
        history_ns=history_ns,
        process_noise=_matrix(params, "process_noise_covariance",
                              np.diag([0.05, 0.05, 0.06, 0.03, 0.03, 0.06, 0.025, 0.025,
                                       0.04, 0.01, 0.01, 0.02, 0.01, 0.01, 0.015])),
        initial_covariance=_matrix(params, "initial_estimate_covariance",
                                   np.eye(STATE_SIZE) * 1e-9),
        initial_state=initial_state,
        sensor_timeout_ns=round(timeout * 1e9),
        predict_to_current_time=bool(params.get("predict_to_current_time", False)),
        dynamic_process_noise=bool(params.get("dynamic_process_noise_covariance", False)),
        weights=UnscentedWeights(float(params.get("alpha", 0.001)),
                                 float(params.get("kappa", 0.0)),
                                 float(params.get("beta", 2.0))))
    settings = _with_gyro_biases(settings, params, sensors)
    return FusionConfig(
        settings=settings, sensors=sensors, frequency=frequency,
        world_frame=str(params.get("world_frame", params.get("odom_frame", "odom"))),
        base_link_frame=str(params.get("base_link_frame", "base_link")),
        odom_frame=str(params.get("odom_frame", "odom")),
        map_frame=str(params.get("map_frame", "map")),
        publish_tf=bool(params.get("publish_tf", True)),
        transform_time_offset_ns=_offset_ns(params),
        gravity=float(params.get("gravitational_acceleration", 9.80665)),
        two_d_mode=bool(params.get("two_d_mode", False)),
        print_diagnostics=bool(params.get("print_diagnostics", False)),
        stamped_control=bool(params.get("stamped_control", False)),
        unsupported=tuple(unsupported),
        notes=notes + history_notes + _unused_gyro_bias_notes(params, sensors))


def _unused_gyro_bias_notes(params: dict[str, Any], sensors: dict[str, SensorConfig]
                            ) -> tuple[str, ...]:
    """A line for each gyro bias figure given to an IMU whose bias is not estimated."""
    return tuple(f"{name}{suffix} is given but {name}_gyro_bias is not true: not used"
                 for name, sensor in sensors.items()
                 if sensor.kind == "imu" and sensor.gyro_bias is None
                 for suffix in GYRO_BIAS_SUFFIXES[1:] if f"{name}{suffix}" in params)


def _history(params: dict[str, Any]) -> tuple[int | None, tuple[str, ...]]:
    """How far back late measurements are put in their place (``smooth_lagged_data``,
    ``history_length`` in s; None: not smoothed), and the lines to warn of (the peer's)."""
    value = params.get("history_length", 0.0)
    try:
        length = math.nan if isinstance(value, bool) else float(value)
    except (TypeError, ValueError):
        length = math.nan
    if not math.isfinite(length):
        raise FusionConfigError(f"history_length: expected a finite time in s, got {value!r}")
    if not _flag(params, "smooth_lagged_data"):
        if length != 0.0:
            return None, (f"Filter history interval of {length} specified, but "
                          "smooth_lagged_data is set to false. Lagged data will not be "
                          "smoothed.",)
        return None, ()
    notes: tuple[str, ...] = ()
    if length < 0:
        notes = (f"Negative history interval of {length} specified. Absolute value will "
                 "be assumed.",)
    return round(abs(length) * 1e9), notes


def _per_velocity(params: dict[str, Any], name: str, default: tuple[float, ...]
                  ) -> tuple[float, ...]:
    if name not in params:
        return default
    values = np.asarray(params[name], dtype=float).ravel()
    if values.size != CONTROL_SIZE or not (np.all(np.isfinite(values)) and np.all(values >= 0)):
        raise FusionConfigError(f"{name}: expected {CONTROL_SIZE} non-negative numbers "
                                f"({' '.join(CONTROL_NAMES)}), got {list(values)}")
    return tuple(float(v) for v in values)


def _control(params: dict[str, Any], sensors: dict[str, SensorConfig], sensor_timeout: float
             ) -> tuple[ControlSettings | None, tuple[str, ...]]:
    """The control term's settings with ``use_control`` (None without), and the lines to
    warn of. Unlike the peer, a malformed entry is an error, not a term silently off."""
    if not bool(params.get("use_control", False)):
        return None, ()
    if "control_config" not in params:
        raise FusionConfigError("control_config: use_control is true, so expected "
                                f"{CONTROL_SIZE} booleans ({' '.join(CONTROL_NAMES)})")
    controlled = [bool(v) for v in params["control_config"]]
    if len(controlled) != CONTROL_SIZE:
        raise FusionConfigError(f"control_config: expected {CONTROL_SIZE} booleans "
                                f"({' '.join(CONTROL_NAMES)}), got {len(controlled)}")
    notes = []
    # An acceleration the IMU measures is not also commanded (the peer's rule and line).
    for axis in range(3):
        if controlled[axis] and any(config.kind == "imu" and config.update[AX + axis]
                                    for config in sensors.values()):
            controlled[axis] = False
            notes.append(f"{'XYZ'[axis]} acceleration is being measured from IMU; "
                         f"{'XYZ'[axis]} velocity control input is disabled")
    timeout = float(params.get("control_timeout", sensor_timeout))
    if not timeout > 0:
        raise FusionConfigError("control_timeout: expected a positive time in s")
    acceleration_limits = _per_velocity(params, "acceleration_limits", (1.0,) * CONTROL_SIZE)
    acceleration_gains = _per_velocity(params, "acceleration_gains", (1.0,) * CONTROL_SIZE)
    settings = ControlSettings(
        controlled=tuple(controlled), timeout_ns=round(timeout * 1e9),
        acceleration_limits=acceleration_limits, acceleration_gains=acceleration_gains,
        deceleration_limits=_per_velocity(params, "deceleration_limits", acceleration_limits),
        deceleration_gains=_per_velocity(params, "deceleration_gains", acceleration_gains))
    return settings, tuple(notes)


def _offset_ns(params: dict[str, Any]) -> int:
    offset = float(params.get("transform_time_offset", 0.0))
    if not (math.isfinite(offset) and offset >= 0):
        raise FusionConfigError("transform_time_offset: expected a non-negative time in s")
    return round(offset * 1e9)


def parameters_of_file(path: str, node_name: str | None = None) -> dict[str, Any]:
    """The ``ros__parameters`` of one node in a ROS parameter file (the first with a
    ``filter_type`` or ``frequency`` when no name is given)."""
    import yaml

    with open(path, encoding="utf-8") as stream:
        document = yaml.safe_load(stream) or {}
    for name, section in document.items():
        params = (section or {}).get("ros__parameters", {})
        if (node_name is None and ("frequency" in params or "filter_type" in params)) \
                or name.lstrip("/") == node_name:
            return dict(params)
    raise FusionConfigError(f"{path}: no node {node_name or 'with filter parameters'} "
                            f"under ros__parameters")
