"""The grid filter's public steps in one import; each is defined in the module of its part.

- model.py: the state grid and likelihood field of one map (``GridModel``), the checks
  the steps share (``check_pose``, ``check_belief``), the choice of compiled kernels;
- priors.py: ``uniform_over_free``, ``gaussian_prior``;
- motion.py: the odometry motion model (``OdometryNoise``, ``odometry_delta``,
  ``predict``);
- laser.py: the likelihood-field sensor model (``check_scan``, ``beam_endpoints``,
  ``scan_log_likelihood``, ``correct_scan``);
- correction.py: Bayes' rule (``correct``);
- belief.py: what the belief says (``most_likely_state``, ``refined_pose``,
  ``covariance_around``, ``mass_near``, ``belief_map``, ``entropy_bits``).

The unchecked twins (underscored) and the modules' constants are imported from their
modules, not from here: setting a constant here would change nothing there.
"""

from estimation_nodes.core.grid.belief import (
    belief_map,
    covariance_around,
    entropy_bits,
    mass_near,
    most_likely_state,
    pose_of,
    refined_pose,
)
from estimation_nodes.core.grid.correction import correct
from estimation_nodes.core.grid.laser import (
    beam_endpoints,
    check_scan,
    correct_scan,
    scan_log_likelihood,
    scan_weight,
)
from estimation_nodes.core.grid.model import (
    GridModel,
    check_belief,
    check_pose,
    compiled_kernels,
    mounting_pose,
)
from estimation_nodes.core.grid.motion import (
    OdometryNoise,
    check_delta,
    gaussian_taps,
    layer_shifts,
    motion_noise,
    noise_rotations,
    odometry_delta,
    predict,
)
from estimation_nodes.core.grid.priors import gaussian_prior, uniform_over_free

__all__ = [
    "GridModel", "mounting_pose", "check_pose", "check_belief", "compiled_kernels",
    "uniform_over_free", "gaussian_prior", "OdometryNoise", "check_delta", "odometry_delta",
    "motion_noise", "noise_rotations", "layer_shifts", "predict", "gaussian_taps", "check_scan",
    "beam_endpoints", "scan_log_likelihood", "correct_scan", "scan_weight", "correct",
    "most_likely_state", "pose_of", "refined_pose", "covariance_around", "mass_near", "belief_map",
    "entropy_bits",
]
