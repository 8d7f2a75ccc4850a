"""CausalOrder: whatever order events arrive in, the state is that of the events in stamp order."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation_nodes.core.causal_order import CausalOrder, Submission
from estimation_nodes.core.errors import ZeroEvidenceError
from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.filter import HistogramFilter
from estimation_nodes.core.tiles.models import HistogramModel

SECOND = 10**9
MOVE, READING = 0, 1
#: Eight cells, one bright, and a sensor that never reads a dark tile as bright: a bright
#: reading has no evidence on a belief that rules out cell 0.
ONE_BRIGHT = HistogramModel.from_lists(["bright"] + ["dark"] * 7, ["bright", "dark"],
                                       [[0.8, 0.2], [0.0, 1.0]], [0.1, 0.8, 0.1])


class Sequence:
    """A toy filter whose state is the tuple of events applied, in order; an event rejected
    when ``reject(state, event)`` says so. It logs every application, as a node publishes."""

    def __init__(self, reject=lambda state, event: False):
        self.state: tuple = ()
        self.published: list[tuple] = []
        self._reject = reject

    def snapshot(self):
        return self.state

    def restore(self, state):
        self.state = state

    def apply(self, event, first_time):
        if self._reject(self.state, event):
            return False
        self.state = self.state + (event,)
        self.published.append(self.state)
        return True


class TileFilter:
    """A histogram filter as the estimator replays it: a reading of zero evidence is
    rejected, the belief left as it was. It logs every try with its ``first_time``."""

    def __init__(self, model):
        self.belief_filter = HistogramFilter(model, histogram.uniform(model.size),
                                             in_place=False)
        self.tries = []

    def snapshot(self):
        return self.belief_filter.snapshot()

    def restore(self, state):
        self.belief_filter.restore(state)

    def apply(self, event, first_time):
        self.tries.append((event, first_time))
        kind, value = event
        if kind == "move":
            self.belief_filter.predict(value)
            return True
        try:
            self.belief_filter.correct(value)
        except ZeroEvidenceError:
            return False
        return True


def offline(model, events):
    """The oracle: the belief of the filter over ``events`` (stamp, rank, event) sorted in
    causal order, from a uniform prior, and the stamps of the readings it rejected."""
    belief, rejected = histogram.uniform(model.size), []
    for stamp, _, (kind, value) in sorted(events):
        if kind == "move":
            belief = histogram.predict(belief, value, model.kernel)
            continue
        try:
            belief, _ = histogram.correct(belief, model.likelihood(value))
        except ZeroEvidenceError:
            rejected.append(stamp)
    return belief, rejected


def test_in_order_events_are_applied_once_each():
    target = Sequence()
    order = CausalOrder(target, 10 * SECOND, 1000)
    for stamp in (1, 2, 3):
        submission = order.submit(stamp, 0, stamp)
        assert submission.applied and not submission.reordered
    assert target.state == (1, 2, 3)
    assert target.published == [(1,), (1, 2), (1, 2, 3)]


def test_a_late_event_goes_in_its_place_and_the_later_ones_are_applied_again():
    target = Sequence()
    order = CausalOrder(target, 10 * SECOND, 1000)
    order.submit(1, 0, "move 1")
    order.submit(3, 1, "reading 2")          # arrived before the move that caused it
    submission = order.submit(2, 0, "move 2")
    assert submission.reordered and submission.reapplied == 1
    assert target.state == ("move 1", "move 2", "reading 2")
    # What a subscriber saw: the provisional estimate, then the ones that replace it.
    assert target.published[-2:] == [("move 1", "move 2"), ("move 1", "move 2", "reading 2")]


def test_rank_orders_events_of_the_same_instant():
    target = Sequence()
    order = CausalOrder(target, 10 * SECOND, 1000)
    order.submit(5, 1, "reading")
    order.submit(5, 0, "move")
    assert target.state == ("move", "reading")


def test_a_rejected_late_event_changes_nothing_and_replays_nothing():
    target = Sequence(reject=lambda state, event: event == "bad")
    order = CausalOrder(target, 10 * SECOND, 1000)
    order.submit(1, 0, "a")
    order.submit(3, 0, "c")
    published = len(target.published)
    submission = order.submit(2, 0, "bad")
    assert not submission.applied
    assert target.state == ("a", "c") and len(target.published) == published
    order.submit(2, 0, "b")                   # the history is intact
    assert target.state == ("a", "b", "c")


def test_an_event_older_than_the_horizon_is_applied_now_and_reported():
    target = Sequence()
    order = CausalOrder(target, 2 * SECOND, 1000)
    for stamp in (1, 2, 3, 4, 5):
        order.submit(stamp * SECOND, 0, stamp)
    assert len(order) == 3                    # stamps 3, 4, 5: within 2 s of the newest
    submission = order.submit(1 * SECOND + 1, 0, "late")
    assert submission.applied and submission.too_late
    assert target.state == (1, 2, 3, 4, 5, "late")
    # Within the horizon it still goes in its place.
    order.submit(4 * SECOND + 1, 0, "in place")
    assert target.state == (1, 2, 3, 4, "in place", 5, "late")


def test_max_events_bounds_the_history():
    target = Sequence()
    order = CausalOrder(target, 100 * SECOND, 4)
    for stamp in range(10):
        order.submit(stamp, 0, stamp)
    assert len(order) == 4


def test_the_first_events_can_be_reordered_while_nothing_was_forgotten():
    target = Sequence()
    order = CausalOrder(target, 10 * SECOND, 1000)
    order.submit(2, 1, "reading")
    order.submit(1, 0, "move")
    assert target.state == ("move", "reading")


def test_clear_forgets_the_past():
    target = Sequence()
    order = CausalOrder(target, 10 * SECOND, 1000)
    order.submit(1, 0, "a")
    order.clear()
    target.state = ()
    order.submit(0, 0, "b")
    assert target.state == ("b",)


@settings(max_examples=200, deadline=None)
@given(st.permutations(range(12)))
def test_any_arrival_order_ends_in_stamp_order(arrival):
    """Any permutation, with a history at least as long as the worst lateness, gives the
    state of the events in stamp order, and the last estimate published is that state."""
    target = Sequence()
    order = CausalOrder(target, 100 * SECOND, 12)
    for stamp in arrival:
        order.submit(stamp, 0, stamp)
    assert target.state == tuple(range(12))
    assert target.published[-1] == tuple(range(12))
    # Every prefix of the causal order was published at some point: each step settled.
    assert all(tuple(range(k)) in target.published for k in range(1, 13))


@pytest.mark.parametrize("in_place", [True, False])
def test_histogram_snapshots_survive_later_steps_only_without_in_place(in_place):
    world = HistogramModel.book()
    belief_filter = HistogramFilter(world, histogram.uniform(world.size), in_place=in_place)
    belief_filter.predict(1)
    saved = belief_filter.snapshot()
    kept = saved[0].copy()
    belief_filter.correct("bright")
    assert np.array_equal(saved[0], kept) is (not in_place)


def test_the_book_example_in_any_arrival_order():
    """Example 6.14 with its readings arriving before their moves: the book's numbers."""
    target = TileFilter(HistogramModel.book())
    order = CausalOrder(target, 10 * SECOND, 1000)
    events = [(1, 0, ("move", 1)), (2, 1, ("read", "bright")), (3, 0, ("move", 1)),
              (4, 1, ("read", "dark")), (5, 0, ("move", 1)), (6, 1, ("read", "dark"))]
    for index in (1, 0, 3, 2, 5, 4):
        order.submit(*events[index])
    np.testing.assert_allclose(target.belief_filter.belief,
                               [0.048443, 0.063322, 0.244983, 0.528374, 0.114879], atol=1e-6)


