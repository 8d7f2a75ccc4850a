"""The filters as pure numpy functions over validated models; never imports rclpy."""

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
