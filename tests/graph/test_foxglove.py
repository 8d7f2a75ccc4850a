"""Watching runs live in Foxglove: the demo's --foxglove and the stand-alone foxglove_view.

The client is not the project's code: the ``websockets`` package speaking the
Foxglove WebSocket protocol (tests/foxglove_client.py), decoding the CDR
payloads with the schema the server advertised, by mcap_ros2.
"""

import asyncio
import os
import re
import signal
import socket
import stat
import subprocess
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from estimation_nodes.params import topics
from tests.conftest import SCENARIOS
from tests.foxglove_client import FoxgloveClient
from tests.graph.graph_tools import SETTLE, executable, node_command
from tests.support import large_world_params

#: Example 6.14 of the book, step 3 (../shared/reference/README.md).
BOOK_FINAL_BELIEF = [0.048443, 0.063322, 0.244983, 0.528374, 0.114879]
#: Every topic the live view serves, as the nodes resolve them in the root namespace.
SERVED = {t if t.startswith("/") else f"/{t}": n for t, n in topics.LIVE_TOPIC_TYPES.items()}
CORRECTED = re.compile(r"step\s+\d+\s+corrected\s+\|[^|]*\|\s+\[([^\]]+)\]")
#: Any world size: larger ones print the top cells instead of the values.
CORRECTED_LINE = re.compile(r"step\s+\d+\s+corrected")


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def printed_beliefs(output: str) -> list[list[float]]:
    return [[float(v) for v in m.group(1).split()] for m in CORRECTED.finditer(output)]


def served_url(process, marker: str) -> str:
    """Read the process's output up to the line that names its WebSocket URL."""
    for line in process.stdout:
        if marker in line:
            return re.search(r"ws://\S+", line).group()
    raise AssertionError(f"{process.args[0]} ended without serving")


def demo_command(*args: str) -> list[str]:
    return [executable("estimation_demo"), "--settle", SETTLE, "--linger", "0.5", *args]


def test_ros2_run_finds_foxglove_view_and_the_layouts_are_installed():
    from ament_index_python.packages import get_package_prefix, get_package_share_directory

    path = Path(get_package_prefix("estimation_nodes")) / "lib" / "estimation_nodes"
    assert (path / "foxglove_view").stat().st_mode & stat.S_IXUSR
    share = Path(get_package_share_directory("estimation_nodes")) / "foxglove"
    assert {p.name for p in share.glob("*.json")} == {
        "tile_world.json", "tracking_2d.json", "grid_localization.json", "landmarks.json"}


@pytest.mark.timeout(240)
def test_an_independent_client_decodes_the_beliefs_the_demo_printed(ros_env, processes,
                                                                    tmp_path):
    port = free_port()
    recording = tmp_path / "run.mcap"
    demo = processes(demo_command("--scenario", "example_6_14", "--foxglove",
                                  f"127.0.0.1:{port}", "--record", str(recording)))

    async def watch():
        client = await FoxgloveClient.connect(f"ws://127.0.0.1:{port}", timeout=60)
        await client.subscribe(["/belief"])
        received = await client.receive({"/belief": 3}, timeout=120, quiet=2.0)
        await client.close()
        return client, received

    client, received = asyncio.run(watch())
    output = demo.communicate(timeout=120)[0]
    assert demo.returncode == 0, output
    decode = client.decoder("/belief")
    beliefs = [list(decode(r.payload).data) for r in received if r.topic == "/belief"]
    printed = printed_beliefs(output)
    # Three steps; a belief republished after a late input would be a fourth, in both.
    assert len(beliefs) == len(printed) >= 3, output
    np.testing.assert_allclose(beliefs, printed, atol=1e-6)
    np.testing.assert_allclose(beliefs[-1], BOOK_FINAL_BELIEF, atol=1e-6)
    assert {t: c["schemaName"] for t, c in client.channels.items()} == SERVED
    assert {(c["encoding"], c["schemaEncoding"]) for c in client.channels.values()} == {
        ("cdr", "ros2msg")}
    # One monitor fed both sinks; the recording keeps its own topics (no /diagnostics).
    with recording.open("rb") as stream:
        recorded = {c.topic for c in make_reader(stream).get_summary().channels.values()}
    assert recorded == set(SERVED) - {topics.DIAGNOSTICS}


def start_graph_in(processes, namespace: str) -> subprocess.Popen:
    """The three nodes of Example 6.14 under ``namespace``; returns the commander, which
    waits for three subscribers on motion_cmd: sensor, estimator and the view."""
    scenario = SCENARIOS / "example_6_14.yaml"
    remap = ("-r", f"__ns:={namespace}")
    for name in ("estimator", "tile_sensor"):
        processes(node_command(name, scenario, *remap))
    return processes(node_command(
        "motion_commander", scenario, *remap, "-p", f"start_delay:={SETTLE}",
        "-p", "exit_when_done:=true", "-p", "required_subscribers:=3"))


