"""The grid Markov localization core against brute force: explicit loops over states and beams."""

import math

import numpy as np
import pytest

from estimation_nodes.core import errors
from estimation_nodes.core.grid.belief import (
    belief_map,
    covariance_around,
    mass_near,
    most_likely_state,
    pose_of,
    refined_pose,
)
from estimation_nodes.core.grid.correction import correct
from estimation_nodes.core.grid.laser import correct_scan, scan_log_likelihood, scan_weight
from estimation_nodes.core.grid.model import COMPILED_MIN_STATES, GridModel, compiled_kernels
from estimation_nodes.core.grid.motion import (
    OdometryNoise,
    gaussian_taps,
    motion_noise,
    odometry_delta,
    predict,
)
from estimation_nodes.core.grid.priors import gaussian_prior, uniform_over_free

RNG = np.random.default_rng(4)


def small_model(rows=7, cols=9, bins=8, resolution=0.1, obstacles=0.2):
    rng = np.random.default_rng(rows * 100 + cols)
    free = rng.random((rows, cols)) > obstacles
    free[rows // 2, cols // 2] = True
    log_field = np.log(0.05 + rng.random((rows, cols)))
    return GridModel(free=free, log_field=log_field, log_outside=math.log(0.01),
                     resolution=resolution, origin=(-0.3, 1.2), heading_bins=bins)


def random_belief(model):
    belief = RNG.random(model.shape) * model.free[None]
    return belief / belief.sum()


def brute_force_scan(model, ranges, angles):
    """For every state, every beam: where its end point falls, and the field there."""
    xs, ys = model.cell_centres()
    rows, cols = model.free.shape
    out = np.zeros(model.shape)
    for k in range(model.heading_bins):
        heading = k * 2 * math.pi / model.heading_bins
        for i in range(rows):
            for j in range(cols):
                total = 0.0
                for r, phi in zip(ranges, angles):
                    x = xs[j] + r * math.cos(heading + phi)
                    y = ys[i] + r * math.sin(heading + phi)
                    col = math.floor((x - model.origin[0]) / model.resolution)
                    row = math.floor((y - model.origin[1]) / model.resolution)
                    inside = 0 <= row < rows and 0 <= col < cols
                    total += model.log_field[row, col] if inside else model.log_outside
                out[k, i, j] = total
    return out


def brute_force_predict(belief, model, delta, noise):
    """Every source state's mass sent to its target cells one by one: bilinear in x, y,
    linear in heading, then spread by the Gaussian taps, each cell visited in loops."""
    rot1, trans, rot2 = delta
    bins, rows, cols = model.shape
    moved = np.zeros(model.shape)
    turn = (rot1 + rot2) / model.bin_width
    for k in range(bins):
        angle = k * model.bin_width + rot1
        sc = trans * math.cos(angle) / model.resolution
        sr = trans * math.sin(angle) / model.resolution
        for i in range(rows):
            for j in range(cols):
                mass = belief[k, i, j]
                # Whole cells and the fraction of the shift itself: floor(j + sc) for a
                # shift of -3e-16 rounds j + sc up to j at j = 8 and sent the mass a cell on.
                for ti, wi in ((i + math.floor(sr), 1 - (sr - math.floor(sr))),
                               (i + math.floor(sr) + 1, sr - math.floor(sr))):
                    for tj, wj in ((j + math.floor(sc), 1 - (sc - math.floor(sc))),
                                   (j + math.floor(sc) + 1, sc - math.floor(sc))):
                        whole, part = math.floor(turn), turn - math.floor(turn)
                        for tk, wk in (((k + whole) % bins, 1 - part),
                                       ((k + whole + 1) % bins, part)):
                            if 0 <= ti < rows and 0 <= tj < cols:
                                moved[tk, ti, tj] += mass * wi * wj * wk
    # AMCL's noise: a rotation counts as its distance to 0 or pi (backwards is as certain
    # as forwards); a translation below 1 cm is jitter, the motion the turn alone.
    if trans < 0.01:
        turned = abs(math.remainder(rot1 + rot2, 2 * math.pi))
    else:
        turned = sum(min(abs(r), math.pi - abs(r)) for r in (rot1, rot2))
    sigma_m = noise.floor_m + noise.alpha3 * trans + noise.alpha4 * turned
    sigma_rad = noise.floor_rad + noise.alpha1 * turned + noise.alpha2 * trans
    taps_xy = gaussian_taps(sigma_m / model.resolution)
    taps_k = gaussian_taps(sigma_rad / model.bin_width)
    hxy, hk = taps_xy.size // 2, taps_k.size // 2
    spread = np.zeros(model.shape)
    for k in range(bins):
        for i in range(rows):
            for j in range(cols):
                mass = moved[k, i, j]
                if mass == 0:
                    continue
                for a, wa in enumerate(taps_k):
                    for b, wb in enumerate(taps_xy):
                        for c, wc in enumerate(taps_xy):
                            ti, tj = i + b - hxy, j + c - hxy
                            if 0 <= ti < rows and 0 <= tj < cols:
                                spread[(k + a - hk) % bins, ti, tj] += mass * wa * wb * wc
    spread *= model.free[None]
    return spread / spread.sum()


@pytest.mark.parametrize("beams", [1, 5, 12])
def test_scan_log_likelihood_equals_brute_force(beams):
    model = small_model()
    ranges = RNG.uniform(0.05, 1.2, beams)
    angles = RNG.uniform(-math.pi, math.pi, beams)
    np.testing.assert_allclose(scan_log_likelihood(model, ranges, angles),
                               brute_force_scan(model, ranges, angles), rtol=0, atol=1e-12)


@pytest.mark.parametrize("delta", [
    (0.0, 0.0, 0.0),                      # standing still: only the noise floor spreads
    (0.3, 0.17, -0.1),                    # a fraction of a cell, turning
    (-2.0, 0.55, 1.1),                    # several cells, a large turn
    (math.pi / 2, 0.45, 0.0),             # out of the small map for many states
    (3.0, 0.2, -3.1),                     # backwards
    (1.5, 0.004, -1.4),                   # turning on the spot, odometry's jitter aside
])
def test_prediction_equals_brute_force(delta):
    model = small_model()
    noise = OdometryNoise(alpha1=0.1, alpha2=0.3, alpha3=0.15, alpha4=0.05)
    belief = random_belief(model)
    np.testing.assert_allclose(predict(belief, model, delta, noise),
                               brute_force_predict(belief, model, delta, noise),
                               rtol=0, atol=1e-12)


def test_backwards_is_as_certain_as_forwards_and_jitter_is_no_turn():
    model = small_model()
    noise = OdometryNoise(alpha1=0.2, alpha2=0.2, alpha3=0.2, alpha4=0.2)
    forward = motion_noise((0.1, 0.3, -0.05), noise, model)
    backward = motion_noise((0.1 - math.pi, 0.3, math.pi - 0.05), noise, model)
    np.testing.assert_allclose(backward, forward, rtol=0, atol=1e-12)
    # 3 mm to the robot's back left while it turned 0.1 rad: rot1 2.4, rot2 -2.3.
    jitter = odometry_delta((1.0, 1.0, 0.0), (1.0 - 0.002, 1.0 + 0.002, 0.1))
    assert abs(jitter[0]) > 2.0
    on_the_spot = motion_noise((0.0, jitter[1], 0.1), noise, model)
    np.testing.assert_allclose(motion_noise(jitter, noise, model)[1], on_the_spot[1],
                               rtol=0, atol=1e-12)


def test_correction_is_bayes_rule_and_returns_the_log_evidence():
    model = small_model()
    belief = random_belief(model)
    log_likelihood = scan_log_likelihood(model, [0.4, 0.7], [0.1, -1.3])
    posterior, log_evidence = correct(belief, log_likelihood)
    joint = belief * np.exp(log_likelihood)
    np.testing.assert_allclose(posterior, joint / joint.sum(), rtol=1e-12, atol=1e-15)
    assert log_evidence == pytest.approx(math.log(joint.sum()), rel=1e-12)


def test_a_scan_nothing_explains_raises_and_changes_nothing():
    model = small_model()
    belief = np.zeros(model.shape)
    with pytest.raises(errors.ZeroEvidenceError):
        correct(belief, np.zeros(model.shape))


def test_uniform_prior_covers_free_cells_only():
    model = small_model()
    belief = uniform_over_free(model)
    assert belief.sum() == pytest.approx(1.0)
    assert np.all(belief[:, ~model.free] == 0)
    assert np.allclose(belief[:, model.free], 1.0 / (model.free.sum() * model.heading_bins))


def test_odometry_delta_of_the_book():
    rot1, trans, rot2 = odometry_delta((0.0, 0.0, 0.0), (1.0, 1.0, math.pi / 2))
    assert trans == pytest.approx(math.sqrt(2))
    assert rot1 == pytest.approx(math.pi / 4) and rot2 == pytest.approx(math.pi / 4)
    assert odometry_delta((0, 0, 0.5), (0, 0, -0.5)) == (0.0, 0.0, pytest.approx(-1.0))


def test_a_certain_belief_gives_its_pose_quality_one_and_a_small_covariance():
    model = small_model()
    belief = np.zeros(model.shape)
    belief[3, 3, 4] = 1.0
    state = most_likely_state(belief)
    pose = pose_of(model, state)
    assert state == (3, 3, 4)
    assert pose == pytest.approx((-0.3 + 0.45, 1.2 + 0.35, 3 * math.pi / 4 - 0.0), abs=1e-12)
    assert mass_near(belief, model, pose, 0.3, math.radians(10)) == pytest.approx(1.0)
    cov = covariance_around(belief, model, pose)
    np.testing.assert_allclose(np.diag(cov), [0.01 / 12, 0.01 / 12, (math.pi / 4) ** 2 / 12])


def test_the_refined_pose_is_the_mean_of_the_mode_and_its_neighbours():
    model = small_model(rows=20, cols=20, bins=8, obstacles=0.0)
    belief = np.zeros(model.shape)
    belief[3, 5, 6] = 1.0
    # One state: its centre.
    assert refined_pose(belief, model, (3, 5, 6)) == pytest.approx(
        pose_of(model, (3, 5, 6)), abs=1e-12)
    # A quarter of the mass one cell right and a heading bin up: a quarter of the way.
    belief[3, 5, 6], belief[4, 5, 7] = 0.75, 0.25
    x, y, yaw = pose_of(model, (3, 5, 6))
    assert refined_pose(belief, model, (3, 5, 6)) == pytest.approx(
        (x + 0.025, y, yaw + 0.25 * math.pi / 4), abs=1e-12)
    # Mass farther than one cell or bin from the mode is not counted.
    belief[3, 5, 9] = belief[6, 5, 6] = 0.1
    assert refined_pose(belief, model, (3, 5, 6)) == pytest.approx(
        (x + 0.025, y, yaw + 0.25 * math.pi / 4), abs=1e-12)


def test_the_refined_heading_crosses_the_first_bin_cyclically():
    model = small_model(rows=5, cols=5, bins=8, obstacles=0.0)
    belief = np.zeros(model.shape)
    belief[0, 2, 2], belief[7, 2, 2] = 0.5, 0.5
    # Halfway between bin 7 (-45 degrees) and bin 0: -22.5 degrees, not +157.5.
    assert refined_pose(belief, model, (0, 2, 2))[2] == pytest.approx(-math.pi / 8)


def test_the_refined_pose_of_a_mode_at_the_map_edge():
    model = small_model(rows=5, cols=5, bins=8, obstacles=0.0)
    belief = np.zeros(model.shape)
    belief[0, 0, 0], belief[0, 1, 0] = 0.5, 0.5
    x, y, _ = pose_of(model, (0, 0, 0))
    assert refined_pose(belief, model, (0, 0, 0))[:2] == pytest.approx((x, y + 0.05))
    with pytest.raises(errors.InvalidInputError, match="state"):
        refined_pose(belief, model, (0, 5, 0))


def test_two_far_modes_give_quality_one_half():
    model = small_model(rows=20, cols=20, obstacles=0.0)
    belief = np.zeros(model.shape)
    belief[0, 2, 2] = belief[0, 17, 17] = 0.5
    pose = pose_of(model, most_likely_state(belief))
    assert mass_near(belief, model, pose, 0.3, math.radians(10)) == pytest.approx(0.5)


def test_belief_map_scales_the_maximum_over_headings_to_100():
    model = small_model()
    belief = random_belief(model)
    picture = belief_map(belief)
    assert picture.dtype == np.int8 and picture.max() == 100 and picture.min() >= 0


def test_gaussian_prior_centres_on_the_given_pose():
    model = small_model(rows=20, cols=20, obstacles=0.0)
    xs, ys = model.cell_centres()
    prior = gaussian_prior(model, xs[5], ys[12], math.pi / 2, np.diag([0.01, 0.01, 0.05]))
    assert most_likely_state(prior) == (2, 12, 5)
    assert prior.sum() == pytest.approx(1.0)


def test_gaussian_prior_is_the_gaussian_over_the_free_states():
    model = small_model(rows=9, cols=11, bins=8, obstacles=0.3)
    covariance = np.array([[0.04, 0.01, 0.02], [0.01, 0.09, -0.03], [0.02, -0.03, 0.3]])
    pose = (0.1, 1.6, 3.0)
    prior = gaussian_prior(model, *pose, covariance)
    # Term by term, every state: the Gaussian with the grid's own spread added.
    floor = np.diag([(model.resolution / 2) ** 2] * 2 + [(model.bin_width / 2) ** 2])
    information = np.linalg.inv(covariance + floor)
    xs, ys = model.cell_centres()
    expected = np.zeros(model.shape)
    for k, heading in enumerate(model.headings()):
        for i, y in enumerate(ys):
            for j, x in enumerate(xs):
                d = np.array([x - pose[0], y - pose[1],
                              math.remainder(heading - pose[2], 2 * math.pi)])
                expected[k, i, j] = math.exp(-0.5 * d @ information @ d) * model.free[i, j]
    np.testing.assert_allclose(prior, expected / expected.sum(), rtol=1e-9, atol=1e-15)


def test_a_prior_written_over_a_belief_is_the_same_and_a_refused_one_writes_nothing():
    model = small_model(rows=9, cols=11, bins=8, obstacles=0.3)
    covariance = np.diag([0.04, 0.09, 0.3])
    held = random_belief(model)
    prior = gaussian_prior(model, 0.1, 1.6, 3.0, covariance, out=held)
    assert prior is held
    np.testing.assert_array_equal(prior, gaussian_prior(model, 0.1, 1.6, 3.0, covariance))
    before = held.copy()
    with pytest.raises(errors.NonFiniteResultError):
        gaussian_prior(model, 1e300, 1e300, 0.0, covariance, out=held)
    np.testing.assert_array_equal(held, before)
    np.testing.assert_array_equal(uniform_over_free(model, out=held), uniform_over_free(model))


def test_a_prior_that_covers_no_free_cell_goes_to_the_nearest_free_states():
    model = small_model(rows=9, cols=11, bins=8, obstacles=0.0)
    free = model.free.copy()
    free[:, :6] = False
    model = GridModel(free=free, log_field=model.log_field, log_outside=model.log_outside,
                      resolution=model.resolution, origin=model.origin, heading_bins=8)
    xs, ys = model.cell_centres()
    # Far left of the free cells and very sure: all the mass on the nearest free column.
    prior = gaussian_prior(model, xs[0], ys[4], 0.0, np.diag([1e-4, 1e-4, 1e-4]))
    assert prior.sum() == pytest.approx(1.0) and np.all(np.isfinite(prior))
    assert most_likely_state(prior) == (0, 4, 6)
    assert prior[:, :, :6].sum() == 0.0


def test_bad_models_are_refused_with_the_field_named():
    with pytest.raises(ValueError, match="resolution"):
        GridModel(np.ones((2, 2), bool), np.zeros((2, 2)), -1.0, 0.0, (0, 0), 4)
    with pytest.raises(ValueError, match="no free cell"):
        GridModel(np.zeros((2, 2), bool), np.zeros((2, 2)), -1.0, 0.1, (0, 0), 4)


def compiled_sized_model():
    """Just above COMPILED_MIN_STATES: the compiled kernels' path."""
    model = small_model(rows=60, cols=60, bins=36)
    assert np.prod(model.shape) >= COMPILED_MIN_STATES
    return model


def test_the_compiled_scan_equals_brute_force():
    pytest.importorskip("numba")
    model = compiled_sized_model()
    ranges = RNG.uniform(0.05, 2.0, 3)
    angles = RNG.uniform(-math.pi, math.pi, 3)
    compiled = scan_log_likelihood(model, ranges, angles)
    assert compiled_kernels(compiled.size) is not None
    np.testing.assert_allclose(compiled, brute_force_scan(model, ranges, angles),
                               rtol=0, atol=1e-12)


@pytest.mark.parametrize("delta", [(0.0, 0.0, 0.0), (0.3, 0.17, -0.1), (-2.0, 0.55, 1.1),
                                   (math.pi, 3.0, 0.0)])
def test_the_compiled_prediction_equals_numpys(delta):
    pytest.importorskip("numba")
    model = compiled_sized_model()
    noise = OdometryNoise(alpha1=0.1, alpha2=0.3, alpha3=0.15, alpha4=0.05)
    belief = random_belief(model)
    np.testing.assert_allclose(predict(belief, model, delta, noise),
                               predict(belief, model, delta, noise, compiled=False),
                               rtol=0, atol=1e-15)
    # And the whole correction, through both paths.
    ranges, angles = RNG.uniform(0.1, 2.0, 8), RNG.uniform(-math.pi, math.pi, 8)
    fast = correct_scan(belief, model, ranges, angles)
    slow = correct_scan(belief, model, ranges, angles, compiled=False)
    np.testing.assert_allclose(fast[0], slow[0], rtol=1e-12, atol=1e-300)
    assert fast[1] == pytest.approx(slow[1], rel=1e-12)


@pytest.mark.parametrize("delta", [(0.3, 0.17, -0.1), (0.0, 0.0, 0.0)])
def test_the_compiled_prediction_of_a_few_heading_layers_equals_numpys(delta):
    """The compiled passes skip the layers without probability: the same prediction."""
    pytest.importorskip("numba")
    model = compiled_sized_model()
    noise = OdometryNoise(alpha1=0.1, alpha2=0.3, alpha3=0.15, alpha4=0.05)
    belief = random_belief(model)
    belief[[k for k in range(model.heading_bins) if k not in (0, 3, 4)]] = 0.0
    belief /= belief.sum()
    np.testing.assert_allclose(predict(belief, model, delta, noise),
                               predict(belief, model, delta, noise, compiled=False),
                               rtol=0, atol=1e-15)


def test_a_scan_of_more_beams_than_independent_ones_is_a_tempered_likelihood():
    model = small_model()
    belief = random_belief(model)
    ranges, angles = RNG.uniform(0.1, 0.6, 12), RNG.uniform(-math.pi, math.pi, 12)
    log_likelihood = scan_log_likelihood(model, ranges, angles)
    tempered = correct_scan(belief, model, ranges, angles, independent_beams=4)
    expected = correct(belief, log_likelihood * 4 / 12)
    np.testing.assert_allclose(tempered[0], expected[0], rtol=1e-12, atol=1e-300)
    assert tempered[1] == pytest.approx(expected[1], rel=1e-12)
    # As many independent beams as beams, or more: the scan's own likelihood.
    exact = correct(belief, log_likelihood)
    for independent in (12, 100):
        np.testing.assert_allclose(
            correct_scan(belief, model, ranges, angles, independent_beams=independent)[0],
            exact[0], rtol=1e-12, atol=1e-300)
    assert scan_weight(20, 60) == pytest.approx(1 / 3)


@pytest.mark.parametrize("bad", [0, -3, 2.5, "4", None])
def test_independent_beams_below_one_or_not_a_count_are_refused(bad):
    with pytest.raises(errors.InvalidInputError, match="independent_beams"):
        scan_weight(bad, 10)
