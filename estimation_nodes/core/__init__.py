"""The filters as pure functions over validated models (numpy, numba, scipy; never rclpy).

tiles/: the book's histogram filter on a cyclic world of tiles; kalman/: the linear
Kalman filter (scalar, fusion, matrix); grid/: grid localization on a map; sim/:
what the simulators draw; causal_order: events applied in the order they happened;
validation: the checks every model and step shares.

Never imports rclpy: nodes, replay and tests share it (a test checks).
"""

from estimation_nodes.core.kalman.models import (
    GaussianState,
    LinearGaussianModel,
    ScalarKalmanModel,
)
from estimation_nodes.core.tiles.models import HistogramModel, MotionKernel, SensorModel

__all__ = [
    "GaussianState",
    "HistogramModel",
    "LinearGaussianModel",
    "MotionKernel",
    "ScalarKalmanModel",
    "SensorModel",
]
