"""What a Foxglove live view and its clients cost a run of the demo.

    python bench/tools/foxglove_bench.py [--runs 3] [--cells 100000]

Each run is ``estimation_demo --quiet --record run.mcap`` in one of four
settings, interleaved run by run so a noisy machine slows each alike: no live
view; ``--foxglove`` with no client; one client (the tests' protocol client,
tests/foxglove_client.py, in a process of its own) subscribed to every topic
and reading; one subscribed to every topic that never reads (a small fixed
receive buffer, so it backs up at once). The recording is the monitor's own
view of the run: for every message the time its publisher sent it (publish
time, the DDS source timestamp) and the time the monitor took it (log time).
From it:

- graph: tile_observation published -> belief published, the estimator's
  correction as the graph sees it; the live view lives in the demo's process
  and should not move it;
- monitor: belief published -> taken by the monitor, the callback that feeds
  the sinks (it falls behind if writing to the live view blocks or is slow);
- run: the demo's wall time, spawn to exit (a stuck client that held up the
  monitor or the exit would show here).

Two scenarios: ``localization`` (20 cells, 40 steps at 4 Hz; its whole run is
a few hundred kB, which socket buffers absorb even for a client that never
reads) and a world of ``--cells`` cells from a world file (0.8 MB beliefs at
100,000 cells, 40 steps), where the never-reading client does back up and the
server drops for it. Last, ``LiveView.write`` in this process, per call.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import re
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[2]))  # the repository: bench, tests
from bench.common import compare, confine_ros, format_seconds, table  # noqa: E402

from estimation_nodes.params import topics  # noqa: E402
from tests.foxglove_client import FoxgloveClient  # noqa: E402
from tests.support import large_world_params  # noqa: E402

SETTINGS = ("no live view", "live view, 0 clients", "1 reading client", "1 never-reading client")
ARRAY = "std_msgs/msg/Float64MultiArray"
SERVED = sorted(t if t.startswith("/") else f"/{t}" for t in topics.LIVE_TOPIC_TYPES)
BELIEF = f"/{topics.BELIEF}"


class Client(threading.Thread):
    """A Foxglove client in a thread: subscribed to every topic, reading or never reading."""

    def __init__(self, url: str, reads: bool) -> None:
        super().__init__(daemon=True)
        self.url, self.reads = url, reads
        self.beliefs = 0
        self.subscribed = threading.Event()
        self._done = threading.Event()

    def run(self) -> None:
        asyncio.run(self._session())

    async def _session(self) -> None:
        options = {} if self.reads else {"sock": unread_socket(self.url), "max_queue": 1}
        client = await FoxgloveClient.connect(self.url, **options)
        await client.subscribe(SERVED)
        self.subscribed.set()
        while not self._done.is_set():
            if self.reads:
                self._count(await client.receive({BELIEF: 10**9}, 0.2))
            else:
                await asyncio.sleep(0.2)
        self._count(await client.receive({BELIEF: 10**9}, 1.0))

    def _count(self, received: list) -> None:
        self.beliefs += sum(r.topic == BELIEF for r in received)

    def finish(self) -> int:
        """The number of beliefs this client got."""
        self._done.set()
        self.join(timeout=30)
        return self.beliefs


def client_process(url: str, reads: bool) -> None:
    """The child: a Client until stdin says stop, then the count of beliefs it got."""
    client = Client(url, reads)
    client.start()
    client.subscribed.wait(30)
    print("subscribed", flush=True)
    sys.stdin.readline()
    print(client.finish(), flush=True)


def start_client(url: str, reads: bool) -> subprocess.Popen:
    """A client in a process of its own, so it takes no time from the one it watches."""
    child = subprocess.Popen([sys.executable, __file__, "--client", url,
                              "reads" if reads else "never-reads"],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    if child.stdout.readline().strip() != "subscribed":
        raise RuntimeError("the client did not subscribe")
    return child


def finish_client(child: subprocess.Popen) -> int:
    return int(child.communicate("stop\n", timeout=60)[0].strip())


def unread_socket(url: str) -> socket.socket:
    """A fixed SO_RCVBUF turns off Linux's growing of it (to 32 MB here)."""
    host, port = re.fullmatch(r"ws://(.+):(\d+)", url).groups()
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 65536)
    sock.connect((host, int(port)))
    return sock


