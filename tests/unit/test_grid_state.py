"""The grid localizer's update rule: when a scan updates, with which odometry."""

import math

import numpy as np
import pytest

from estimation_nodes.core.errors import InvalidInputError
from estimation_nodes.core.grid.localization import GridLocalization, OdometryStep
from estimation_nodes.params.grid import default_odometry_noise
from tests.unit.test_grid import small_model

SECOND = 10**9


def localization(**kwargs):
    model = small_model(rows=20, cols=20, obstacles=0.0)
    return GridLocalization(model, default_odometry_noise(), 0.25, 0.2, 1.0, **kwargs)


def test_the_first_scan_updates_once_odometry_is_there_then_only_after_motion():
    loc = localization()
    assert not loc.due()
    loc.on_odometry((0.0, 0.0, 0.0), 1 * SECOND)
    assert loc.due(1 * SECOND)
    loc.update(np.array([0.5]), np.array([0.0]), 1 * SECOND)
    loc.on_odometry((0.1, 0.0, 0.0), 2 * SECOND)
    assert not loc.due(2 * SECOND)
    loc.on_odometry((0.3, 0.0, 0.0), 3 * SECOND)
    assert loc.due(3 * SECOND) and not loc.due(2 * SECOND)
    loc.on_odometry((0.3, 0.0, 0.3), 4 * SECOND)
    assert loc.due(4 * SECOND)


def test_an_update_predicts_with_the_odometry_of_the_scan_time_not_a_later_one():
    """The same scan and odometry give the same belief whichever came first."""
    first, second = localization(), localization()
    for loc in (first, second):
        loc.on_odometry((0.0, 0.0, 0.0), 1 * SECOND)
        loc.update(np.array([0.5]), np.array([0.0]), 1 * SECOND)
        loc.on_odometry((0.4, 0.0, 0.0), 2 * SECOND)
    second.on_odometry((0.8, 0.1, 0.2), 3 * SECOND)       # already the next step's odometry
    for loc in (first, second):
        loc.update(np.array([0.7, 0.2]), np.array([0.0, math.pi / 2]), 2 * SECOND)
    np.testing.assert_array_equal(first.belief, second.belief)
    assert second.odometry_covers(3 * SECOND) and not first.odometry_covers(3 * SECOND)


def test_an_odometry_jump_is_not_motion():
    loc = localization()
    loc.on_odometry((0.0, 0.0, 0.0), 1 * SECOND)
    loc.update(np.array([0.5]), np.array([0.0]), 1 * SECOND)
    assert loc.on_odometry((5.0, 0.0, 0.0), 2 * SECOND) is OdometryStep.JUMP
    assert not loc.due(2 * SECOND)                          # followed from the new pose


def test_the_first_odometry_at_a_stamp_is_that_time_s_pose_whenever_the_scan_comes():
    """Real logs repeat odometry stamps with different poses. Live, a scan of that time is
    answered as soon as the first came; replayed, after all of them: the same belief."""
    live, replayed = localization(), localization()
    for loc in (live, replayed):
        loc.on_odometry((0.0, 0.0, 0.0), 1 * SECOND)
        loc.update(np.array([0.5]), np.array([0.0]), 1 * SECOND)
        assert loc.on_odometry((0.4, 0.0, 0.0), 2 * SECOND) is OdometryStep.TAKEN
    assert live.odometry_covers(2 * SECOND)
    live.update(np.array([0.7, 0.2]), np.array([0.0, math.pi / 2]), 2 * SECOND)
    assert replayed.on_odometry((0.6, 0.1, 0.3), 2 * SECOND) is OdometryStep.REPEATED_STAMP
    assert live.on_odometry((0.6, 0.1, 0.3), 2 * SECOND) is OdometryStep.REPEATED_STAMP
    replayed.update(np.array([0.7, 0.2]), np.array([0.0, math.pi / 2]), 2 * SECOND)
    np.testing.assert_array_equal(live.belief, replayed.belief)
    # The next step is measured from the first pose (turned 0.3 rad since), not the ignored.
    for loc in (live, replayed):
        loc.on_odometry((0.5, 0.0, 0.3), 3 * SECOND)
        assert loc.due(3 * SECOND)


def test_kidnap_probability_keeps_a_uniform_share():
    loc = localization(kidnap_probability=1e-3)
    loc.on_odometry((0.0, 0.0, 0.0), 1 * SECOND)
    loc.set_prior((0.5, 1.5, 0.0), np.diag([1e-4, 1e-4, 1e-4]))
    loc.update(np.array([0.3]), np.array([0.0]), 1 * SECOND)
    assert loc.belief.min() > 0
    assert loc.belief.sum() == pytest.approx(1.0)


def test_independent_beams_temper_the_scan_and_a_bad_count_is_refused():
    exact, tempered = localization(), localization(independent_beams=2)
    ranges, angles = np.full(6, 0.5), np.linspace(-math.pi, math.pi, 6, endpoint=False)
    for loc in (exact, tempered):
        loc.on_odometry((0.0, 0.0, 0.0), 1 * SECOND)
        loc.update(ranges, angles, 1 * SECOND)
    assert tempered.belief.max() < exact.belief.max()
    assert tempered.entropy_bits() > exact.entropy_bits()
    with pytest.raises(InvalidInputError, match="independent_beams"):
        localization(independent_beams=0)
