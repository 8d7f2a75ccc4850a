"""What the benchmarks share: the paths they read, the ROS environment they run in,
interleaved timing and Markdown tables, the package's processes, and a run's recording.

A benchmark runs as ``python bench/<subject>/<script>.py``: it puts the repository on
sys.path and imports this module as ``bench.common`` (and another subject's script as
``bench.<subject>.<script>``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

BENCH = Path(__file__).resolve().parent
#: The repository: its maps, msgs_config and tests.
REPO = BENCH.parent
#: The data sets beside the repository (../shared/data/README.md).
SHARED_DATA = REPO.parent / "shared" / "data"
#: The bare rclpy node the latency figures are compared with.
RELAY_NODE = BENCH / "relay_node.py"


# --- the ROS environment -----------------------------------------------------------------
#
# The ROS environment every benchmark runs in: DDS on loopback, a domain of its own.
#
# The test suite takes domains 1 to 80 (tests/conftest.py), one per test; a benchmark
# run beside it must never share one, or its messages reach a test's nodes. Benchmarks
# take 81 to 98 (each its own number), the demo 99 (Makefile): all at most 101, whose
# ports stay below Linux's ephemeral range.

BENCH_DOMAINS = range(81, 99)


def confine_ros(domain_id: int) -> dict[str, str]:
    """Set (unless the caller did) LOCALHOST discovery and ``domain_id`` (one of
    BENCH_DOMAINS); return the env."""
    if domain_id not in BENCH_DOMAINS:
        raise ValueError(f"a benchmark's domain is one of 81..98, got {domain_id}")
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", str(domain_id))
    return dict(os.environ)


# --- timing and tables -------------------------------------------------------------------
#
# Interleaved timing: each figure with a reference measured in the same run.
#
# Every repeat times the candidate and its reference back to back, so a noisy
# machine slows both alike; the ratio of the medians is what the tables quote,
# with the spread (10th to 90th percentile of the per-call time) beside it.


@dataclass(frozen=True)
class Timing:
    """Per-call seconds over the repeats."""

    samples: np.ndarray

    @property
    def median(self) -> float:
        return float(np.median(self.samples))

    def spread(self) -> str:
        low, high = np.percentile(self.samples, [10, 90])
        return f"{format_seconds(low)}..{format_seconds(high)}"


def format_seconds(seconds: float) -> str:
    if seconds < 1e-3:
        return f"{seconds * 1e6:.2f} us"
    if seconds < 1.0:
        return f"{seconds * 1e3:.3f} ms"
    return f"{seconds:.3f} s"


def _calls_for(function: Callable[[], object], budget: float) -> int:
    """How many calls fill about ``budget`` seconds (at least one)."""
    start = time.perf_counter()
    function()
    once = max(time.perf_counter() - start, 1e-7)
    return max(1, int(budget / once))


def _per_call(function: Callable[[], object], calls: int) -> float:
    start = time.perf_counter()
    for _ in range(calls):
        function()
    return (time.perf_counter() - start) / calls


def compare(
    functions: dict[str, Callable[[], object]], repeats: int = 15, budget: float = 0.02
) -> dict[str, Timing]:
    """Time each function ``repeats`` times, interleaved, each repeat about ``budget`` s."""
    calls = {name: _calls_for(f, budget) for name, f in functions.items()}
    samples: dict[str, list[float]] = {name: [] for name in functions}
    for _ in range(repeats):
        for name, function in functions.items():
            samples[name].append(_per_call(function, calls[name]))
    return {name: Timing(np.array(values)) for name, values in samples.items()}


def table(header: list[str], rows: list[list[str]]) -> str:
    """A Markdown table, so the README can carry the output as it is."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


# --- the package's processes -------------------------------------------------------------


def executable(name: str) -> str:
    """The console script beside this interpreter (the venv's)."""
    return str(Path(sys.executable).parent / name)


def wait_for_line(process: subprocess.Popen, output: Path, text: str,
                  timeout: float) -> bool:
    """Whether ``process`` wrote ``text`` to ``output`` (its log) within ``timeout``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and process.poll() is None:
        if text in output.read_text():
            return True
        time.sleep(0.1)
    return False


def end_run(play: subprocess.Popen | None, localizer: subprocess.Popen, node) -> None:
    """Stop the play (if it still runs) and the node, each by its pid; rclpy shut down."""
    import rclpy

    from estimation_nodes.tools.demo.graph_runtime import stop_process

    if play is not None and play.poll() is None:
        stop_process(play)
    stop_process(localizer)
    node.destroy_node()
    rclpy.try_shutdown()


# --- a run's recording -------------------------------------------------------------------
#
# A bench's recording of a node's run, checked by estimation_replay.
#
# The bench's node subscribes raw to the inputs the node under test hears and the
# outputs it publishes, and keeps each message with its publish (source) time, as
# estimation_demo's recorder does; at the end the messages go to an MCAP file with
# the node's parameters in its metadata, and ``estimation_replay`` runs on it: the
# node's filter offline over the same inputs must publish the same outputs (EQUAL).


class RunRecorder:
    """Raw subscriptions on ``node`` to ``topics`` ({topic: (message type name, QoS)})."""

    def __init__(self, node, topics: dict[str, tuple[str, object]]) -> None:
        from estimation_nodes.tools.demo.monitor import message_class

        self.types = {topic: name for topic, (name, _qos) in topics.items()}
        #: (topic, raw message, publish time in ns), in arrival order.
        self.recorded: list[tuple[str, bytes, int]] = []
        for topic, (name, qos) in topics.items():
            node.create_subscription(message_class(name), topic, self._keep(topic), qos,
                                     raw=True)

    def _keep(self, topic: str):
        from estimation_nodes.nodes.stamps import published_ns

        def keep(data: bytes, info) -> None:
            self.recorded.append((topic, data, published_ns(info)))
        return keep

    def sent(self, topic: str, type_name: str, msg, published_ns: int) -> None:
        """A message the bench itself published at ``published_ns`` (taken just before the
        publish call; its own subscription would not hear it)."""
        from rclpy.serialization import serialize_message

        self.types[topic] = type_name
        self.recorded.append((topic, serialize_message(msg), published_ns))

    def write_and_replay(self, path: Path, metadata: dict[str, str],
                         replay_executable: str) -> list[list[str]]:
        """Write the recording to ``path``, run estimation_replay on it; table rows."""
        from estimation_nodes.tools.recording.mcap import McapRunWriter

        writer = McapRunWriter(path, self.types, metadata)
        for topic, data, published_ns in self.recorded:
            writer.write(topic, data, published_ns, published_ns)
        writer.close()
        started = time.monotonic()
        replay = subprocess.run([replay_executable, str(path)], capture_output=True, text=True)
        print(replay.stdout + replay.stderr)
        verdict = (replay.stdout.strip().splitlines() or ["(no output)"])[-1]
        return [["recording", f"{path} ({len(self.recorded)} messages)"],
                ["estimation_replay", f"{verdict} (exit {replay.returncode}, "
                 f"{time.monotonic() - started:.0f} s)"]]