def one_run(source: list[str], setting: str, mcap: Path, env: dict) -> dict:
    command = [sys.executable, "-m", "estimation_nodes.tools.demo.cli", *source, "--quiet",
               "--record", str(mcap)]
    if setting != "no live view":
        command += ["--foxglove", "127.0.0.1:0"]
    started = time.perf_counter()
    demo = subprocess.Popen(command, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    client = None
    if setting in ("1 reading client", "1 never-reading client"):
        url = next(re.search(r"ws://\S+", line).group() for line in demo.stdout
                   if "Foxglove live view on" in line)
        client = start_client(url, reads=setting == "1 reading client")
    output = demo.communicate(timeout=600)[0]
    seconds = time.perf_counter() - started
    if demo.returncode != 0:
        raise RuntimeError(f"{setting}: the demo failed:\n{output}")
    return dict(run=seconds, received=finish_client(client) if client else 0,
                **latencies(mcap))


def latencies(mcap: Path) -> dict:
    from mcap.reader import make_reader

    times: dict[str, list[tuple[int, int]]] = {"/tile_observation": [], "/belief": []}
    with mcap.open("rb") as stream:
        for _schema, channel, message in make_reader(stream).iter_messages():
            if channel.topic in times:
                times[channel.topic].append((message.publish_time, message.log_time))
    observations = sorted(times["/tile_observation"])
    beliefs = sorted(times["/belief"])
    if len(observations) != len(beliefs):
        raise RuntimeError(f"{len(observations)} observations, {len(beliefs)} beliefs")
    graph = [(b[0] - o[0]) / 1e9 for o, b in zip(observations, beliefs)]
    monitor = [(b[1] - b[0]) / 1e9 for b in beliefs]
    return dict(graph=graph, monitor=monitor, steps=len(beliefs))


def scenario_table(title: str, source: list[str], runs: int, env: dict, tmp: Path) -> None:
    results: dict[str, list[dict]] = {s: [] for s in SETTINGS}
    for _ in range(runs):
        for setting in SETTINGS:
            results[setting].append(one_run(source, setting, tmp / "run.mcap", env))
    steps = results[SETTINGS[0]][0]["steps"]
    print(f"\n{title}: {steps} steps, {runs} runs per setting, medians (p10..p90) over all "
          f"steps of all runs")

    def spread(key: str, setting: str) -> str:
        values = np.concatenate([r[key] for r in results[setting]])
        low, high = np.percentile(values, [10, 90])
        return (f"{format_seconds(float(np.median(values)))} "
                f"({format_seconds(low)}..{format_seconds(high)})")

    def run_time(setting: str) -> str:
        values = [r["run"] for r in results[setting]]
        return f"{np.median(values):.2f} s ({min(values):.2f}..{max(values):.2f})"

    def received(setting: str) -> str:
        counts = [r["received"] for r in results[setting]]
        return "-" if setting in SETTINGS[:2] else "/".join(str(c) for c in counts)

    print(table(["figure", *SETTINGS], [
        ["graph: tile_observation -> belief", *(spread("graph", s) for s in SETTINGS)],
        ["monitor: belief published -> taken", *(spread("monitor", s) for s in SETTINGS)],
        ["run, spawn to exit", *(run_time(s) for s in SETTINGS)],
        [f"beliefs the client got of {steps}, per run", *(received(s) for s in SETTINGS)],
    ]))


def time_write(payload: bytes, clients: str) -> str:
    """LiveView.write of ``payload`` per call, with ``clients`` connected."""
    from estimation_nodes.tools.live_view.server import LiveView

    view = LiveView("127.0.0.1", 0, dict.fromkeys(SERVED, ARRAY))
    client = None
    if clients != "0 clients":
        client = start_client(view.url, reads=clients == "1 reading client")
        time.sleep(0.3)   # the subscription reaches the server asynchronously
    try:
        timing = compare({"write": lambda: view.write(SERVED[0], payload, 1, 1)},
                         repeats=15, budget=0.02)["write"]
    finally:
        view.close()
        if client:
            finish_client(client)
    return f"{format_seconds(timing.median)} ({timing.spread()})"


def write_table() -> None:
    """LiveView.write per call in this process, by client and payload size."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Float64MultiArray

    clients = ("0 clients", "1 reading client", "1 never-reading client")
    sizes = {"20 doubles (localization belief)": 20, "100,000 doubles (0.8 MB)": 100_000}
    rows = []
    for label, count in sizes.items():
        payload = serialize_message(Float64MultiArray(data=[0.0] * count))
        rows.append([label, *(time_write(payload, c) for c in clients)])
    print("\nLiveView.write per call (the monitor's added callback time), median (p10..p90)")
    print(table(["payload", *clients], rows))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--cells", type=int, default=100_000)
    parser.add_argument("--client", nargs=2, metavar=("URL", "MODE"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.client:
        client_process(args.client[0], reads=args.client[1] == "reads")
        return
    env = confine_ros(82)
    env["PYTHONUNBUFFERED"] = "1"
    print(f"estimation_demo with and without a Foxglove live view (ROS_DOMAIN_ID "
          f"{env['ROS_DOMAIN_ID']}, {os.cpu_count()} cores)")
    with tempfile.TemporaryDirectory() as directory:
        tmp = Path(directory)
        scenario_table("localization (20 cells)", ["--scenario", "localization"],
                       args.runs, env, tmp)
        scenario_table(f"large world ({args.cells:,} cells)",
                       ["--params-file", str(large_world_params(tmp, args.cells, 40))],
                       args.runs, env, tmp)
    write_table()


if __name__ == "__main__":
    main()
