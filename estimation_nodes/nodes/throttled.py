"""Warnings about rejected input, at most one per reason every few seconds."""

from __future__ import annotations

import math
import time

#: Seconds between two warnings about the same kind of rejected message.
WARN_THROTTLE_S = 5.0


class ThrottledWarnings:
    """Logs a warning for a reason unless one was logged for it within WARN_THROTTLE_S:
    a flood of bad messages is counted in full but fills no log."""

    def __init__(self, logger) -> None:
        self._logger = logger
        self._last: dict[str, float] = {}

    def warn(self, reason: str, message: str) -> None:
        now = time.monotonic()
        if now - self._last.get(reason, -math.inf) >= WARN_THROTTLE_S:
            self._last[reason] = now
            self._logger.warning(message)
