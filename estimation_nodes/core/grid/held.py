"""The belief a localizer holds: its windows' parts, every state outside them zero.

A tracked robot's belief has probability on a few square metres of a building
(grid/window.py), so that is all it keeps in memory: one (headings, rows, columns)
array per window, not the building's (ACES: 178 MB dense, a few MB held). The
dense filter's belief (belief_floor 0) is the one window of the whole grid.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from estimation_nodes.core.grid.window import Box, States, support_boxes, window_of
from estimation_nodes.core.validation import FloatArray


@dataclass
class HeldBelief:
    """``parts[n]``: the belief within ``boxes[n]`` (disjoint boxes). A part is read, never
    written: a start's uniform one is a view repeating one heading layer."""

    shape: tuple[int, int, int]
    boxes: list[Box]
    parts: list[FloatArray]

    @classmethod
    def whole(cls, belief: FloatArray) -> HeldBelief:
        """A belief over the whole grid, held as it is (not copied)."""
        _, rows, cols = belief.shape
        return cls(belief.shape, [(0, rows, 0, cols)], [belief])

    @classmethod
    def windowed(cls, belief: FloatArray) -> HeldBelief:
        """A belief over the whole grid, held as copies of the windows of its support."""
        _, rows, cols = belief.shape
        return cls.within(belief.shape, (0, rows, 0, cols), belief)

    @classmethod
    def within(cls, shape: tuple[int, int, int], box: Box, part: FloatArray) -> HeldBelief:
        """``part`` (the belief within ``box``, zero outside it), held as copies of the
        windows of its support (``window.support_boxes``)."""
        local = support_boxes(np.any(part, axis=0))
        r0, _, c0, _ = box
        return cls(shape, [(r0 + a, r0 + b, c0 + c, c0 + d) for a, b, c, d in local],
                   [window_of(part, within) for within in local])

    def windows(self) -> Iterator[tuple[Box, FloatArray]]:
        return zip(self.boxes, self.parts)

    def within_box(self, box: Box) -> FloatArray:
        """The belief within ``box``, C-contiguous (as the compiled kernels take it): the
        part held where ``box`` is a window (the steps only read their input) and the part
        is one, else a new array."""
        if box in self.boxes:
            return np.ascontiguousarray(self.parts[self.boxes.index(box)])
        return self.gather(box)

    def gather(self, box: Box) -> FloatArray:
        """The belief within ``box``, a new array."""
        r0, r1, c0, c1 = box
        out = np.zeros((self.shape[0], r1 - r0, c1 - c0))
        for (a, b, c, d), part in self.windows():
            top, bottom, left, right = max(a, r0), min(b, r1), max(c, c0), min(d, c1)
            if top < bottom and left < right:
                out[:, top - r0:bottom - r0, left - c0:right - c0] = \
                    part[:, top - a:bottom - a, left - c:right - c]
        return out

    def regrouped(self, boxes: list[Box], states: States) -> HeldBelief:
        """This belief and the single ``states`` (headings, rows, columns, probabilities;
        outside the windows) held in the windows ``boxes``, which hold every state of
        either with probability."""
        ks, rs, cs, values = states
        parts = []
        for box in boxes:
            r0, r1, c0, c1 = box
            inside = (rs >= r0) & (rs < r1) & (cs >= c0) & (cs < c1)
            if inside.any():
                part = self.gather(box)
                part[ks[inside], rs[inside] - r0, cs[inside] - c0] = values[inside]
            else:   # a window unchanged is kept as it is: a global start's are the building's
                part = self.within_box(box)
            parts.append(part)
        return HeldBelief(self.shape, list(boxes), parts)

    def dense(self) -> FloatArray:
        """The belief over the whole grid: the held array where it is one window of the
        whole grid that may be written (the dense filter's), else a new array (the
        building's size: for tests and tools)."""
        whole = self.parts[0] if len(self.parts) == 1 else None
        if whole is not None and whole.shape == self.shape and whole.flags.writeable:
            return whole
        return self.gather((0, self.shape[1], 0, self.shape[2]))

    @property
    def nbytes(self) -> int:
        """The memory the parts hold (a repeated layer's once)."""
        return sum(part[0].nbytes if part.strides[0] == 0 else part.nbytes
                   for part in self.parts)

    @property
    def states(self) -> int:
        """The states the windows hold, all headings."""
        return sum((r1 - r0) * (c1 - c0) for r0, r1, c0, c1 in self.boxes) * self.shape[0]

