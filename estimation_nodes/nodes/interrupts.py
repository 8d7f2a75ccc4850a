"""A Ctrl-C noted instead of raised, for code that must not be broken into half-way."""

from __future__ import annotations

import signal
from typing import Any


class HeldInterrupts:
    """While the block runs, a Ctrl-C (SIGINT) is noted instead of raised, so that what the
    block does is done whole: a child started is a child known, a stop is a stop of all, an
    object rclpy makes is made whole (one broken into half-way printed a traceback from its
    finalizer).

    ``noted`` says whether one came. At the end the handler in place before comes back;
    with ``restore=False`` the noting one stays: the end that a Ctrl-C began is let finish,
    a second Ctrl-C only noted.
    """

    def __init__(self, restore: bool = True) -> None:
        self.noted = False
        self._restore = restore
        self._previous: Any = None

    def __enter__(self) -> HeldInterrupts:
        self._previous = signal.signal(signal.SIGINT, self._note)
        return self

    def _note(self, _signum: int, _frame: Any) -> None:
        self.noted = True

    def __exit__(self, *_exc: object) -> None:
        if self._restore:
            signal.signal(signal.SIGINT, self._previous)
