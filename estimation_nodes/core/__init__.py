"""The filters as pure functions over validated models (numpy; numba for large worlds).

models: validated, immutable models (world, sensor model, motion kernel, linear
Gaussian system); histogram and kalman: the filter steps; compiled: numba
kernels for large worlds; simulation: the simulated world's random draws;
filter_state: running estimates advanced by the steps.

Never imports rclpy: nodes, replay and tests share it (a test checks).
"""

from estimation_nodes.core import histogram, kalman, simulation
from estimation_nodes.core.models import (
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
    "simulation",
]