def test_a_rejected_event_is_kept_and_tried_again_when_the_state_before_it_changes():
    """A reading possible only after the second move: rejected when it arrives before that
    move, taken when the move comes (tried again, not as a new arrival)."""
    target = Sequence(reject=lambda state, event: event == "reading" and len(state) < 2)
    order = CausalOrder(target, 10 * SECOND, 1000)
    order.submit(1, MOVE, "move 1")
    assert not order.submit(3, READING, "reading").applied
    assert len(order) == 2                    # kept in its place
    submission = order.submit(2, MOVE, "move 2")
    assert submission == Submission(applied=True, reordered=True, taken_on_retry=1)
    assert target.state == ("move 1", "move 2", "reading")


def test_an_event_dropped_on_reapply_stays_kept_and_is_taken_again_later():
    """A reading possible after one or three moves, not two: taken, dropped when the second
    move comes late, taken again when the third does."""
    target = Sequence(reject=lambda state, event: event == "reading" and len(state) == 2)
    order = CausalOrder(target, 10 * SECOND, 1000)
    order.submit(1, MOVE, 1)
    assert order.submit(5, READING, "reading").applied
    assert order.submit(2, MOVE, 2) == Submission(applied=True, reordered=True,
                                                    dropped_on_reapply=1)
    assert target.state == (1, 2)
    assert order.submit(3, MOVE, 3) == Submission(applied=True, reordered=True,
                                                    taken_on_retry=1)
    assert target.state == (1, 2, 3, "reading")


