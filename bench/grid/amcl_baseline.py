"""Nav2's AMCL as a benchmark's baseline: its particle filter from PyPI's ``amcl``.

``amcl`` (0.1.2, GPLv3: a benchmark-only extra, ``pip install .[bench]``, never a
dependency of the package) binds Nav2's AMCL C/C++ sources (pf, the differential motion
model, the laser models) for Python. What it binds, and so what these figures are of:

- the beam model (ray casting each beam in the map), the only laser model the bindings
  make; Nav2's default is the likelihood field, cheaper per beam;
- every call updates (motion, laser, resampling): there is no update_min_d gate, so the
  caller gives it only the scans our localizer took;
- the pose is the particle set's mean, not the mean of the heaviest cluster that Nav2
  publishes: while the particles are one cluster (tracking), the same.

The parameters are Nav2's defaults (nav2_params.yaml): 500 to 2000 particles, alpha1..4
0.2, z_hit 0.5, z_short 0.05, z_max 0.05, z_rand 0.5, sigma_hit 0.2, lambda_short 0.1,
60 beams, no recovery (alpha_slow = alpha_fast = 0).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

try:
    import amcl
except ImportError:     # the bench extra is not installed
    amcl = None

NAV2_DEFAULTS = {"min_particles": 500, "max_particles": 2000, "alpha": 0.2, "z_hit": 0.5,
                 "z_short": 0.05, "z_max": 0.05, "z_rand": 0.5, "sigma_hit": 0.2,
                 "lambda_short": 0.1, "chi_outlier": 0.05, "max_beams": 60}


def available() -> bool:
    return amcl is not None


class AmclBaseline:
    """AMCL on an occupancy map (core/grid/occupancy.OccupancyMap), started from a pose
    and its covariance."""

    def __init__(self, occupancy, prior: Sequence[float], covariance: np.ndarray,
                 particles: int | None = None) -> None:
        """``particles``: that many always (min_particles = max_particles), instead of
        Nav2's 500 to 2000."""
        if amcl is None:
            raise RuntimeError("AMCL baseline: pip install amcl==0.1.2 (.[bench])")
        d = NAV2_DEFAULTS
        fewest, most = (d["min_particles"], d["max_particles"]) if particles is None \
            else (particles, particles)
        motion = amcl.MotionParameters(d["alpha"], d["alpha"], d["alpha"], d["alpha"], 0.0)
        laser = amcl.LaserParameters(d["z_hit"], d["z_short"], d["z_max"], d["z_rand"],
                                     d["sigma_hit"], d["lambda_short"], d["chi_outlier"],
                                     d["max_beams"])
        self._filter = amcl.AMCL(fewest, most, 0.0, 0.0, motion, laser, "differential")
        # Row 0 at the origin, as nav_msgs/OccupancyGrid and the bindings both hold it.
        self._filter.set_map(amcl.create_occupancy_grid_from_list(
            occupancy.cells.astype(int).tolist(), occupancy.resolution, *occupancy.origin))
        self._filter.set_laser_pose(amcl.Vector3D(0.0, 0.0, 0.0))
        cov = amcl.Matrix3D()
        cov.from_list(np.asarray(covariance, dtype=float).tolist())
        self._filter.set_initial_pose(amcl.Vector3D(*map(float, prior)), cov)

    def update(self, ranges: np.ndarray, angles: np.ndarray, range_max: float,
               odometry: Sequence[float]) -> tuple[float, float, float]:
        """Motion to ``odometry`` (the raw odometry pose at the scan), the scan's every
        reading (the model takes its 60 beams), resampling; the pose after."""
        pairs = np.column_stack([ranges, angles]).tolist()
        self._filter.update(amcl.create_laser_scan_from_list(pairs, range_max),
                            amcl.Vector3D(*map(float, odometry)))
        pose = self._filter.get_pose_mean()
        return pose.x, pose.y, math.remainder(pose.theta, 2 * math.pi)
