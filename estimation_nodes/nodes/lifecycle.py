"""The localizers' lifecycle, as Nav2's nodes have it (rclpy.lifecycle underneath).

``configure`` makes the node's publishers, subscriptions, services and timers (the
subclass's ``on_configure``, keeping each in ``configured_handles`` and each lifecycle
publisher in ``configured_publishers``: not rclpy's own ``subscriptions`` and
``publishers``, which rclpy keeps itself); ``activate`` sets ``active``, and a node takes
and publishes nothing unless it is; ``deactivate`` clears it; ``cleanup`` and
``shutdown`` destroy what configure made and call ``forget`` for the node's own state.
``autostart`` (a parameter the node declares) configures and activates at start, for
running without a lifecycle manager.
"""

from __future__ import annotations

from typing import Any

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.service import Service
from rclpy.timer import Timer


class ManagedNode(LifecycleNode):
    """A lifecycle node that remembers what its configure made, to undo it."""

    def __init__(self, node_name: str, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.active = False
        self.configured_handles: list[Any] = []
        self.configured_publishers: list[Any] = []

    def start_if_asked(self) -> None:
        """Configure and activate now when the ``autostart`` parameter says so (call it at
        the end of the subclass's constructor, once its parameters are declared)."""
        if self.get_parameter("autostart").value:
            self.trigger_configure()
            self.trigger_activate()

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = True
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def _release(self) -> None:
        for handle in self.configured_handles:
            if isinstance(handle, Timer):
                self.destroy_timer(handle)
            elif isinstance(handle, Service):
                self.destroy_service(handle)
            else:
                self.destroy_subscription(handle)
        for publisher in self.configured_publishers:
            self.destroy_lifecycle_publisher(publisher)
        self.configured_handles, self.configured_publishers = [], []
        self.forget()

    def forget(self) -> None:
        """What the node drops at cleanup beyond its handles (its estimate, its buffers)."""
