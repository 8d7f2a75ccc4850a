"""The grid filter over its belief's support (core/grid/window.py) equals the dense filter."""

import math

import numpy as np
import pytest

from estimation_nodes.core.errors import ZeroEvidenceError
from estimation_nodes.core.grid import window
from estimation_nodes.core.grid.correction import correct
from estimation_nodes.core.grid.laser import (
    _scan_log_likelihood,
    _scan_log_likelihood_cells,
    _scan_reads,
    scan_log_likelihood,
)
from estimation_nodes.core.grid.localization import GridLocalization
from estimation_nodes.core.grid.model import COMPILED_MIN_STATES, GridModel, compiled_kernels
from estimation_nodes.core.grid.motion import _predict
from estimation_nodes.core.grid.priors import gaussian_prior
from estimation_nodes.params.grid import default_odometry_noise

SECOND = 10**9
RNG = np.random.default_rng(7)


def room(rows, cols, bins=16, resolution=0.1):
    """A room with walls and a few pillars, its field high near them."""
    rng = np.random.default_rng(rows * 1000 + cols)
    free = np.ones((rows, cols), dtype=bool)
    free[[0, -1], :] = free[:, [0, -1]] = False
    free[rng.integers(1, rows - 1, 12), rng.integers(1, cols - 1, 12)] = False
    log_field = np.where(free, math.log(0.05), math.log(2.0)) + 0.1 * rng.random((rows, cols))
    return GridModel(free=free, log_field=log_field, log_outside=math.log(0.01),
                     resolution=resolution, origin=(-1.0, 2.0), heading_bins=bins)


def scan(count=12, rng=RNG):
    angles = np.linspace(-math.pi, math.pi, count, endpoint=False)
    return 0.2 + rng.random(count), angles


def tracked_pair(model, floor, kidnap=0.0, compiled=True):
    """A dense localizer and a windowed one (``floor``), the same tight prior."""
    make = lambda f: GridLocalization(model, default_odometry_noise(), 0.0, 0.0, 10.0,  # noqa: E731
                                      kidnap_probability=kidnap, belief_floor=f)
    dense, windowed = make(0.0), make(floor)
    for loc in (dense, windowed):
        loc.set_prior((1.5, 4.0, 0.3), np.diag([0.01, 0.01, 0.01]))
    return dense, windowed


def assert_the_same_filter(windowed, dense):
    """Belief and evidence equal to rounding, and what is said of them."""
    np.testing.assert_allclose(windowed.belief, dense.belief, rtol=0, atol=1e-12)
    assert windowed.log_evidence == pytest.approx(dense.log_evidence, abs=1e-9)
    assert_the_same_figures(windowed, dense)


def assert_the_same_figures(windowed, dense):
    """Estimate, entropy and belief map equal to rounding."""
    a, b = dense.estimate(0.3, 0.2), windowed.estimate(0.3, 0.2)
    np.testing.assert_allclose(b.pose, a.pose, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.covariance, a.covariance, rtol=1e-9, atol=1e-12)
    assert b.quality == pytest.approx(a.quality, abs=1e-12)
    assert windowed.entropy_bits() == pytest.approx(dense.entropy_bits(), abs=1e-9)
    np.testing.assert_array_equal(windowed.belief_map(), dense.belief_map())


@pytest.mark.parametrize("rows, cols, small", [(40, 50, False), (120, 130, True)])
def test_the_window_follows_the_dense_filter_to_rounding(rows, cols, small):
    """A floor of 1e-30 drops only what is already ~0: every update equals the dense
    one's."""
    model = room(rows, cols)
    dense, windowed = tracked_pair(model, floor=1e-30)
    odometry = (0.0, 0.0, 0.0)
    for step in range(8):
        odometry = (odometry[0] + 0.12, odometry[1] + 0.03 * (step % 3), odometry[2] + 0.1)
        ranges, angles = scan()
        for loc in (dense, windowed):
            loc.on_odometry(odometry, (step + 1) * SECOND)
            loc.update(ranges, angles, (step + 1) * SECOND)
        assert_the_same_filter(windowed, dense)
    # In the small room (numpy's path) the tails above 1e-30 reach every wall; in the
    # large one (compiled) the windows stay small.
    assert not small or windowed.window_states < 0.5 * rows * cols * 16


