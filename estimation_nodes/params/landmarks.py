"""The landmark filter's settings (ekf_localizer, bench/landmarks/ekf_real.py) from parameter
values (LANDMARK_MODEL_SPECS)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from estimation_nodes.core.kalman.landmarks import LandmarkModel
from estimation_nodes.core.kalman.range_bearing import Ranging, SensorPose
from estimation_nodes.core.kalman.ukf import SigmaPoints
from estimation_nodes.core.kalman.unicycle import UnicycleNoise
from estimation_nodes.core.sim.landmarks import Camera
from estimation_nodes.params.map_files import find_map_file
from estimation_nodes.params.specs import (
    EKF_LOCALIZER_SPECS,
    LANDMARK_MODEL_SPECS,
    LANDMARK_ROBOT_SPECS,
    spec_defaults,
)
from estimation_nodes.params.values import as_list, bounded

NOISE_NAMES = ("translation_per_m", "translation_per_rad", "translation_per_s",
               "rotation_per_m", "rotation_per_rad", "rotation_per_s")


def landmark_model(values: Mapping[str, Any],
                   landmarks: Mapping[int, tuple[float, float]]) -> LandmarkModel:
    """The filter's model; ValueError naming the first bad parameter."""
    kind = values["filter"]
    scale_std = bounded("range_scale_std", values["range_scale_std"])
    points = SigmaPoints(values["ukf.alpha"], values["ukf.beta"], values["ukf.kappa"],
                         n=4 if scale_std > 0 else 3) if kind == "ukf" else None
    noise = UnicycleNoise(**{name: bounded(f"noise.{name}", values[f"noise.{name}"])
                             for name in NOISE_NAMES})
    return LandmarkModel(kind, noise, bounded("range_std", values["range_std"]),
                         bounded("range_std_per_m", values["range_std_per_m"]),
                         bounded("bearing_std", values["bearing_std"]), _sensor_pose(values),
                         dict(landmarks), bounded("gate_probability",
                                                  values["gate_probability"]),
                         bounded("recovery_time", values["recovery_time"]),
                         _pair("recovery_std", values["recovery_std"]), points,
                         Ranging(values["range_model"],
                                 bounded("range_scale", values["range_scale"])),
                         int(bounded("ekf.iterations", values["ekf.iterations"])),
                         bounded("odometry_delay", values["odometry_delay"]),
                         _pair("odometry_scale", values["odometry_scale"],
                               "[forward, turn]"), scale_std,
                         _sensor_pose_std(values))


def _pair(name: str, value: Any, shape: str = "[position, heading]") -> tuple[float, float]:
    numbers = [float(v) for v in as_list(name, value)]
    if len(numbers) != 2:
        raise ValueError(f"{name}: expected {shape}, got {numbers}")
    return numbers[0], numbers[1]


def default_landmark_model(kind: str,
                           landmarks: Mapping[int, tuple[float, float]]) -> LandmarkModel:
    """The spec table's defaults, with filter ``kind``."""
    return landmark_model({**spec_defaults(LANDMARK_MODEL_SPECS), "filter": kind}, landmarks)


def read_landmarks_file(path_text: str) -> dict[int, tuple[float, float]]:
    """``landmarks: [{id: 6, x: 0.588, y: -4.282}, ...]``; ValueError naming what is wrong.
    A relative name not found from the working folder is looked up among the package's
    maps, as a map file is."""
    if not path_text:
        raise ValueError("landmarks_file: expected a YAML file of landmarks, got none")
    path = find_map_file(str(Path(path_text).expanduser()))
    try:
        document = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as error:
        raise ValueError(f"landmarks_file: cannot read {path}: {error.strerror}") from None
    except yaml.YAMLError as error:
        raise ValueError(f"landmarks_file: {path} is not valid YAML: {error}") from None
    entries = document.get("landmarks") if isinstance(document, dict) else None
    if not isinstance(entries, list) or not entries:
        raise ValueError(f"landmarks_file: {path}: expected 'landmarks:' with a list of "
                         f"{{id, x, y}}")
    landmarks: dict[int, tuple[float, float]] = {}
    for entry in entries:
        try:
            key, x, y = int(entry["id"]), float(entry["x"]), float(entry["y"])
        except (TypeError, KeyError, ValueError):
            raise ValueError(f"landmarks_file: {path}: expected {{id, x, y}}, got "
                             f"{entry!r}") from None
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f"landmarks_file: {path}: landmark {key} is not finite")
        if key in landmarks:
            raise ValueError(f"landmarks_file: {path}: landmark {key} is given twice")
        landmarks[key] = (x, y)
    return landmarks


