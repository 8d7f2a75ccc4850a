"""The belief a windowed localizer holds (core/grid/held.py): its windows, not the
building, and the same filter as the dense one."""

import numpy as np
import pytest

from estimation_nodes.core.errors import InvalidInputError
from estimation_nodes.core.grid.held import HeldBelief
from estimation_nodes.core.grid.localization import GridLocalization
from estimation_nodes.params.grid import default_odometry_noise
from tests.unit.test_grid_window import (
    SECOND,
    assert_the_same_figures,
    assert_the_same_filter,
    room,
    scan,
)


def localizer(model, floor):
    return GridLocalization(model, default_odometry_noise(), 0.0, 0.0, 10.0,
                            belief_floor=floor)


def dense_bytes(model):
    return 8 * int(np.prod(model.shape))


def test_the_start_s_uniform_belief_is_held_as_one_layer_and_reads_as_the_dense_one():
    """Before a prior, the windowed localizer's figures are the dense one's, from one
    heading layer per window in memory."""
    model = room(120, 130)
    dense, windowed = localizer(model, 0.0), localizer(model, 1e-9)
    assert_the_same_figures(windowed, dense)
    np.testing.assert_array_equal(windowed.belief, dense.belief)
    # (Which of the equal states are listed is the partition's choice.)
    assert [p for _, p in windowed.most_likely_states(5)] == \
        [p for _, p in dense.most_likely_states(5)]
    assert windowed.held_bytes <= dense_bytes(model) / model.heading_bins
    assert dense.held_bytes == dense_bytes(model)


def test_a_global_start_from_the_held_uniform_is_the_dense_filter():
    model = room(120, 130)
    dense, windowed = localizer(model, 0.0), localizer(model, 1e-30)
    for step in range(4):
        ranges, angles = scan(rng=np.random.default_rng(step))
        for loc in (dense, windowed):
            loc.on_odometry((0.1 * step, 0.0, 0.05 * step), (step + 1) * SECOND)
            loc.update(ranges, angles, (step + 1) * SECOND)
        assert_the_same_filter(windowed, dense)


def test_a_tracked_belief_holds_its_few_square_metres():
    model = room(120, 130)
    windowed = localizer(model, 1e-9)
    windowed.set_prior((4.0, 6.0, 0.3), np.diag([0.01, 0.01, 0.01]))
    for step in range(5):
        ranges, angles = scan(rng=np.random.default_rng(10 + step))
        windowed.on_odometry((0.05 * step, 0.0, 0.0), (step + 1) * SECOND)
        windowed.update(ranges, angles, (step + 1) * SECOND)
        assert windowed.held_bytes < 0.1 * dense_bytes(model)
        assert windowed.belief.sum() == pytest.approx(1.0, abs=1e-12)


def test_gather_and_regroup_keep_every_state_where_it_is():
    rng = np.random.default_rng(3)
    dense = np.zeros((4, 30, 40))
    dense[:, 2:9, 3:12] = rng.random((4, 7, 9))
    dense[:, 20:27, 25:38] = rng.random((4, 7, 13))
    held = HeldBelief.windowed(dense)
    assert len(held.boxes) == 2
    np.testing.assert_array_equal(held.dense(), dense)
    # A box cutting both windows: their states inside it.
    np.testing.assert_array_equal(held.gather((5, 25, 10, 30)), dense[:, 5:25, 10:30])
    # Regrouped into one box of both, with a single state outside the old windows.
    states = (np.array([2]), np.array([15]), np.array([15]), np.array([0.5]))
    regrouped = held.regrouped([(0, 30, 0, 40)], states)
    expected = dense.copy()
    expected[2, 15, 15] = 0.5
    np.testing.assert_array_equal(regrouped.dense(), expected)


def test_a_windowed_localizer_s_belief_is_the_caller_s_own_array():
    """With belief_floor, ``belief`` is a new array every time, even where one window
    covers the whole grid (a map free to its edges, a uniform start): writing it changes
    nothing in the filter."""
    import dataclasses

    base = room(30, 40)
    model = dataclasses.replace(base, free=np.ones_like(base.free))
    windowed = localizer(model, 1e-9)
    assert windowed._windows.boxes == [(0, 30, 0, 40)]
    entropy = windowed.entropy_bits()
    belief = windowed.belief
    belief[:] = 0.0
    belief[0, 0, 0] = 1.0
    assert windowed.entropy_bits() == entropy
    assert windowed.most_likely_states(0) == []
    with pytest.raises(InvalidInputError, match="count"):
        windowed.most_likely_states(-1)
