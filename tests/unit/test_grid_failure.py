"""Whether the most likely place holds the robot (core/grid/failure.py), and what the
localizer then publishes: a place found by one scan through the kidnap share, or a mode
the motion did not carry there, is doubted until later scans confirm it (issue 38)."""

import math

import numpy as np
import pytest

from estimation_nodes.core.geometry import compose
from estimation_nodes.core.grid import failure
from estimation_nodes.core.grid.laser import scan_log_likelihood
from estimation_nodes.core.grid.localization import GridLocalization
from estimation_nodes.core.grid.motion import odometry_delta
from estimation_nodes.core.validation import InvalidInputError
from estimation_nodes.core.sim import planar
from estimation_nodes.params.grid import build_grid_localizer_settings, default_odometry_noise
from estimation_nodes.params.map_files import read_map_file
from estimation_nodes.params.specs import GRID_LOCALIZER_SPECS, spec_defaults
from tests.conftest import REPO

CORRIDOR = REPO / "maps" / "corridor.yaml"
#: Squared Mahalanobis distance in (x, y, yaw) beyond which a covariance rules an error
#: out (chi-square, 3 degrees of freedom, 99.9 %).
CHI2_999 = 16.27


@pytest.mark.parametrize("doubt, kidnapped, jumped, expected", [
    (0.0, 1e-9, False, 1e-9),                       # tracking: the share's crumb only
    (0.0, 0.3, False, 0.3),                         # a third of the posterior came new
    (0.0, 1e-9, True, 1.0),                         # the mode jumped: all of it is new
    (1.0, 0.0, False, 1.0 - failure.RECOVERY),      # confirmed by a scan: it goes down
    (0.5, 0.2, False, 0.2 + 0.8 * 0.5 * (1.0 - failure.RECOVERY)),
])
def test_the_doubt_is_the_new_mode_s_probability_and_what_is_left_of_the_old(
        doubt, kidnapped, jumped, expected):
    assert failure.judged(doubt, kidnapped, jumped) == pytest.approx(expected, rel=1e-12)


def test_a_new_mode_is_trusted_after_several_scans_that_confirm_it():
    doubts = [1.0]
    for _ in range(4):
        doubts.append(failure.judged(doubts[-1], 0.0, False))
    np.testing.assert_allclose(doubts, [1.0, 0.5, 0.25, 0.125, 0.0625], rtol=1e-12)


def corridor_settings(**values):
    merged = spec_defaults(GRID_LOCALIZER_SPECS)
    merged.update(map_file=str(CORRIDOR), heading_bins=36, odometry_source="topic", **values)
    return build_grid_localizer_settings(merged)


@pytest.mark.parametrize("after, jumps", [
    ((2.3, 1.6, 0.0), False),         # 0.3 m on, as the odometry said
    ((2.45, 1.65, 0.05), False),      # within the motion's spread and two cells
    ((3.0, 1.6, 0.0), True),          # 0.7 m further than the odometry said
    ((2.3, 1.6, 0.6), True),          # turned 34 degrees the odometry did not
])
def test_a_mode_beyond_the_prediction_s_reach_jumped(after, jumps):
    model = corridor_settings().model
    delta = odometry_delta((0.0, 0.0, 0.0), (0.3, 0.0, 0.0))
    assert failure.jumped(model, default_odometry_noise(), (2.0, 1.6, 0.0), delta,
                          after) is jumps


def test_anywhere_is_the_free_cells_second_moment_about_the_pose():
    """Against an explicit sum over the free cells and the headings."""
    model = corridor_settings().model
    pose = (3.0, 1.0, 0.4)
    xs, ys = model.cell_centres()
    rows, cols = np.nonzero(model.free)
    dx, dy = xs[cols] - pose[0], ys[rows] - pose[1]
    turns = np.array([math.remainder(h - pose[2], 2 * math.pi) for h in model.headings()])
    expected = np.diag([np.mean(dx * dx), np.mean(dy * dy), np.mean(turns ** 2)])
    expected[0, 1] = expected[1, 0] = np.mean(dx * dy)
    np.testing.assert_allclose(failure.anywhere_around(failure.spread_of(model), pose),
                               expected, rtol=1e-9, atol=1e-12)


