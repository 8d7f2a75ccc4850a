"""Whether a recording holds every message its publishers sent (no rclpy here).

DDS numbers the samples each writer sends, 1, 2, 3, ..., and a raw subscription's
MessageInfo carries that number (``publication_sequence_number``). A number the
recorder never got, below the highest it got on the topic, is a message lost to the
recording: one sent before the recorder matched the publisher (the first ones), or
one the publisher's history no longer held for it (``history_depth``). What a
publisher sent after the last message recorded cannot be told apart from nothing,
so the end of a run is not covered.

Numbers are kept per topic, not per publisher (MessageInfo does not say which):
with several publishers on a topic, one's missing number may be another's, and a
loss may go unseen; what is reported is always lost.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from estimation_nodes.params.wording import plural


@dataclass
class SequenceGaps:
    """The publication sequence numbers recorded on each topic."""

    _seen: dict[str, set[int]] = field(default_factory=dict)

    def note(self, topic: str, sequence: int | None) -> None:
        """One recorded message; ``sequence`` None where the middleware gives no number."""
        if sequence is not None and sequence > 0:
            self._seen.setdefault(topic, set()).add(sequence)

    def missing(self) -> dict[str, list[tuple[int, int]]]:
        """Each topic with numbers missing below its highest: those, as inclusive ranges."""
        gaps = {}
        for topic, seen in sorted(self._seen.items()):
            ranges: list[tuple[int, int]] = []
            for number in range(1, max(seen) + 1):
                if number in seen:
                    continue
                if ranges and ranges[-1][1] == number - 1:
                    ranges[-1] = (ranges[-1][0], number)
                else:
                    ranges.append((number, number))
            if ranges:
                gaps[topic] = ranges
        return gaps

    def describe(self) -> list[str]:
        """One line per topic that misses messages (none: the recording is whole)."""
        lines = []
        for topic, ranges in self.missing().items():
            lost = sum(last - first + 1 for first, last in ranges)
            shown = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in ranges[:5])
            more = ", ..." if len(ranges) > 5 else ""
            lines.append(f"{topic}: {plural(lost, 'message')} of {max(self._seen[topic])} "
                         f"missing (sequence numbers {shown}{more})")
        return lines

    @property
    def recorded(self) -> int:
        """How many numbered messages were recorded."""
        return sum(len(seen) for seen in self._seen.values())
