"""Everything this package takes from rclpy's private API, in one place.

rclpy (Jazzy, 7.1.x) keeps these out of its public API, so a later rclpy may
change them; tests/node/test_rclpy_internals.py checks each one this module
uses and fails with a message naming it. What is used and why:

- ``RCLError`` (``rclpy._rclpy_pybind11``): what ``rclpy.init`` raises for a bad
  command line or parameter file; caught to print one line instead of a trace.
- ``Node._parameter_overrides``: the values given to a node (``-p``, parameter
  files, ``parameter_overrides=``), to warn of a misspelled name that no
  declaration takes; rclpy has no public accessor for them.
- ``EventHandle``, ``wait_set.add_event`` / ``is_ready("event", ...)`` and
  ``take_event``: to watch the estimator's input QoS events in one waitable
  (below). Keep this only while it measurably pays (docs/benchmarks.md, "idle
  spin"); rclpy's public ``SubscriptionEventCallbacks`` does the same work
  with one waitable per event.

Why one waitable for the QoS events: rclpy makes every QoS event handler a
Python waitable of its own, and its executor visits each waitable on every
iteration, ready or not: counting, entering, adding to the wait set,
checking. For the estimator's six input events (message lost and
incompatible QoS on three inputs) that cost a measurable share of its
throughput under load (docs/benchmarks.md). One waitable holding
all six event handles pays the executor's per-waitable cost once; the
handles themselves are the same rcl events rclpy's own handlers use.
"""

from __future__ import annotations

from typing import Any, Callable

from rclpy._rclpy_pybind11 import RCLError
from rclpy.callback_groups import CallbackGroup
from rclpy.event_handler import QoSSubscriptionEventType
from rclpy.executors import await_or_execute
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.subscription import Subscription
from rclpy.waitable import NumberOfEntities, Waitable

MESSAGE_LOST = QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST
INCOMPATIBLE_QOS = QoSSubscriptionEventType.RCL_SUBSCRIPTION_REQUESTED_INCOMPATIBLE_QOS

__all__ = [
    "INCOMPATIBLE_QOS", "MESSAGE_LOST", "RCLError", "SubscriptionEvents", "parameter_overrides",
]


def parameter_overrides(node: Any) -> list[str]:
    """The names of every parameter value given to ``node`` from outside."""
    return list(node._parameter_overrides)


class SubscriptionEvents(Waitable):
    """Calls ``callback(info)`` for each watched event that fires, as rclpy's handlers do."""

    def __init__(self, callback_group: CallbackGroup) -> None:
        super().__init__(callback_group)
        self._watched: list[tuple[Any, Callable[[Any], None]]] = []
        self._handles: list[Any] = []
        self._indices: list[int] = []
        self._ready: list[bool] = []
        self._entered = 0

    def watch(self, subscription: Subscription, event_type: Any,
              callback: Callable[[Any], None]) -> None:
        with subscription.handle:
            handle = _rclpy.EventHandle(subscription.handle, event_type)
        self._watched.append((handle, callback))
        self._handles.append(handle)
        self._ready.append(False)

    # --- the Waitable interface the executor calls ------------------------------------------

    # The executor enters and leaves every waitable on each of its iterations: plain loops
    # over the handles cost less than an ExitStack did (docs/benchmarks.md).

    def __enter__(self) -> None:
        """Hold every handle for the wait; on a failure, release the ones held."""
        self._entered = 0
        try:
            for handle in self._handles:
                handle.__enter__()
                self._entered += 1
        except BaseException:
            self.__exit__(None, None, None)
            raise

    def __exit__(self, *exc_info: Any) -> None:
        handles, self._entered = self._handles[:self._entered], 0
        for handle in reversed(handles):
            handle.__exit__(None, None, None)

    def get_num_entities(self) -> NumberOfEntities:
        return NumberOfEntities(num_events=len(self._watched))

    def add_to_wait_set(self, wait_set: Any) -> None:
        self._indices = [wait_set.add_event(handle) for handle, _ in self._watched]

    def is_ready(self, wait_set: Any) -> bool:
        ready, is_ready = self._ready, wait_set.is_ready
        for position, index in enumerate(self._indices):
            if is_ready("event", index):
                ready[position] = True
        return any(ready)

    def take_data(self) -> list[tuple[Callable[[Any], None], Any]]:
        """Take every ready event, so the wait set does not wake again for it."""
        taken = []
        for position, (handle, callback) in enumerate(self._watched):
            if self._ready[position]:
                self._ready[position] = False
                with handle:
                    info = handle.take_event()
                if info is not None:
                    taken.append((callback, info))
        return taken

    async def execute(self, taken_data: list[tuple[Callable[[Any], None], Any]]) -> None:
        for callback, info in taken_data:
            await await_or_execute(callback, info)

    def destroy(self) -> None:
        for handle, _ in self._watched:
            handle.destroy_when_not_in_use()
        self._watched.clear()