@dataclass(frozen=True)
class EkfLocalizerSettings:
    """The landmark localizer's validated parameters (EKF_LOCALIZER_SPECS)."""

    model: LandmarkModel
    initial_pose: np.ndarray
    initial_covariance: np.ndarray
    frame_id: str
    reorder_horizon: float
    diagnostics_period: float


def build_ekf_localizer_settings(values: Mapping[str, Any],
                                 landmarks: Mapping[int, tuple[float, float]] | None = None
                                 ) -> EkfLocalizerSettings:
    """Validate the node's parameters; the landmarks are read from landmarks_file unless
    given (a runtime change does not read the file again)."""
    if landmarks is None:
        landmarks = read_landmarks_file(values["landmarks_file"])
    model = landmark_model(values, landmarks)
    pose = np.array([float(v) for v in as_list("initial_pose", values["initial_pose"])])
    if pose.size != 3 or not np.isfinite(pose).all():
        raise ValueError(f"initial_pose: expected [x, y, yaw], got {pose.tolist()}")
    given = np.array([float(v) for v in as_list("initial_covariance",
                                                values["initial_covariance"])])
    covariance = np.diag(given) if given.size == 3 else given.reshape(3, 3) \
        if given.size == 9 else None
    if covariance is None:
        raise ValueError(f"initial_covariance: expected 3 or 9 values, got {given.size}")
    from estimation_nodes.core.validation import check_covariance

    covariance = check_covariance("initial_covariance", covariance, 3)
    if not np.linalg.eigvalsh(covariance).min() > 0:
        raise ValueError("initial_covariance: expected a positive definite covariance")
    frame_id = values["frame_id"]
    if not isinstance(frame_id, str) or not frame_id.strip():
        raise ValueError(f"frame_id: expected a frame name, got {frame_id!r}")
    return EkfLocalizerSettings(model, pose, covariance, frame_id,
                                bounded("reorder_horizon", values["reorder_horizon"],
                                        EKF_LOCALIZER_SPECS),
                                bounded("diagnostics_period", values["diagnostics_period"],
                                        EKF_LOCALIZER_SPECS))


def _robot(name: str, value: Any) -> float:
    return bounded(name, value, LANDMARK_ROBOT_SPECS)


@dataclass(frozen=True)
class LandmarkRobotSettings:
    """The simulated robot's validated parameters (LANDMARK_ROBOT_SPECS)."""

    landmarks: dict[int, tuple[float, float]]
    noise: UnicycleNoise
    camera: Camera
    seed: int
    rate_hz: float
    camera_rate_hz: float
    speed: float
    turn_rate: float
    initial_pose: np.ndarray
    duration: float
    exit_when_done: bool
    hold_until_matched: bool
    hold_for_nodes: tuple[str, ...]


def build_landmark_robot_settings(values: Mapping[str, Any]) -> LandmarkRobotSettings:
    landmarks = read_landmarks_file(values["landmarks_file"])
    noise = UnicycleNoise(**{name: _robot(f"noise.{name}", values[f"noise.{name}"])
                             for name in NOISE_NAMES})
    camera = Camera(_sensor_pose(values), _robot("camera_max_range",
                                                  values["camera_max_range"]),
                    _robot("camera_field_of_view", values["camera_field_of_view"]),
                    _robot("range_std", values["range_std"]),
                    _robot("range_std_per_m", values["range_std_per_m"]),
                    _robot("bearing_std", values["bearing_std"]))
    pose = np.array([float(v) for v in as_list("initial_pose", values["initial_pose"])])
    if pose.size != 3 or not np.isfinite(pose).all():
        raise ValueError(f"initial_pose: expected [x, y, yaw], got {pose.tolist()}")
    return LandmarkRobotSettings(
        landmarks, noise, camera, int(values["seed"]), _robot("rate_hz", values["rate_hz"]),
        _robot("camera_rate_hz", values["camera_rate_hz"]), _robot("speed", values["speed"]),
        _robot("turn_rate", values["turn_rate"]), pose, _robot("duration", values["duration"]),
        bool(values["exit_when_done"]), bool(values["hold_until_matched"]),
        tuple(name for name in values["hold_for_nodes"] if name))


def _sensor_pose_std(values: Mapping[str, Any]) -> tuple[float, float, float]:
    std = [float(v) for v in as_list("sensor_pose_std", values["sensor_pose_std"])]
    if len(std) != 3:
        raise ValueError(f"sensor_pose_std: expected [x, y, yaw], got {std}")
    return std[0], std[1], std[2]


def _sensor_pose(values: Mapping[str, Any]) -> SensorPose:
    pose = [float(v) for v in as_list("sensor_pose", values["sensor_pose"])]
    if len(pose) != 3:
        raise ValueError(f"sensor_pose: expected [x, y, yaw], got {pose}")
    return SensorPose(*pose)