def test_a_floor_drops_at_most_floor_per_state_and_never_the_largest():
    belief = RNG.random((4, 10, 10)) ** 8
    belief /= belief.sum()
    floor = 1e-4
    kept, dropped = window.drop_below(belief.copy(), floor)
    assert dropped <= floor * belief.size
    assert dropped == pytest.approx(belief[belief < floor].sum())
    assert kept.sum() == pytest.approx(1.0)
    assert (kept[belief < floor] == 0).all() and (kept[belief >= floor] > 0).all()
    certain = np.full((2, 3, 3), 1.0 / 18)
    kept, dropped = window.drop_below(certain.copy(), 0.5)     # every state below it
    np.testing.assert_array_equal(kept, certain)
    assert dropped == 0.0


def area(box):
    r0, r1, c0, c1 = box
    return (r1 - r0) * (c1 - c0)


def test_the_grown_box_holds_everything_the_prediction_reaches():
    model = room(60, 70)
    noise = default_odometry_noise()
    for _ in range(20):
        belief = np.zeros(model.shape)
        r, c = RNG.integers(5, 50), RNG.integers(5, 60)
        belief[RNG.integers(0, 16), r:r + 3, c:c + 4] = model.free[r:r + 3, c:c + 4]
        if not belief.any():
            continue
        belief /= belief.sum()
        delta = (RNG.uniform(-3, 3), RNG.uniform(0, 0.6), RNG.uniform(-3, 3))
        try:
            predicted = _predict(belief, model, delta, noise)
        except ZeroEvidenceError:
            continue
        box = window.support_box(belief)
        held = np.flatnonzero(belief.any(axis=(1, 2)))
        for headings in (None, held):
            r0, r1, c0, c1 = grown = window.grown_box(box, model, delta, noise, headings)
            outside = predicted.copy()
            outside[:, r0:r1, c0:c1] = 0.0
            assert not outside.any()
            assert window.disjoint([grown, box]) == [grown]     # it holds the source too
        # The layer's own direction: a box of a few cells, not the motion's length each way.
        assert (r1 - r0) * (c1 - c0) <= area(window.grown_box(box, model, delta, noise))


@pytest.mark.parametrize("phase", [0, 1])
def test_the_kidnap_lattice_correction_is_bayes_rule_over_the_mixed_prior(phase):
    """Floor 0 keeps every lattice state: the posterior equals the dense correction of
    (1 - share) belief + share spread over the free states of the lattice's part."""
    model = room(30, 34)
    belief = np.zeros(model.shape)
    belief[:, 10:14, 12:15] = RNG.random((16, 4, 3)) * model.free[10:14, 12:15]
    belief /= belief.sum()
    box = (8, 16, 10, 18)
    ranges, angles = scan()
    share, weight = 0.01, 0.7
    correction = window.correct_boxes([window.window_of(belief, box)], [box], model, ranges,
                                      angles, weight, share, floor=0.0, phase=phase)
    lattice = np.zeros(model.shape)
    rows, columns = np.indices((15, 17))
    lattice[::2, ::2, ::2] = model.free[::2, ::2] & ((rows + columns) % 2 == phase)
    prior = (1 - share) * belief + share * lattice / lattice.sum()
    expected, expected_evidence = correct(
        prior, weight * scan_log_likelihood(model, ranges, angles))
    full = np.zeros(model.shape)
    r0, r1, c0, c1 = box
    full[:, r0:r1, c0:c1] = correction.parts[0]
    ks, rs, cs, kept = correction.kept
    full[ks, rs, cs] = kept
    np.testing.assert_allclose(full, expected, rtol=0, atol=1e-14)
    assert correction.log_evidence == pytest.approx(expected_evidence, abs=1e-12)
    assert correction.left_out == pytest.approx(0.0, abs=1e-15)   # the sums' rounding


