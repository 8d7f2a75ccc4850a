"""CausalOrder: whatever order events arrive in, the state is that of the events in stamp order."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation_nodes.core.causal_order import CausalOrder
from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.filter import HistogramFilter
from estimation_nodes.core.tiles.models import HistogramModel

SECOND = 10**9


class Sequence:
    """A toy filter whose state is the tuple of events applied, in order; odd ones rejected
    when ``reject`` says so. It logs every application, as a node publishes."""

    def __init__(self, reject=lambda event: False):
        self.state: tuple = ()
        self.published: list[tuple] = []
        self._reject = reject

    def snapshot(self):
        return self.state

    def restore(self, state):
        self.state = state

    def apply(self, event, first_time):
        if self._reject(event):
            return False
        self.state = self.state + (event,)
        self.published.append(self.state)
        return True


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
    target = Sequence(reject=lambda event: event == "bad")
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
    world = HistogramModel.book()

    class Filter:
        def __init__(self):
            self.belief_filter = HistogramFilter(world, histogram.uniform(world.size),
                                                 in_place=False)

        def snapshot(self):
            return self.belief_filter.snapshot()

        def restore(self, state):
            self.belief_filter.restore(state)

        def apply(self, event, first_time):
            kind, value = event
            (self.belief_filter.predict if kind == "move" else self.belief_filter.correct)(value)
            return True

    target = Filter()
    order = CausalOrder(target, 10 * SECOND, 1000)
    events = [(1, 0, ("move", 1)), (2, 1, ("read", "bright")), (3, 0, ("move", 1)),
              (4, 1, ("read", "dark")), (5, 0, ("move", 1)), (6, 1, ("read", "dark"))]
    for index in (1, 0, 3, 2, 5, 4):
        order.submit(*events[index])
    np.testing.assert_allclose(target.belief_filter.belief,
                               [0.048443, 0.063322, 0.244983, 0.528374, 0.114879], atol=1e-6)
