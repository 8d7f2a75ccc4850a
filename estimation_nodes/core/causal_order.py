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

A rejected event is kept in its place too. Whether a reading is possible can
depend on the state before it (with a zero in the sensor model, a reading can
have no evidence on a belief that a move still on its way would have shifted),
and that state is provisional until every earlier event has come. So whenever a late event
changes the state before a rejected one, the replay tries it again: taken now,
it changes the state like any other; rejected again, it stays kept. With
nothing forgotten, the state is that of the events applied in causal order
from the start, each taken or rejected on the state before it: what the filter
run offline over the sorted events gives. This needs ``apply`` to be a function
of the state and the event (the same answer on the same state): a late event
that is rejected leaves the state before every later one as it was, so nothing
after it runs again.

The order key is (stamp, rank, arrival): ``stamp`` is when the event happened
(a source timestamp, in ns), ``rank`` breaks ties between kinds of event (a
move before the reading taken at the same instant), and arrival keeps equal
keys stable.

The history is bounded by ``horizon_ns`` (events older than the newest by
more are forgotten) and ``max_events``, rejected events included. An event
older than everything the history still holds cannot be put in its place: it
is applied at once, as the newest, and reported as such
(``Submission.too_late``).
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

        ``first_time`` is True once per event, when it arrives, and False whenever it
        runs again after a late one: applied again, or tried again after a rejection
        (count an event, or warn of it, only the first time).
        """
        ...


@dataclass(frozen=True)
class Submission:
    """What one ``submit`` did."""

    #: The event changed the state (False: rejected; kept in its place, to be tried again
    #: if a late event changes the state before it).
    applied: bool
    #: It happened before events already applied, was applied in its place and the later
    #: ones run again (False for a rejected one: it changed nothing, so nothing ran again).
    reordered: bool = False
    #: Events after it applied before and applied again (0 when it arrived in order).
    reapplied: int = 0
    #: Events after it that were applied before but were rejected when applied again
    #: (kept, to be tried again).
    dropped_on_reapply: int = 0
    #: Events after it that were rejected before and were taken when tried again.
    taken_on_retry: int = 0
    #: It happened before everything the history holds: applied at once, out of order.
    too_late: bool = False


#: What most submissions return (a Submission is immutable, so one of each will do).
_APPLIED, _REJECTED = Submission(applied=True), Submission(applied=False)


@dataclass
class _Entry(Generic[State]):
    key: tuple[int, int, int]
    event: Any
    before: State
    #: Whether the event changed the state from ``before`` (False: rejected there).
    taken: bool


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
        """Apply ``event`` after every event held, and keep it, taken or not."""
        before = self._target.snapshot()
        taken = self._target.apply(event, True)
        self._entries.append(_Entry(key, event, before, taken))
        self._forget_old()
        return taken

    def _insert(self, key: tuple[int, int, int], event: Any) -> Submission:
        """Go back to the state before the first later event, apply ``event``, then run the
        later ones again (those rejected before are tried again)."""
        entries = self._entries
        index = bisect_right(entries, key, key=_key_of)
        latest = self._target.snapshot()
        before = entries[index].before
        self._target.restore(before)
        if not self._target.apply(event, True):
            # Rejected: the state before each later event is as it was, and so is what
            # each did there; nothing runs again.
            self._target.restore(latest)
            entries.insert(index, _Entry(key, event, before, False))
            self._forget_old()
            return _REJECTED
        later = entries[index:]
        del entries[index:]
        entries.append(_Entry(key, event, before, True))
        reapplied = dropped = retaken = 0
        for entry in later:
            before = self._target.snapshot()
            taken = self._target.apply(entry.event, False)
            entries.append(_Entry(entry.key, entry.event, before, taken))
            if entry.taken and taken:
                reapplied += 1
            elif entry.taken:
                dropped += 1
            elif taken:
                retaken += 1
        self._forget_old()
        return Submission(applied=True, reordered=True, reapplied=reapplied,
                          dropped_on_reapply=dropped, taken_on_retry=retaken)

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
