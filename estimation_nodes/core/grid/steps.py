"""The grid filter's steps, each from its own module (moved there; importable here as before).

model.py: the state grid and likelihood field (``GridModel``) and the shared checks;
priors.py: the priors; motion.py: the odometry motion model (``predict``); laser.py: the
likelihood-field sensor model (``scan_log_likelihood``, ``correct_scan``); correction.py:
Bayes' rule (``correct``); belief.py: what the belief says.
"""

from estimation_nodes.core.grid.model import (  # noqa: F401
    TWO_PI as TWO_PI,
    COMPILED_MIN_STATES as COMPILED_MIN_STATES,
    MAX_MAP_EXTENT as MAX_MAP_EXTENT,
    Pose as Pose,
    GridModel as GridModel,
    MAX_MOUNTING_OFFSET as MAX_MOUNTING_OFFSET,
    mounting_pose as mounting_pose,
    _numbers as _numbers,
    _booleans as _booleans,
    check_pose as check_pose,
    _check_model as _check_model,
    check_belief as check_belief,
    _any_belief as _any_belief,
    _compiled_kernels as _compiled_kernels,
    compiled_kernels as compiled_kernels,
    _states as _states,
    _wrap as _wrap,
    _wrap_scalar as _wrap_scalar,
)
from estimation_nodes.core.grid.priors import (  # noqa: F401
    _covariance_3x3 as _covariance_3x3,
    uniform_over_free as uniform_over_free,
    gaussian_prior as gaussian_prior,
    _prior_exponent as _prior_exponent,
)
from estimation_nodes.core.grid.motion import (  # noqa: F401
    MAX_TAPS_HALF_WIDTH as MAX_TAPS_HALF_WIDTH,
    OdometryNoise as OdometryNoise,
    check_delta as check_delta,
    odometry_delta as odometry_delta,
    motion_noise as motion_noise,
    JITTER_M as JITTER_M,
    _motion_noise as _motion_noise,
    noise_rotations as noise_rotations,
    layer_shifts as layer_shifts,
    _layer_shifts as _layer_shifts,
    _bounded_shifts as _bounded_shifts,
    predict as predict,
    _predict as _predict,
    _spread as _spread,
    _spread_compiled as _spread_compiled,
    _normalized as _normalized,
    _shift_bilinear as _shift_bilinear,
    _add_shifted as _add_shifted,
    _shift_headings as _shift_headings,
    _half_width as _half_width,
    gaussian_taps as gaussian_taps,
    _gaussian_taps as _gaussian_taps,
    _identity as _identity,
    _reaching_taps as _reaching_taps,
    _heading_taps as _heading_taps,
    _blur as _blur,
    _blur_cyclic as _blur_cyclic,
)
from estimation_nodes.core.grid.laser import (  # noqa: F401
    LOG_SUM_LIMIT as LOG_SUM_LIMIT,
    check_scan as check_scan,
    beam_endpoints as beam_endpoints,
    _beam_endpoints as _beam_endpoints,
    scan_log_likelihood as scan_log_likelihood,
    _scan_log_likelihood as _scan_log_likelihood,
    _scan_log_likelihood_strided as _scan_log_likelihood_strided,
    _padded_field as _padded_field,
    correct_scan as correct_scan,
    scan_weight as scan_weight,
    _correct_scan as _correct_scan,
)
from estimation_nodes.core.grid.correction import (  # noqa: F401
    _correct_in as _correct_in,
    _weighted as _weighted,
    correct as correct,
)
from estimation_nodes.core.grid.belief import (  # noqa: F401
    most_likely_state as most_likely_state,
    _most_likely_state as _most_likely_state,
    pose_of as pose_of,
    _centres as _centres,
    _pose_of as _pose_of,
    refined_pose as refined_pose,
    _refined_pose as _refined_pose,
    covariance_around as covariance_around,
    _covariance_around as _covariance_around,
    mass_near as mass_near,
    _mass_near as _mass_near,
    belief_map as belief_map,
    _belief_map as _belief_map,
    entropy_bits as entropy_bits,
    _entropy_bits as _entropy_bits,
)
