"""Shared fixtures: an isolated ROS domain per test, a fresh rclpy Context, a collector node.

Every ROS participant a test makes, in this process or a child, uses
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a ROS_DOMAIN_ID that
domain_coordinator reserves for that test alone.
"""

from __future__ import annotations

import os
import subprocess
import warnings
from collections import defaultdict
from pathlib import Path

import pytest

from estimation_nodes.tools.demo.graph_runtime import spin_until

__all__ = ["spin_until"]

REPO = Path(__file__).resolve().parent.parent
SCENARIOS = REPO / "msgs_config"


#: Tests take domains 1 to TEST_DOMAINS.
TEST_DOMAINS = 80


class _NextDomain:
    """domain_coordinator's selector, but moving on through 1..80 over the session (81 to
    98 are the benchmarks', bench/common.py; 99 the demo's, Makefile).

    Its default selector starts from 1 on every call, so consecutive tests all
    got domain 1: a process or a sample that outlived its test could then reach
    the next one. Each test now gets the next free domain instead.
    """

    def __init__(self) -> None:
        self._next = os.getpid() % TEST_DOMAINS

    def __call__(self) -> int:
        self._next += 1
        return (self._next - 1) % TEST_DOMAINS + 1


_NEXT_DOMAIN = _NextDomain()


@pytest.fixture
def domain_id():
    from domain_coordinator import domain_id as reserve

    with reserve(_NEXT_DOMAIN) as reserved:
        yield reserved


@pytest.fixture
def ros_env(domain_id, monkeypatch, request):
    """Environment for child processes, and the same settings for this process. A process
    of the test's domain still running after the test (its other fixtures have ended
    theirs) is ended by its pid and named in a warning: it could otherwise answer a later
    test that gets the same domain with a latched sample of this one."""
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain_id))
    monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
    env = dict(os.environ)
    env["PYTHONUNBUFFERED"] = "1"
    yield env
    left = end_processes_of_domain(domain_id)
    if left:
        warnings.warn(LeftBehind(f"{request.node.nodeid} left processes of its ROS domain "
                                 f"{domain_id} running (ended here): {left}"), stacklevel=2)


class LeftBehind(UserWarning):
    """A test's child process that outlived the test."""


#: How long a process of the domain may take to end after its test (a child still
#: shutting down after its parent was stopped) before it is killed.
LEFT_BEHIND_GRACE_S = 10.0


def processes_of_domain(domain_id: int) -> dict[int, str]:
    """This user's processes (other than this one) whose environment has the domain: pid
    -> command line."""
    wanted = f"ROS_DOMAIN_ID={domain_id}".encode()
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            if wanted not in (entry / "environ").read_bytes().split(b"\0"):
                continue
            command = (entry / "cmdline").read_bytes().replace(b"\0", b" ")
        except OSError:          # gone, or not ours
            continue
        found[int(entry.name)] = command.decode(errors="replace").strip()
    return found


def end_processes_of_domain(domain_id: int) -> dict[int, str]:
    """End, by pid, the processes of the domain still running after a grace: those found."""
    import signal
    import time

    found = processes_of_domain(domain_id)
    deadline = time.monotonic() + LEFT_BEHIND_GRACE_S
    while found and time.monotonic() < deadline:
        time.sleep(0.2)
        found = {pid: command for pid, command in processes_of_domain(domain_id).items()
                 if pid in found}
    for pid in found:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return found


@pytest.fixture
def context(ros_env, domain_id):
    import rclpy

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    try:
        yield ctx
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.fixture
def executor(context):
    from rclpy.executors import SingleThreadedExecutor

    ex = SingleThreadedExecutor(context=context)
    try:
        yield ex
    finally:
        ex.shutdown()


class Collector:
    """A test node that records every message on the topics it is given.

    ``topics`` maps a topic to its type, or to (type, QoS); the default QoS is
    the estimator's latched output profile.
    """

    def __init__(self, context, topics: dict, name: str = "test_collector"):
        from rclpy.node import Node

        from estimation_nodes.nodes.qos import latched_qos

        self.node = Node(name, context=context)
        self.messages: dict[str, list] = defaultdict(list)
        #: The DDS source timestamp (ns) of each message, beside ``messages``.
        self.stamps: dict[str, list[int]] = defaultdict(list)
        self.subscriptions = {}
        for topic, spec in topics.items():
            msg_type, qos = spec if isinstance(spec, tuple) else (spec, latched_qos(1000))
            self.subscriptions[topic] = self.node.create_subscription(
                msg_type, topic, lambda msg, info, t=topic: self._keep(t, msg, info), qos)

    def _keep(self, topic: str, msg, info: dict) -> None:
        self.messages[topic].append(msg)
        self.stamps[topic].append(info["source_timestamp"])

    def count(self, topic: str) -> int:
        return len(self.messages[topic])

    def unmatched(self) -> list[str]:
        """Topics whose subscription has not matched a publisher yet."""
        return [topic for topic, sub in self.subscriptions.items()
                if sub.get_publisher_count() < 1]

    def all_matched(self) -> bool:
        return not self.unmatched()


@pytest.fixture
def collector_factory(context, executor):
    made = []

    def make(topics, name="test_collector"):
        collector = Collector(context, topics, name)
        executor.add_node(collector.node)
        made.append(collector)
        return collector

    yield make
    for collector in made:
        collector.node.destroy_node()


@pytest.fixture
def make_node(context, executor):
    """``make_node(name or node class, **parameters)``: a bare node of that name, or one of
    the package's nodes, spun by the test's executor and destroyed after the test."""
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    made = []

    def make(kind, **parameters):
        overrides = [Parameter(k, value=v) for k, v in parameters.items()]
        node = Node(kind, context=context, parameter_overrides=overrides) \
            if isinstance(kind, str) else kind(context=context, parameter_overrides=overrides)
        executor.add_node(node)
        made.append(node)
        return node

    yield make
    for node in made:
        node.destroy_node()


@pytest.fixture
def processes(ros_env):
    """Start children with the test's ROS environment; each is ended by its pid afterwards."""
    started: list[subprocess.Popen] = []

    def start(command, **kwargs):
        kwargs.setdefault("env", ros_env)
        process = subprocess.Popen(command, stdout=subprocess.PIPE,
                                   stderr=subprocess.STDOUT, text=True, **kwargs)
        started.append(process)
        return process

    yield start
    from estimation_nodes.tools.demo.graph_runtime import stop_process

    for process in started:
        stop_process(process, grace=10.0)