def test_the_dense_filter_s_kidnap_share_is_its_posterior_probability():
    """Against the sum written out: (kidnap / free states) x sum over the free states of
    the likelihood, over the evidence of the whole mixture."""
    settings = corridor_settings(belief_floor=0.0, kidnap_probability=1e-3)
    model = settings.model
    localization = settings.localization(model)
    localization.set_prior((4.0, 1.6, 0.0), np.diag([0.01, 0.01, 0.003]))
    ranges, angles = corridor_scan((6.0, 1.6, 0.0))          # taken 2 m from the prior
    prior = localization.belief.copy()
    localization.update(ranges, angles, odometry=(0.0, 0.0, 0.0))
    likelihood = np.exp(settings.independent_beams / ranges.size * scan_log_likelihood(
        model, ranges, angles)) if ranges.size > settings.independent_beams else \
        np.exp(scan_log_likelihood(model, ranges, angles))
    free_states = model.free.sum() * model.heading_bins
    share = 1e-3 / free_states * float(np.sum(likelihood * model.free))
    tracked = (1 - 1e-3) * float(np.sum(likelihood * prior))
    assert localization.doubt == pytest.approx(share / (share + tracked), rel=1e-6)
    assert localization.doubt > 1e-3     # the scan was taken where the prior is not


def corridor_scan(pose, rng=None):
    world = planar.planar_world(read_map_file(CORRIDOR))
    angles = -math.pi + 2 * math.pi * np.arange(180) / 180
    ranges = planar.ray_cast(world, pose, angles, 12.0)
    if rng is not None:
        ranges = planar.noisy_ranges(ranges, rng, 0.02, 0.0, 12.0)
    valid = np.flatnonzero(ranges < 12.0)
    valid = valid[np.linspace(0, valid.size - 1, 60).round().astype(int)]
    return ranges[valid], angles[valid]


def kidnapped_run(carried: float, steps: int = 20, at: int = 12, **values) -> list[dict]:
    """The robot drives along the corridor with grid_localizer's defaults, 0.3 m a scan
    (every scan an update), seeded noisy scans; at step ``at`` it is carried ``carried``
    m on, the odometry saying nothing. Each update's error, quality, doubt and squared
    Mahalanobis distance under the published covariance."""
    settings = corridor_settings(**values)
    localization: GridLocalization = settings.localization(settings.model)
    rng = np.random.default_rng(38)
    truth, odometry = (2.0, 1.6, 0.0), (0.0, 0.0, 0.0)
    localization.set_prior(truth, np.diag([0.01, 0.01, 0.003]))
    updates = []
    for step in range(steps):
        stamp = (step + 1) * 10**8
        truth = compose(truth, (0.3 + (carried if step == at else 0.0), 0.0, 0.0))
        odometry = compose(odometry, (0.3, 0.0, 0.0))
        localization.on_odometry(odometry, stamp)
        assert localization.due(stamp)
        localization.update(*corridor_scan(truth, rng), stamp)
        estimate = localization.estimate(settings.quality_radius, settings.quality_angle)
        error = np.array([estimate.pose[0] - truth[0], estimate.pose[1] - truth[1],
                          math.remainder(estimate.pose[2] - truth[2], 2 * math.pi)])
        updates.append({"step": step, "error": math.hypot(*error[:2]),
                        "pose": estimate.pose, "astray": localization.astray.mass,
                        "quality": estimate.quality, "doubt": localization.doubt,
                        "d2": float(error @ np.linalg.solve(estimate.covariance, error))})
    return updates


def test_a_place_found_again_after_a_kidnapping_is_doubted_then_confirmed():
    """Carried 4.4 m along the corridor: the belief stays behind for a scan (explained
    12 nats worse than usual, no match for the prior's odds against a kidnapping), then
    the kidnap share finds the robot. Found by one scan, the place is published as
    doubtful (the filter's own mass near it is 1) and trusted over the next scans."""
    updates = kidnapped_run(4.4)
    before, behind, found, after = updates[5:12], updates[12], updates[13], updates[14:]
    assert all(u["quality"] > 0.99 and u["error"] < 0.1 for u in before), before
    assert behind["error"] > 4.0       # the scan after the kidnapping is explained there
    # ... but a place around the predicted pose explains it better: the odometry may have
    # failed (4.4 m is a large odometry error for the model: some doubt, not most), and
    # the covariance reaches the robot.
    assert behind["quality"] < 0.9 and behind["d2"] < CHI2_999
    assert found["error"] < 0.1 and found["quality"] < 0.5 and found["doubt"] > 0.99
    np.testing.assert_allclose([u["doubt"] for u in after[:3]], [0.5, 0.25, 0.125],
                               rtol=1e-3)
    assert after[2]["quality"] > 0.8 and after[2]["error"] < 0.1
    # Where the place is doubted the covariance covers the robot anywhere in proportion.
    assert found["d2"] < CHI2_999


