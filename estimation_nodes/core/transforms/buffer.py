"""A transform tree over time with tf2's semantics, without ROS: what ``/tf`` and
``/tf_static`` say, kept so that ``lookup(target, source, time)`` answers where one frame
was in another at a time.

As in tf2's ``BufferCore``:
- each frame has one parent; a dynamic edge keeps its samples of the last
  ``cache_time_ns`` (10 s, tf2's default) and is interpolated between the two around the
  time asked (translation linearly, rotation by slerp); a static edge holds at any time;
- a lookup at a time outside an edge's samples is an extrapolation, refused with the
  frame, the time asked and the span held; time 0 asks for the latest time every dynamic
  edge on the way holds (tf2's "latest common time");
- a sample older than the cache or at a stamp the edge already holds is dropped
  (tf2's TF_OLD_DATA, TF_REPEATED_DATA).
Stricter than tf2, because a drop-in localizer must never follow a broken tree: a frame
given a second parent, a transform that would close a loop, a non-finite or non-unit
rotation, a changed static transform and (where the caller says what time it is) a
transform further in the future than a tolerance are refused with a
``TransformRejected`` whose ``reason`` a node counts. Nothing refused changes the tree.
"""

from __future__ import annotations

from bisect import bisect_left, insort
from dataclasses import dataclass, field

from estimation_nodes.core.errors import EstimationError
from estimation_nodes.core.transforms.rigid import Transform, interpolate

#: tf2's default cache: 10 s of each dynamic edge.
DEFAULT_CACHE_NS = 10_000_000_000


class TransformRejected(EstimationError):
    """A transform the buffer does not take; ``reason`` is a short key to count it by."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


class LookupFailed(EstimationError):
    """A lookup the tree cannot answer; the message names the frame and the times."""


class UnknownFrame(LookupFailed):
    """A frame no transform has named."""


class NotConnected(LookupFailed):
    """Two frames in trees that do not meet."""


class Extrapolation(LookupFailed):
    """A time outside what an edge on the way holds."""


@dataclass
class _Edge:
    """What is known of one frame's place in its parent."""

    parent: str
    static: Transform | None = None
    stamps: list[int] = field(default_factory=list)
    samples: dict[int, Transform] = field(default_factory=dict)

    def at(self, child: str, time_ns: int) -> Transform:
        if self.static is not None:
            return self.static
        stamps = self.stamps
        if not stamps:
            raise Extrapolation(f"no transform {self.parent} -> {child} is held")
        if time_ns in (0, stamps[-1]):
            return self.samples[stamps[-1]]
        i = bisect_left(stamps, time_ns)
        if i < len(stamps) and stamps[i] == time_ns:
            return self.samples[time_ns]
        if i == 0 or i == len(stamps):
            side = "past" if i == 0 else "future"
            raise Extrapolation(
                f"{self.parent} -> {child} at {time_ns * 1e-9:.3f} s: extrapolation into the "
                f"{side} (held {stamps[0] * 1e-9:.3f} to {stamps[-1] * 1e-9:.3f} s)")
        before, after = stamps[i - 1], stamps[i]
        return interpolate(self.samples[before], self.samples[after],
                           (time_ns - before) / (after - before))


