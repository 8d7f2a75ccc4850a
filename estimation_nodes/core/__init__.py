"""The filters as pure functions over validated models (numpy; numba for large worlds).

Never imports rclpy: nodes, replay and tests share it.
"""

from estimation_nodes.core import histogram, kalman
from estimation_nodes.core.config import (
    GaussianState,
    HistogramModel,
    LinearGaussianModel,
    MotionKernel,
    ScalarKalmanModel,
    SensorModel,
)

__all__ = [
    "GaussianState",
    "HistogramModel",
    "LinearGaussianModel",
    "MotionKernel",
    "ScalarKalmanModel",
    "SensorModel",
    "histogram",
    "kalman",
]
