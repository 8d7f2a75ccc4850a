"""The landmark filter's settings (ekf_localizer, bench/ekf_real.py) from parameter values
(LANDMARK_MODEL_SPECS)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from estimation_nodes.core.kalman.landmarks import LandmarkModel
from estimation_nodes.core.kalman.range_bearing import SensorPose
from estimation_nodes.core.kalman.ukf import SigmaPoints
from estimation_nodes.core.kalman.unicycle import UnicycleNoise
from estimation_nodes.params.specs import LANDMARK_MODEL_SPECS, spec_defaults
from estimation_nodes.params.values import as_list, bounded

NOISE_NAMES = ("translation_per_m", "translation_per_rad", "translation_per_s",
               "rotation_per_m", "rotation_per_rad", "rotation_per_s")


def landmark_model(values: Mapping[str, Any],
                   landmarks: Mapping[int, tuple[float, float]]) -> LandmarkModel:
    """The filter's model; ValueError naming the first bad parameter."""
    kind = values["filter"]
    pose = [float(v) for v in as_list("sensor_pose", values["sensor_pose"])]
    if len(pose) != 3:
        raise ValueError(f"sensor_pose: expected [x, y, yaw], got {pose}")
    points = SigmaPoints(values["ukf.alpha"], values["ukf.beta"], values["ukf.kappa"]) \
        if kind == "ukf" else None
    noise = UnicycleNoise(**{name: bounded(f"noise.{name}", values[f"noise.{name}"])
                             for name in NOISE_NAMES})
    return LandmarkModel(kind, noise, bounded("range_std", values["range_std"]),
                         bounded("range_std_per_m", values["range_std_per_m"]),
                         bounded("bearing_std", values["bearing_std"]), SensorPose(*pose),
                         dict(landmarks), bounded("gate_probability",
                                                  values["gate_probability"]),
                         bounded("recovery_time", values["recovery_time"]),
                         _pair("recovery_std", values["recovery_std"]), points)


def _pair(name: str, value: Any) -> tuple[float, float]:
    numbers = [float(v) for v in as_list(name, value)]
    if len(numbers) != 2:
        raise ValueError(f"{name}: expected [position, heading], got {numbers}")
    return numbers[0], numbers[1]


def default_landmark_model(kind: str,
                           landmarks: Mapping[int, tuple[float, float]]) -> LandmarkModel:
    """The spec table's defaults, with filter ``kind``."""
    return landmark_model({**spec_defaults(LANDMARK_MODEL_SPECS), "filter": kind}, landmarks)