def test_the_odometry_failing_is_a_mixture_component_scored_on_the_lattice_around():
    """astray_in against the sums written out: the component's prior spread over the
    lattice states within ASTRAY_RADIUS_M of the predicted pose and of the last one, half
    around each (as distance to the -ASTRAY_FALL, most of it on the predicted heading),
    its posterior against the rest of the mixture's evidence, its states where the scan
    fits."""
    model = corridor_settings().model
    step = 2
    rows, cols = (step * index for index in np.nonzero(model.free[::step, ::step]))
    headings = model.headings()[::step]
    rng = np.random.default_rng(5)
    weights = rng.random((headings.size, rows.size))
    last, predicted, tracked = (1.0, 1.6, 0.4), (3.0, 1.6, 0.5), 0.7
    xs, ys = model.cell_centres()
    x, y = xs[cols], ys[rows]
    reach = failure.reach_of(x, y, failure.Increment(last, predicted, 0.3))
    # every state listed, the weights given at a scale: the component's mass is the same
    k, n = np.divmod(np.arange(weights.size), rows.size)
    found = failure.astray_in(headings, k, n, weights.reshape(-1) / 4.0, tracked, reach,
                              4.0)

    def places_around(centre):
        distance = np.hypot(x - centre[0], y - centre[1])
        density = np.where(distance <= failure.ASTRAY_RADIUS_M,
                           np.maximum(distance, failure.ASTRAY_NEAR_M) ** -failure.ASTRAY_FALL,
                           0)
        return density / density.sum()

    places = 0.5 * places_around(predicted) + 0.5 * places_around(last)
    same = np.array([abs(math.remainder(h - predicted[2], 2 * math.pi))
                     <= failure.ASTRAY_TURN_RAD for h in headings])
    bearings = np.where(same, failure.ASTRAY_SAME_HEADING / same.sum(),
                        (1 - failure.ASTRAY_SAME_HEADING) / (~same).sum())
    prior = bearings[:, None] * places[None]
    assert prior.sum() == pytest.approx(1.0)
    share = 0.3 * float((weights * prior).sum())
    expected = share / (share + 0.7 * tracked)
    assert found.mass == pytest.approx(expected, rel=1e-9)
    assert np.all((np.hypot(found.x - predicted[0], found.y - predicted[1])
                   <= failure.ASTRAY_RADIUS_M + 1e-9)
                  | (np.hypot(found.x - last[0], found.y - last[1])
                     <= failure.ASTRAY_RADIUS_M + 1e-9))
    # its states are the posterior's: their mean x as the discs' posterior mean x (but the
    # states below ASTRAY_KEPT of the largest, left out)
    posterior = weights * prior
    mean_x = float((posterior.sum(axis=0) * x).sum() / posterior.sum())
    assert float(found.p @ found.x) / found.mass == pytest.approx(mean_x, rel=1e-4)


def test_the_odometry_failure_fades_and_moves_with_the_robot():
    earlier = failure.Astray(np.array([1.0]), np.array([2.0]), np.array([math.pi / 2]),
                             np.array([0.4]))
    new = failure.Astray(np.array([5.0]), np.array([5.0]), np.array([0.0]), np.array([0.2]))
    after = earlier.faded(new, (0.0, 0.5, 0.0))      # 0.5 m ahead, facing +y
    assert after.mass == pytest.approx(0.2 + 0.8 * 0.4 * (1 - failure.RECOVERY))
    np.testing.assert_allclose([after.x[1], after.y[1]], [1.0, 2.5], atol=1e-12)
    # its probability near a pose, and its second moment about it
    assert after.near((1.0, 2.5, math.pi / 2), 0.1, 0.1) == pytest.approx(after.p[1])
    moment = after.about((5.0, 5.0, 0.0))
    assert moment[0, 0] == pytest.approx(after.p[1] * 16.0)
    assert moment[1, 1] == pytest.approx(after.p[1] * 2.5 ** 2)


