"""Events applied in the order they happened, whatever order they arrived in.

DDS keeps the order of one publisher's messages on one topic, not across
topics: a reading can reach the estimator before the move that caused it
(right after discovery, under load, or when a link comes back with a
backlog). ``CausalOrder`` applies each event at once; when an event arrives
that happened before events already applied, it restores the filter state
saved before the first of them, applies the late event and then the later
ones again, in order (robot_localization's ``smooth_lagged_data`` idea). An
event in order costs one state snapshot (references, no copy) and one list
append; nothing waits for a reorder window.

The order key is (stamp, rank, arrival): ``stamp`` is when the event happened
(a source timestamp, in ns), ``rank`` breaks ties between kinds of event (a
move before the reading taken at the same instant), and arrival keeps equal
keys stable.

The history is bounded by ``horizon_ns`` (events older than the newest by
more are forgotten) and ``max_events``. An event older than everything the
history still holds cannot be put in its place: it is applied at once, as
the newest, and reported as such (``Submission.too_late``).
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar

State = TypeVar("State")


class Replayable(Protocol[State]):
    """What ``CausalOrder`` needs of a filter: save, restore, and apply one event."""

    def snapshot(self) -> State:
        """The state as it is now; later steps must not modify what this returns."""
        ...

    def restore(self, state: State) -> None:
        """Go back to a state ``snapshot`` returned."""
        ...

    def apply(self, event: Any, first_time: bool) -> bool:
        """Apply ``event``; False when it was rejected and changed nothing.

        ``first_time`` is False when the event is applied again after a late one.
        """
        ...


@dataclass(frozen=True)
class Submission:
    """What one ``submit`` did."""

    #: The event changed the state (False: rejected, nothing kept).
    applied: bool
    #: It happened before events already applied, and was put in its place.
    reordered: bool = False
    #: Events applied again after it (0 when it arrived in order).
    reapplied: int = 0
    #: Events that were applied before but were rejected when applied again.
    dropped_on_reapply: int = 0
    #: It happened before everything the history holds: applied at once, out of order.
    too_late: bool = False


#: What most submissions return (a Submission is immutable, so one of each will do).
_APPLIED, _REJECTED = Submission(applied=True), Submission(applied=False)


@dataclass
class _Entry(Generic[State]):
    key: tuple[int, int, int]
    event: Any
    before: State


def _key_of(entry: _Entry) -> tuple[int, int, int]:
    return entry.key


class CausalOrder(Generic[State]):
    """Applies events to ``target`` in the order of their stamps (see the module docstring)."""

    def __init__(self, target: Replayable[State], horizon_ns: int, max_events: int) -> None:
        if horizon_ns < 0 or max_events < 1:
            raise ValueError(f"horizon_ns must be >= 0 and max_events >= 1, got {horizon_ns} "
                             f"and {max_events}")
        self._target = target
        self._horizon_ns = horizon_ns
        self._max_events = max_events
        self._entries: list[_Entry[State]] = []
        self._arrivals = 0
        # Whether the oldest entry's saved state is the start of everything applied:
        # true until the history forgets its first event.
        self._holds_everything = True

    def __len__(self) -> int:
        return len(self._entries)

    def clear(self) -> None:
        """Forget every event (after a reset: the state no longer follows from them)."""
        self._entries.clear()
        self._holds_everything = True

    def submit(self, stamp_ns: int, rank: int, event: Any) -> Submission:
        """Apply ``event``, which happened at ``stamp_ns``, in its place among the others."""
        self._arrivals += 1
        key = (stamp_ns, rank, self._arrivals)
        entries = self._entries
        if not entries or key > entries[-1].key:
            return _APPLIED if self._apply_new(key, event) else _REJECTED
        if key < entries[0].key and not self._holds_everything:
            # Nothing saved goes back far enough: apply it now, as the newest event.
            newest = entries[-1].key
            applied = self._apply_new((newest[0], newest[1], self._arrivals), event)
            return Submission(applied=applied, too_late=True)
        return self._insert(key, event)

    def _apply_new(self, key: tuple[int, int, int], event: Any) -> bool:
        before = self._target.snapshot()
        if not self._target.apply(event, True):
            return False
        self._entries.append(_Entry(key, event, before))
        self._forget_old()
        return True

    def _insert(self, key: tuple[int, int, int], event: Any) -> Submission:
        """Go back to the state before the first later event, apply ``event``, then the
        later ones again."""
        entries = self._entries
        index = bisect_right(entries, key, key=_key_of)
        later = entries[index:]
        del entries[index:]
        latest = self._target.snapshot()
        self._target.restore(later[0].before)
        if not self._apply_new(key, event):
            # Rejected: it changes nothing, so the later events need not run again.
            self._target.restore(latest)
            entries.extend(later)
            return Submission(applied=False)
        dropped = 0
        for entry in later:
            before = self._target.snapshot()
            if self._target.apply(entry.event, False):
                entries.append(_Entry(entry.key, entry.event, before))
            else:
                dropped += 1
        self._forget_old()
        return Submission(applied=True, reordered=True, reapplied=len(later) - dropped,
                          dropped_on_reapply=dropped)

    def _forget_old(self) -> None:
        entries = self._entries
        if not entries:
            return
        oldest_kept = entries[-1].key[0] - self._horizon_ns
        if entries[0].key[0] >= oldest_kept and len(entries) <= self._max_events:
            return   # the usual case, one event in and nothing old enough to go: no search
        cut = max(len(entries) - self._max_events,
                  bisect_right(entries, (oldest_kept, -1, -1), key=_key_of))
        if cut > 0:
            del entries[:cut]
            self._holds_everything = False
