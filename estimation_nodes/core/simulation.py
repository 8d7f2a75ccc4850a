"""Random draws of the simulated world: where a move lands, what a sensor reports.

The tile sensor node uses these with a seeded generator, so a seeded run is
repeatable; the filters never draw.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from estimation_nodes.core.models import MotionKernel


def sample_offset(kernel: MotionKernel, rng: np.random.Generator) -> int:
    """Draw where a real move lands relative to its target, as the kernel says."""
    return int(rng.choice(kernel.offsets, p=kernel.weights))


def sample_observation(
    probabilities: npt.NDArray[np.float64], true_class: int, rng: np.random.Generator
) -> int:
    """Draw an observed class index for a tile of class ``true_class``."""
    return int(rng.choice(probabilities.shape[1], p=probabilities[true_class]))