def test_the_odometry_failure_is_scored_where_it_can_matter_and_its_mass_kept(monkeypatch):
    """The lattice states within the component's reach are scored to the end only while
    their bound could add ASTRAY_UNSCORED to its mass (failure.astray_bounds): the same
    run with every one of them scored gives the same poses, and the component's mass and
    the quality to within that, with states left unscored."""
    bounded = kidnapped_run(4.4)
    finite = []
    real_bounds = failure.astray_bounds

    def every_state_scored(reach, size, log_tracked):
        bounds = real_bounds(reach, size, log_tracked)
        finite.append(int(np.count_nonzero(np.isfinite(bounds))))
        return np.where(np.isfinite(bounds), -math.inf, bounds)

    monkeypatch.setattr(failure, "astray_bounds", every_state_scored)
    full = kidnapped_run(4.4)
    assert sum(finite) > 0                   # states of the reach had a bound to skip by
    assert max(u["astray"] for u in full) > 0.01     # and the component mattered
    for ours, exact in zip(bounded, full):
        # (the states left unscored count at their bounds in what the lattice leaves out,
        # as the kidnap share's do: the belief's renormalization moves in the last bits)
        np.testing.assert_allclose(ours["pose"], exact["pose"], rtol=0, atol=1e-9)
        assert ours["astray"] == pytest.approx(exact["astray"], abs=failure.ASTRAY_UNSCORED)
        assert ours["quality"] == pytest.approx(exact["quality"],
                                                abs=2 * failure.ASTRAY_UNSCORED)


def test_odometry_failure_probability_weighs_the_component_and_0_leaves_it_out():
    """The parameter is the component's prior: more of it, more of its posterior where a
    place around fits the scan; 0, none, and the poses are the tracked belief's all the
    same."""
    usual = kidnapped_run(4.4)
    more = kidnapped_run(4.4, odometry_failure_probability=0.5)
    without = kidnapped_run(4.4, odometry_failure_probability=0.0)
    assert all(u["astray"] == 0.0 for u in without)
    behind = 12          # the scan after the kidnapping: a place around fits it better
    assert 0.0 < usual[behind]["astray"] < more[behind]["astray"]
    for a, b in zip(usual, without):
        np.testing.assert_allclose(a["pose"], b["pose"], rtol=0, atol=1e-9)


@pytest.mark.parametrize("probability", [-0.1, 1.0, float("nan")])
def test_an_odometry_failure_probability_outside_0_to_1_is_refused(probability):
    settings = corridor_settings()
    with pytest.raises(InvalidInputError, match="odometry_failure_probability"):
        GridLocalization(settings.model, settings.noise, 0.25, 0.2, 1.0, 1e-6, None, 1e-9,
                         probability)


def test_the_states_left_unscored_can_add_at_most_astray_unscored_to_the_component():
    """At their bounds, every state within reach (each cell's headings sharing 1 of the
    prior) would add the bounds' allowance in all: ASTRAY_UNSCORED of the tracked
    evidence, so the mass is short by less than that; beyond the reach no bound
    (+inf: the component never needs those states)."""
    xs, ys = np.meshgrid(np.arange(0.0, 30.0, 0.2), np.arange(0.0, 6.0, 0.2))
    x, y = xs.ravel(), ys.ravel()
    reach = failure.reach_of(x, y, failure.Increment((9.0, 3.0, 0.0), (10.0, 3.0, 0.0), 0.3))
    log_tracked = -42.0
    bounds = failure.astray_bounds(reach, x.size, log_tracked)
    outside = np.setdiff1d(np.arange(x.size), reach.cells)
    assert outside.size > 0 and np.all(bounds[outside] == math.inf)
    added = 0.3 * float(np.sum(reach.prior[reach.cells] * np.exp(bounds[reach.cells])))
    assert added == pytest.approx(failure.ASTRAY_UNSCORED * 0.7 * math.exp(log_tracked),
                                  rel=1e-9, abs=0.0)
    # nothing known of the rest of the mixture: every state within reach is scored
    unknown = failure.astray_bounds(reach, x.size, -math.inf)
    assert np.all(unknown[reach.cells] == -math.inf)