def test_the_lattice_s_parts_take_each_free_lattice_cell_once():
    model = room(31, 34)
    parts = [window.lattice_cells(model, phase) for phase in range(window.KIDNAP_PHASES)]
    np.testing.assert_array_equal(sum(part.astype(int) for part in parts),
                                  model.free[::2, ::2].astype(int))
    np.testing.assert_array_equal(window.lattice_cells(model, window.KIDNAP_PHASES + 1),
                                  parts[1])


def test_a_kidnapped_robot_is_found_on_the_lattice():
    """The belief sure of a wrong place; scans that only the true place explains."""
    model = room(60, 60)
    loc = GridLocalization(model, default_odometry_noise(), 0.0, 0.0, 10.0,
                           kidnap_probability=1e-3, belief_floor=1e-9)
    loc.set_prior((0.0, 3.5, 0.0), np.diag([1e-3, 1e-3, 1e-3]))
    truth = (3.2 - 1.0, 2.0 + 4.2, 0.0)     # a lattice state's centre, far from the prior
    xs, ys = model.cell_centres()
    j, i = int(np.argmin(abs(xs - truth[0]))), int(np.argmin(abs(ys - truth[1])))
    field = np.full(model.free.shape, math.log(0.01))
    field[i, j + 5] = math.log(50.0)        # only from the truth does a beam end here
    model = GridModel(model.free, field, math.log(0.01), model.resolution,
                      model.origin, model.heading_bins)
    loc.model = model
    ranges, angles = np.array([0.5]), np.array([0.0])
    loc.on_odometry((0.0, 0.0, 0.0), SECOND)
    for step in range(3):
        loc.on_odometry((0.0, 0.0, 0.0), (step + 1) * SECOND)
        loc.update(ranges, angles, (step + 1) * SECOND)
    # Found: a pose from which the beam ends in the marked cell (every heading has one).
    pose = loc.estimate(0.3, 0.2).pose
    end = (pose[0] + 0.5 * math.cos(pose[2]), pose[1] + 0.5 * math.sin(pose[2]))
    assert math.hypot(end[0] - xs[j + 5], end[1] - ys[i]) < 0.1
    assert math.hypot(pose[0] - 0.0, pose[1] - 3.5) > 1.0


def test_the_compiled_lattice_scan_equals_numpys_and_the_dense_scan_on_the_lattice():
    model = room(260, 250)     # a lattice of 8 x 130 x 125 states: the compiled path
    assert compiled_kernels(8 * 130 * 125) is not None
    ranges, angles = scan(20, np.random.default_rng(11))
    reads = _scan_reads(model, ranges, angles)
    rows, cols = (2 * index for index in np.nonzero(window.lattice_cells(model, 1)))
    compiled, scored = _scan_log_likelihood_cells(model, reads, 2, rows, cols, compiled=True)
    numpy_s, _ = _scan_log_likelihood_cells(model, reads, 2, rows, cols, compiled=False)
    dense = _scan_log_likelihood(model, ranges, angles)
    # The same sums in the same order: the same bits.
    assert scored.all()
    np.testing.assert_array_equal(compiled, numpy_s)
    np.testing.assert_array_equal(compiled, dense[::2][:, rows, cols])


def test_a_lattice_state_stops_being_scored_only_below_its_bound():
    """Stopped sums are upper bounds below the threshold; the others are exact, on both
    paths alike."""
    model = room(260, 250)
    ranges, angles = scan(20, np.random.default_rng(11))
    reads = _scan_reads(model, ranges, angles)
    rows, cols = (2 * index for index in np.nonzero(window.lattice_cells(model, 0)))
    dense = _scan_log_likelihood(model, ranges, angles)[::2][:, rows, cols]
    below = np.full(rows.size, float(np.median(dense)))
    below[::3] = -math.inf        # never stopped
    compiled, scored = _scan_log_likelihood_cells(model, reads, 2, rows, cols, below)
    numpy_s, numpy_scored = _scan_log_likelihood_cells(model, reads, 2, rows, cols, below,
                                                       compiled=False)
    np.testing.assert_array_equal(scored, numpy_scored)
    np.testing.assert_array_equal(compiled, numpy_s)
    assert 0 < scored.sum() < scored.size
    assert scored[:, ::3].all()
    np.testing.assert_array_equal(compiled[scored], dense[scored])
    # Upper bounds (to the rounding of a sum in another order).
    assert (compiled[~scored] >= dense[~scored] - 1e-9).all()
    assert (compiled[~scored] < below[None].repeat(scored.shape[0], 0)[~scored]).all()


