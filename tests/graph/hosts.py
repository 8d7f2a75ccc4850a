"""Two simulated hosts: network namespaces joined by a veth pair, made and removed by a test.

Each namespace has its own loopback and one address on a /24 that exists only
between the two (10.231.K.1 and .2). DDS discovers across it with
``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` and a multicast route on each end,
or without multicast with ``ROS_STATIC_PEERS``. Fast DDS is held to UDP:
processes in two namespaces of one machine share /dev/shm, and its
shared-memory transport would carry their messages past a cut link.

Needs root (``ip netns add``); ``available()`` says why not otherwise.
"""

from __future__ import annotations

import os
import shutil
import subprocess

MULTICAST = "224.0.0.0/4"


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=check,
                          timeout=30)


def available() -> str | None:
    """None when this process can make namespaces; otherwise the reason it cannot."""
    if shutil.which("ip") is None:
        return "needs iproute2's ip command"
    if os.geteuid() != 0:
        return "needs root to create network namespaces (ip netns add)"
    return None


class TwoHosts:
    """Hosts "a" and "b"; ``tag`` (0..249) keeps names and addresses apart per test run."""

    def __init__(self, tag: int, multicast: bool = True) -> None:
        self.tag = tag
        self.multicast = multicast
        self.names = {"a": f"estn{tag}a", "b": f"estn{tag}b"}
        self.links = {"a": f"estv{tag}a", "b": f"estv{tag}b"}
        self.addresses = {"a": f"10.231.{tag}.1", "b": f"10.231.{tag}.2"}

    def create(self) -> None:
        a, b = self.names["a"], self.names["b"]
        _ip("netns", "add", a)
        _ip("netns", "add", b)
        _ip("link", "add", self.links["a"], "type", "veth", "peer", "name", self.links["b"])
        for host in ("a", "b"):
            namespace, link = self.names[host], self.links[host]
            _ip("link", "set", link, "netns", namespace)
            _ip("-n", namespace, "addr", "add", f"{self.addresses[host]}/24", "dev", link)
            _ip("-n", namespace, "link", "set", "lo", "up")
            _ip("-n", namespace, "link", "set", link, "up")
            self._route(host)

    def _route(self, host: str) -> None:
        if self.multicast:
            _ip("-n", self.names[host], "route", "replace", MULTICAST, "dev", self.links[host])

    def remove(self) -> None:
        """Delete both namespaces (and with them the veth pair); safe to call twice."""
        for namespace in self.names.values():
            _ip("netns", "del", namespace, check=False)

    def cut(self) -> None:
        """Take the link down: nothing passes between the hosts until ``heal``."""
        _ip("-n", self.names["a"], "link", "set", self.links["a"], "down")

    def heal(self) -> None:
        _ip("-n", self.names["a"], "link", "set", self.links["a"], "up")
        # A link that went down lost its routes; the multicast one is ours to put back.
        for host in ("a", "b"):
            self._route(host)

    def command(self, host: str, command: list[str]) -> list[str]:
        """``command`` run on ``host``."""
        return ["ip", "netns", "exec", self.names[host], *command]

    def environment(self, base: dict[str, str], static_peer_of: str | None = None) -> dict:
        """ROS settings for a process on a host: discovery over the subnet, UDP only; with
        ``static_peer_of``, the other host is named as a static peer (no multicast needed)."""
        env = dict(base, ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET",
                   FASTDDS_BUILTIN_TRANSPORTS="UDPv4")
        if static_peer_of is not None:
            other = "b" if static_peer_of == "a" else "a"
            env["ROS_STATIC_PEERS"] = self.addresses[other]
        return env
