"""Scans that never reached the localizer, counted from the stamps of those that did.

A laser publishes at its own rate; the localizer's scan subscription keeps only the
newest scan (depth 1), so while an update runs the scans that come replace one another
and only the last is answered. Nothing in the transport reports those replaced: the
stamps do. Between two scans received ``dt`` apart, ``round(dt / scan_time) - 1`` were
made and not received. A driver that leaves ``scan_time`` 0 gives no period, and no
count is made: a recording's scans may come at irregular times (a log's scans thinned
out), where any period guessed from the intervals would count scans that never were.
"""

from __future__ import annotations

#: A gap longer than this many periods is a pause of the laser or a jump of the recording
#: played, not scans missed: it is not counted.
LONGEST_GAP = 1000


class ScanGaps:
    """Counts the scans missed between those received."""

    def __init__(self) -> None:
        self.missed = 0
        self.received = 0
        self._last_ns: int | None = None

    def note(self, stamp_ns: int | None, scan_time_s: float) -> int:
        """Note a received scan (its stamp, None if unstamped, and its ``scan_time``);
        the scans missed just before it (also added to ``missed``)."""
        self.received += 1
        if stamp_ns is None:
            return 0
        last, self._last_ns = self._last_ns, stamp_ns
        if last is None or stamp_ns <= last:    # the first, or time went back (a replay)
            return 0
        if not 0 < scan_time_s < float("inf"):
            return 0
        gap = round((stamp_ns - last) / (scan_time_s * 1e9)) - 1
        if not 0 < gap <= LONGEST_GAP:
            return 0
        self.missed += gap
        return gap