def test_a_reading_of_zero_evidence_on_arrival_is_taken_once_its_move_comes():
    """The bright cell seen, two cells on, and a bright reading that reaches the filter
    before the move of six that brought the robot back: no evidence on arrival (the belief
    is on cells 1 to 3), taken once the move is in its place, as the offline filter takes
    it."""
    events = [(1 * SECOND, READING, ("read", "bright")), (2 * SECOND, MOVE, ("move", 2)),
              (3 * SECOND, MOVE, ("move", 6)), (4 * SECOND, READING, ("read", "bright"))]
    target = TileFilter(ONE_BRIGHT)
    order = CausalOrder(target, 10 * SECOND, 1000)
    submissions = [order.submit(*events[index]) for index in (0, 1, 3, 2)]
    assert not submissions[2].applied
    assert submissions[3] == Submission(applied=True, reordered=True, taken_on_retry=1)
    # Tried again as a replay, not as a new arrival: a node counts it once.
    assert target.tries[-1] == (("read", "bright"), False)
    expected, rejected_offline = offline(ONE_BRIGHT, events)
    assert rejected_offline == []
    np.testing.assert_allclose(target.belief_filter.belief, expected, rtol=0, atol=1e-12)


def test_a_reading_rejected_again_leaves_the_offline_state_until_a_move_allows_it():
    """The late move of one still leaves cell 0 out: rejected again, as offline. A second
    late move, of five, brings the belief back over cell 0: taken then."""
    events = [(1 * SECOND, READING, ("read", "bright")), (2 * SECOND, MOVE, ("move", 2)),
              (4 * SECOND, READING, ("read", "bright"))]
    target = TileFilter(ONE_BRIGHT)
    order = CausalOrder(target, 10 * SECOND, 1000)
    for event in events:
        order.submit(*event)
    events.append((3 * SECOND, MOVE, ("move", 1)))
    assert order.submit(*events[-1]) == Submission(applied=True, reordered=True)
    expected, rejected_offline = offline(ONE_BRIGHT, events)
    assert rejected_offline == [4 * SECOND]
    np.testing.assert_allclose(target.belief_filter.belief, expected, rtol=0, atol=1e-12)

    events.append((3 * SECOND + 1, MOVE, ("move", 5)))
    assert order.submit(*events[-1]).taken_on_retry == 1
    expected, rejected_offline = offline(ONE_BRIGHT, events)
    assert rejected_offline == []
    np.testing.assert_allclose(target.belief_filter.belief, expected, rtol=0, atol=1e-12)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.data())
def test_any_arrival_order_ends_on_the_offline_filter_with_rejections(data):
    """Moves and readings on the one-bright world, some of them of zero evidence in causal
    order or on arrival: whatever the arrival order, with nothing forgotten, the belief is
    the offline filter's over the events in causal order."""
    steps = data.draw(st.lists(st.one_of(
        st.tuples(st.just("move"), st.integers(0, 7)),
        st.tuples(st.just("read"), st.sampled_from(["bright", "dark"]))), min_size=1,
        max_size=10))
    events = [(stamp * SECOND, MOVE if kind == "move" else READING, (kind, value))
              for stamp, (kind, value) in enumerate(steps)]
    arrival = data.draw(st.permutations(events))
    target = TileFilter(ONE_BRIGHT)
    order = CausalOrder(target, 100 * SECOND, len(events))
    for event in arrival:
        assert not order.submit(*event).too_late
    assert len(order) == len(events)          # nothing forgotten, rejected ones kept
    expected, _ = offline(ONE_BRIGHT, events)
    np.testing.assert_allclose(target.belief_filter.belief, expected, rtol=0, atol=1e-12)