def test_a_window_scores_only_its_heading_layers_with_probability():
    model = room(40, 44)
    ranges, angles = scan(20, np.random.default_rng(11))
    headings = np.array([3, 4, 5, 15])
    box = (5, 30, 7, 40)
    dense = _scan_log_likelihood(model, ranges, angles, box=box)
    np.testing.assert_array_equal(
        _scan_log_likelihood(model, ranges, angles, box=box, headings=headings),
        dense[headings])


def test_the_windowed_steps_need_no_kernel_beyond_those_compiled_at_load():
    """A kernel compiled mid-run (a new argument layout) is where a Ctrl-C ends in a
    traceback (core/compiled_loader.py): the windowed update and its kidnap lattice use
    exactly the versions warm_up compiled."""
    kernels = compiled_kernels(COMPILED_MIN_STATES)
    model = room(300, 300, bins=32)
    loc = GridLocalization(model, default_odometry_noise(), 0.0, 0.0, 10.0,
                           kidnap_probability=1e-12, belief_floor=1e-9)
    loc.set_prior((12.0, 16.0, 0.3), np.diag([0.6, 0.6, 0.05]))
    compiled = {name: len(getattr(kernels, name).signatures) for name in
                ("shift_motion", "blur_headings", "blur_rows", "blur_cols_masked",
                 "scan_log_likelihood", "scan_log_likelihood_cells")}
    # A scan of its own seed: the module's RNG would make it depend on the tests before.
    ranges, angles = scan(30, np.random.default_rng(7))
    for step in range(4):
        loc.on_odometry((0.1 * step, 0.0, 0.05 * step), (step + 1) * SECOND)
        loc.update(ranges, angles, (step + 1) * SECOND)
    # The window's compiled path ran: more states than COMPILED_MIN_STATES, not all.
    assert COMPILED_MIN_STATES < loc.window_states < model.free.size * 32 / 2
    assert {name: len(getattr(kernels, name).signatures) for name in compiled} == compiled
    # Whatever ran before in this process: no version for a strided ('A') array.
    assert not [sig for name in compiled for sig in getattr(kernels, name).signatures
                if "'A'" in str(sig)]


def test_two_far_modes_are_two_windows_and_the_filter_stays_the_dense_one():
    model = room(120, 130)
    dense, windowed = tracked_pair(model, floor=1e-30)
    # Two hypotheses 8 m apart: one window around each, not the box of both.
    belief = 0.6 * gaussian_prior(model, 1.5, 4.0, 0.3, np.diag([0.01, 0.01, 0.01])) \
        + 0.4 * gaussian_prior(model, 9.5, 12.0, 2.0, np.diag([0.01, 0.01, 0.01]))
    for loc in (dense, windowed):
        loc._hold(belief.copy())
    odometry = (0.0, 0.0, 0.0)
    for step in range(6):
        odometry = (odometry[0] + 0.1, odometry[1], odometry[2] + 0.05)
        ranges, angles = scan()
        for loc in (dense, windowed):
            loc.on_odometry(odometry, (step + 1) * SECOND)
            loc.update(ranges, angles, (step + 1) * SECOND)
        assert_the_same_filter(windowed, dense)
        boxes = windowed._windows.boxes
        assert len(boxes) == 2
        rows = [r for box in boxes for r in box[:2]]
        cols = [c for box in boxes for c in box[2:]]
        both = (max(rows) - min(rows)) * (max(cols) - min(cols)) * model.heading_bins
        assert windowed.window_states < 0.5 * both