@pytest.mark.timeout(240)
def test_foxglove_view_serves_a_graph_it_did_not_start_and_stops_on_ctrl_c(ros_env, processes):
    view = processes([executable("foxglove_view"), "--ros-args", "-r", "__ns:=/robot1",
                      "-r", "true_position:=truth", "-p", "port:=0"], start_new_session=True)
    url = served_url(view, "serving")

    async def watch():
        client = await FoxgloveClient.connect(url)
        await client.subscribe(["/robot1/belief"])
        commander = start_graph_in(processes, "/robot1")
        received = await client.receive({"/robot1/belief": 3}, timeout=120, quiet=2.0)
        await client.close()
        return client, received, commander

    client, received, commander = asyncio.run(watch())
    assert commander.wait(timeout=60) == 0
    decode = client.decoder("/robot1/belief")
    beliefs = [list(decode(r.payload).data) for r in received]
    assert len(beliefs) >= 3   # more when one was republished after a late input
    np.testing.assert_allclose(beliefs[-1], BOOK_FINAL_BELIEF, atol=1e-6)
    # Names as the nodes resolve them: the namespace and the remap apply, /diagnostics
    # is absolute.
    assert {"/robot1/belief", "/robot1/truth", "/diagnostics"} <= set(client.channels)
    assert not {"/belief", "/robot1/true_position"} & set(client.channels)

    os.killpg(view.pid, signal.SIGINT)   # a terminal's Ctrl-C reaches the whole group
    output = view.communicate(timeout=30)[0]
    assert view.returncode == 0, output
    assert "Traceback" not in output


def unread_socket(url: str) -> socket.socket:
    """A connection whose receive buffer stays small: a fixed SO_RCVBUF turns off Linux's
    growing of it (up to 32 MB here), so a client that does not read backs up at once."""
    host, port = re.fullmatch(r"ws://(.+):(\d+)", url).groups()
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 65536)
    sock.connect((host, int(port)))
    return sock


@pytest.mark.timeout(300)
def test_a_client_that_never_reads_does_not_hold_up_the_run(ros_env, processes, tmp_path):
    """A 100,000-cell world: each step sends two 0.8 MB beliefs. A client subscribed to
    everything stops reading at once; the run still ends on its own, every estimate
    printed, and that client has got only part of the stream: the server dropped for it."""
    steps = 30
    # Every belief must reach the demo's monitor, and a reliable writer keeping only the
    # latest (history_depth 1) replaces one that a busy monitor has not read yet: the
    # estimator keeps them all (2 x 40 x 0.8 MB).
    params = large_world_params(tmp_path, 100_000, steps, history_depth=steps + 10)
    demo = processes(demo_command("--params-file", str(params),
                                  "--foxglove", "0", "--timeout", "150"))
    url = served_url(demo, "Foxglove live view on")

    async def connect_and_never_read():
        # max_queue=1: the client's reader stops at one unread frame.
        client = await FoxgloveClient.connect(url, sock=unread_socket(url), max_queue=1)
        await client.subscribe(sorted(SERVED))
        output = await asyncio.to_thread(lambda: demo.communicate(timeout=200)[0])
        received = await client.receive({"/belief": steps}, timeout=5)
        return output, received

    output, received = asyncio.run(connect_and_never_read())
    assert demo.returncode == 0, output
    # One printed line per belief the monitor got: every step's, and one more for each
    # the estimator published again after a late input.
    assert len(CORRECTED_LINE.findall(output)) >= steps, output
    assert sum(r.topic == "/belief" for r in received) < steps


@pytest.mark.timeout(120)
@pytest.mark.parametrize("address", ["abc", "127.0.0.1:70000", "host:", "taken"])
def test_a_bad_or_taken_address_is_one_line_and_exit_2(ros_env, address):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        if address == "taken":
            address = f"127.0.0.1:{taken.getsockname()[1]}"
        result = subprocess.run([executable("estimation_demo"), "--scenario", "example_6_14",
                                 "--foxglove", address], env=ros_env, capture_output=True,
                                text=True, timeout=60)
    assert result.returncode == 2, result.stdout + result.stderr
    assert result.stderr.startswith("estimation_demo: --foxglove: ")
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr


@pytest.mark.timeout(120)
def test_foxglove_view_on_a_taken_port_is_one_line_and_exit_2(ros_env):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        result = subprocess.run(
            [executable("foxglove_view"), "--ros-args", "-p",
             f"port:={taken.getsockname()[1]}"], env=ros_env, capture_output=True, text=True,
            timeout=60)
    assert result.returncode == 2, result.stdout + result.stderr
    fatal = [line for line in result.stderr.splitlines() if "[FATAL]" in line]
    assert len(fatal) == 1 and "in use" in fatal[0], result.stderr
    assert "Traceback" not in result.stderr