class TransformBuffer:
    """The tree: ``set_transform`` what ``/tf`` and ``/tf_static`` say, ``lookup`` it."""

    def __init__(self, cache_time_ns: int = DEFAULT_CACHE_NS) -> None:
        if cache_time_ns <= 0:
            raise ValueError(f"cache_time_ns must be positive, got {cache_time_ns}")
        self._cache_ns = cache_time_ns
        self._edges: dict[str, _Edge] = {}

    def frames(self) -> list[str]:
        """Every frame the tree names, sorted."""
        names = set(self._edges) | {edge.parent for edge in self._edges.values()}
        return sorted(names)

    def parent_of(self, frame: str) -> str | None:
        edge = self._edges.get(_name(frame))
        return None if edge is None else edge.parent

    def set_transform(self, parent: str, child: str, stamp_ns: int, transform: Transform,
                      static: bool = False, now_ns: int | None = None,
                      future_tolerance_ns: int = 0) -> None:
        """Add what a ``TransformStamped`` says: ``child``'s place in ``parent`` at
        ``stamp_ns``. ``TransformRejected`` (tree unchanged) when it cannot be taken."""
        parent, child = _name(parent), _name(child)
        self._check_frames(parent, child)
        edge = self._edges.get(child)
        if edge is not None and edge.parent != parent:
            raise TransformRejected(
                "second_parent", f"frame {child!r} already has the parent {edge.parent!r}: "
                f"a transform from {parent!r} to it was dropped")
        if edge is None:
            self._check_no_loop(parent, child)
        if static:
            self._set_static(edge, parent, child, transform)
            return
        if edge is not None and edge.static is not None:
            raise TransformRejected(
                "static_and_dynamic", f"{parent} -> {child} is static (/tf_static): a "
                "dynamic transform of it was dropped")
        if now_ns is not None and stamp_ns > now_ns + future_tolerance_ns:
            raise TransformRejected(
                "future", f"{parent} -> {child} stamped {(stamp_ns - now_ns) * 1e-9:.3f} s "
                "in the future: dropped")
        self._set_dynamic(edge, parent, child, stamp_ns, transform)

    def _check_frames(self, parent: str, child: str) -> None:
        if not parent or not child:
            raise TransformRejected("empty_frame", "a transform with an empty frame id")
        if parent == child:
            raise TransformRejected("self_parent", f"a transform from {child!r} to itself")

    def _check_no_loop(self, parent: str, child: str) -> None:
        frame: str | None = parent
        while frame is not None:
            if frame == child:
                raise TransformRejected(
                    "loop", f"{parent} -> {child} would close a loop: {child!r} is already "
                    f"an ancestor of {parent!r}; dropped")
            edge = self._edges.get(frame)
            frame = None if edge is None else edge.parent

    def _set_static(self, edge: _Edge | None, parent: str, child: str,
                    transform: Transform) -> None:
        if edge is None:
            self._edges[child] = _Edge(parent, static=transform)
        elif edge.static is None:
            raise TransformRejected(
                "static_and_dynamic", f"{parent} -> {child} is dynamic (/tf): a static "
                "transform of it was dropped")
        elif not _same(edge.static, transform):
            raise TransformRejected(
                "static_changed", f"static transform {parent} -> {child} changed: the first "
                "one is kept (restart the node to take a new mount)")

    def _set_dynamic(self, edge: _Edge | None, parent: str, child: str, stamp_ns: int,
                     transform: Transform) -> None:
        if edge is None:
            edge = self._edges[child] = _Edge(parent)
        if edge.stamps and stamp_ns < edge.stamps[-1] - self._cache_ns:
            raise TransformRejected(
                "too_old", f"{parent} -> {child} at {stamp_ns * 1e-9:.3f} s is older than the "
                f"{self._cache_ns * 1e-9:g} s the buffer keeps: dropped")
        if stamp_ns in edge.samples:
            raise TransformRejected(
                "repeated_stamp", f"{parent} -> {child} at {stamp_ns * 1e-9:.3f} s again: "
                "the first is kept")
        insort(edge.stamps, stamp_ns)
        edge.samples[stamp_ns] = transform
        oldest_kept = edge.stamps[-1] - self._cache_ns
        while edge.stamps[0] < oldest_kept:
            del edge.samples[edge.stamps.pop(0)]

    def clear(self) -> None:
        """Forget every dynamic transform (time jumped back); static ones stay, as their
        publishers do not send them again."""
        self._edges = {child: edge for child, edge in self._edges.items()
                       if edge.static is not None}

    def lookup(self, target: str, source: str, time_ns: int = 0) -> Transform:
        """``source``'s place in ``target`` at ``time_ns`` (0: the latest time the whole
        way holds): maps a point given in ``source`` to ``target``."""
        target, source = _name(target), _name(source)
        up_source, up_target = self._path(source), self._path(target)
        common = _common(up_source, up_target, source, target)
        if time_ns == 0:
            newest = [t for t in (self._latest(up_source, common),
                                  self._latest(up_target, common)) if t]
            time_ns = min(newest) if newest else 0
        root_source = self._chain(up_source, common, time_ns)
        root_target = self._chain(up_target, common, time_ns)
        return root_target.inverse() * root_source

    def can_transform(self, target: str, source: str, time_ns: int = 0) -> bool:
        try:
            self.lookup(target, source, time_ns)
        except LookupFailed:
            return False
        return True

    def _path(self, frame: str) -> list[str]:
        """``frame`` and its ancestors, up to its tree's root."""
        if frame not in self._edges and frame not in {e.parent for e in self._edges.values()}:
            known = ", ".join(self.frames()) or "none"
            raise UnknownFrame(f"frame {frame!r} does not exist (known frames: {known})")
        path = [frame]
        while path[-1] in self._edges:
            path.append(self._edges[path[-1]].parent)
        return path

    def _chain(self, path: list[str], common: str, time_ns: int) -> Transform:
        """The first frame of ``path`` in ``common``."""
        result = Transform()
        for child in path[:path.index(common)]:
            result = self._edges[child].at(child, time_ns) * result
        return result

    def _latest(self, path: list[str], common: str) -> int:
        """The latest time every dynamic edge from the start of ``path`` to ``common``
        holds (0 when all are static)."""
        newest = [self._edges[child].stamps[-1] for child in path[:path.index(common)]
                  if self._edges[child].static is None and self._edges[child].stamps]
        return min(newest) if newest else 0


def _common(up_source: list[str], up_target: list[str], source: str, target: str) -> str:
    ancestors = set(up_target)
    for frame in up_source:
        if frame in ancestors:
            return frame
    raise NotConnected(f"frames {source!r} and {target!r} are not connected: {source!r} is "
                       f"under {up_source[-1]!r}, {target!r} under {up_target[-1]!r}")


def _name(frame: str) -> str:
    """tf2 ignores a leading slash in a frame id."""
    return frame[1:] if frame.startswith("/") else frame


def _same(a: Transform, b: Transform, tolerance: float = 1e-9) -> bool:
    return all(abs(x - y) <= tolerance for x, y in zip(a.translation, b.translation)) and \
        abs(abs(sum(x * y for x, y in zip(a.rotation, b.rotation))) - 1.0) <= tolerance