def test_support_boxes_group_near_cells_and_never_overlap():
    footprint = np.zeros((60, 60), dtype=bool)
    footprint[5:8, 5:9] = True
    footprint[10, 12] = True                    # within JOIN_CELLS: the same window
    footprint[40:45, 30:33] = True              # far: a window of its own
    boxes = window.support_boxes(footprint)
    assert sorted(boxes) == [(5, 11, 5, 13), (40, 45, 30, 33)]
    assert window.support_boxes(np.zeros((4, 4), dtype=bool)) == []
    # Too many separate groups: one box of all.
    scattered = np.zeros((200, 200), dtype=bool)
    scattered[::20, ::20] = True
    assert window.support_boxes(scattered) == [(0, 181, 0, 181)]
    # Boxes that overlap are joined, repeatedly: a chain of three becomes one.
    assert window.disjoint([(0, 5, 0, 5), (4, 9, 8, 12), (8, 12, 0, 9)]) == [(0, 12, 0, 12)]
    assert window.disjoint([(0, 5, 0, 5), (5, 9, 5, 9)]) == [(0, 5, 0, 5), (5, 9, 5, 9)]


def test_more_groups_than_max_windows_are_joined_with_their_nearest_not_into_one_box():
    footprint = np.zeros((200, 220), dtype=bool)
    count = window.MAX_WINDOWS + 3
    footprint[10, 10:10 + 10 * count:10] = True       # a row of groups 10 cells apart
    footprint[180, 60:60 + 10 * count:10] = True      # another, far from the first
    boxes = window.support_boxes(footprint)
    assert len(boxes) == 2
    covered = np.zeros_like(footprint)
    for r0, r1, c0, c1 in boxes:
        covered[r0:r1, c0:c1] = True
    assert covered[footprint].all()
    assert covered.sum() < 0.01 * footprint.size
    # Few enough groups keep a window each.
    few = np.zeros_like(footprint)
    few[10, 10:10 + 10 * window.MAX_WINDOWS:10] = True
    assert len(window.support_boxes(few)) == window.MAX_WINDOWS


def test_the_prior_in_its_box_is_the_whole_one_above_the_cut():
    """priors.gaussian_prior_window: every state at or above the cut is in its box, with
    gaussian_prior's value (to rounding: its sum runs in another order), and what it
    leaves out is the probability of the states outside the box, each below the cut."""
    from estimation_nodes.core.grid.priors import gaussian_prior_window

    model = room(200, 150, bins=16)
    covariance = np.diag([0.3, 0.2, 0.1])
    whole = gaussian_prior(model, 6.0, 9.0, 0.4, covariance)
    cut = 1e-9
    (r0, r1, c0, c1), part, left_out = gaussian_prior_window(model, 6.0, 9.0, 0.4,
                                                             covariance, cut)
    inside = np.zeros(model.shape, dtype=bool)
    inside[:, r0:r1, c0:c1] = True
    assert np.all(inside[whole >= cut * whole.max()])
    assert inside.sum() < 0.5 * inside.size             # not the building's box
    np.testing.assert_allclose(part, whole[:, r0:r1, c0:c1], rtol=1e-12, atol=0)
    assert np.all(whole[~inside] < cut * whole.max())
    assert left_out == pytest.approx(float(whole[~inside].sum()), rel=1e-9)
    assert 0.0 < left_out < cut * whole.size


def test_a_window_scored_on_its_free_cells_alone_has_their_very_sums():
    """laser._scan_log_likelihood's free_only: the free cells' sums bit for bit, -inf on
    the others, on both paths, for a box of mostly walls and for a whole row of runs."""
    import dataclasses

    base = room(260, 250)
    rng = np.random.default_rng(12)
    model = dataclasses.replace(base, free=base.free & (rng.random(base.free.shape) < 0.3))
    ranges, angles = scan(20, np.random.default_rng(13))
    for box in [(30, 200, 20, 240), window.full_box(model), (100, 101, 0, 250)]:
        r0, r1, c0, c1 = box
        free = model.free[r0:r1, c0:c1]
        whole = _scan_log_likelihood(model, ranges, angles, True, box)
        for compiled in (True, False):
            runs = _scan_log_likelihood(model, ranges, angles, compiled, box, free_only=True)
            np.testing.assert_array_equal(runs[:, free], whole[:, free])
            assert np.all(runs[:, ~free] == -np.inf)
    assert window._mostly_not_free(model, window.full_box(model))
    assert not window._mostly_not_free(base, window.full_box(base))
