"""The Foxglove live view in this process: addresses, channels, slow clients, shipped layouts.

The client is tests/foxglove_client.py (the ``websockets`` package speaking the
Foxglove WebSocket protocol), never foxglove-sdk; payloads are decoded with
the advertised schema by mcap_ros2.
"""

import asyncio
import json
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from estimation_nodes.params import topics
from estimation_nodes.tools.live_view.server import (
    BACKLOG,
    LiveView,
    LiveViewError,
    parse_address,
    websocket_url,
)
from estimation_nodes.tools.recording.mcap import schema_text
from tests.foxglove_client import FoxgloveClient
from tests.support import resident_mib

REPO = Path(__file__).resolve().parents[2]
ARRAY = "std_msgs/msg/Float64MultiArray"


@pytest.mark.parametrize("text, address", [
    ("8765", ("127.0.0.1", 8765)),
    ("0", ("127.0.0.1", 0)),
    ("0.0.0.0:9000", ("0.0.0.0", 9000)),
    ("localhost:8765", ("localhost", 8765)),
    ("[::1]:8765", ("::1", 8765)),
])
def test_addresses_that_parse(text, address):
    assert parse_address(text) == address


@pytest.mark.parametrize("text", [
    "", "abc", "host:", ":8765", "127.0.0.1:65536", "::1:8765", "8765:host", "a b:80", "-1",
    "[::1]", "127.0.0.1:8765:1",
])
def test_addresses_that_do_not(text):
    with pytest.raises(LiveViewError, match="expected \\[HOST:\\]PORT"):
        parse_address(text)


def test_an_ipv6_url_has_its_brackets():
    assert websocket_url("::1", 8765) == "ws://[::1]:8765"
    assert websocket_url("127.0.0.1", 8765) == "ws://127.0.0.1:8765"


def test_a_port_in_use_is_one_clear_error():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        expected = f"cannot serve on ws://127.0.0.1:{port}: .*in use"
        with pytest.raises(LiveViewError, match=expected):
            LiveView("127.0.0.1", port, {"/belief": ARRAY})


def test_the_demo_does_not_import_foxglove_unless_asked():
    code = ("import sys, estimation_nodes.tools.demo.cli, "
            "estimation_nodes.tools.live_view.server; "
            "assert 'foxglove' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)


def belief_message(values) -> Float64MultiArray:
    msg = Float64MultiArray(data=list(values))
    msg.layout.dim = [MultiArrayDimension(label="cells", size=len(values), stride=len(values))]
    return msg


async def subscribed(view: LiveView, topic: str, **options) -> FoxgloveClient:
    """A client whose subscription the server has taken: the subscribe op is handled
    asynchronously, and what is written before that never reaches the client."""
    client = await FoxgloveClient.connect(view.url, **options)
    await client.subscribe([topic])
    probe = serialize_message(belief_message([0.0]))
    while not await client.receive({topic: 1}, 0.05):
        view.write(topic, probe, time.time_ns(), time.time_ns())
    return client


@pytest.mark.timeout(60)
def test_a_client_gets_the_cdr_bytes_with_their_ros2msg_schema():
    view = LiveView("127.0.0.1", 0, {"/robot1/belief": ARRAY, "/diagnostics":
                                     topics.LIVE_TOPIC_TYPES[topics.DIAGNOSTICS]})

    async def scenario():
        client = await subscribed(view, "/robot1/belief")
        sent = belief_message([0.25, 0.25, 0.125, 0.125, 0.25])
        view.write("/robot1/belief", serialize_message(sent), 123_456_789, 1)
        view.write("/not_served", b"ignored", 1, 1)
        (received,) = await client.receive({"/robot1/belief": 1}, 10)
        await client.close()
        return client, received

    try:
        client, received = asyncio.run(scenario())
    finally:
        view.close()
    channel = client.channels["/robot1/belief"]
    assert (channel["encoding"], channel["schemaEncoding"], channel["schemaName"]) == (
        "cdr", "ros2msg", ARRAY)
    assert channel["schema"] == schema_text(ARRAY)
    assert set(client.channels) == {"/robot1/belief", "/diagnostics"}
    assert received.timestamp_ns == 123_456_789
    decoded = client.decoder("/robot1/belief")(received.payload)
    assert list(decoded.data) == [0.25, 0.25, 0.125, 0.125, 0.25]
    assert decoded.layout.dim[0].label == "cells"


@pytest.mark.timeout(120)
def test_a_client_that_never_reads_costs_a_bounded_queue_and_never_blocks():
    """1,500 messages of 1 MB to a client that stops reading: each write returns (the
    server drops that client's oldest), the memory held is about BACKLOG messages
    (foxglove-sdk's default of 1024 would hold 1 GB), the client gets a fraction, and
    close() does not wait for it (the server's stop alone waited some 50 s)."""
    view = LiveView("127.0.0.1", 0, {"/big": ARRAY})
    payload = serialize_message(belief_message(np.zeros(125_000)))

    async def scenario():
        # max_queue=1: the client's reader stops at one unread frame, and TCP backs up.
        client = await subscribed(view, "/big", max_queue=1)
        before = resident_mib()
        await asyncio.to_thread(lambda: [view.write("/big", payload, 1, 1) for _ in range(1500)])
        grown = resident_mib() - before
        started = time.monotonic()
        view.close()
        closing = time.monotonic() - started
        got = await client.receive({"/big": 1500}, 5.0)
        return grown, closing, len(got)

    grown, closing, delivered = asyncio.run(scenario())
    assert grown < 4 * BACKLOG, f"{grown:.0f} MiB held for a client that does not read"
    assert closing < 10.0
    assert delivered < 1500 / 2


def script_topics(source: str) -> tuple[set[str], str]:
    inputs = re.search(r"export const inputs = \[(.*?)\];", source, re.S)
    output = re.search(r'export const output = "(.*?)";', source)
    assert inputs and output, source
    return set(re.findall(r'"([^"]+)"', inputs.group(1))), output.group(1)


def referenced_topics(config) -> set[str]:
    """Topics a panel config names: message paths ("/belief.data[0]") and 3D topic keys."""
    found: set[str] = set()
    if isinstance(config, dict):
        for key, value in config.items():
            if key in ("value", "xValuePath", "topicPath", "topicToRender"):
                found.add(re.match(r"/[\w/]+", value).group())
            elif key == "topics":
                found.update(value)
            found |= referenced_topics(value)
    elif isinstance(config, list):
        for item in config:
            found |= referenced_topics(item)
    return found


def panels_in(tree) -> set[str]:
    if isinstance(tree, str):
        return {tree}
    return panels_in(tree["first"]) | panels_in(tree["second"])


LIVE = {t if t.startswith("/") else f"/{t}" for t in topics.LIVE_TOPIC_TYPES}
#: What the grid localizer and its simulated robot will publish (issue 13): the layout
#: ships before the nodes.
GRID = {"/map", "/belief_map", "/pose", "/true_pose", "/localization_quality", "/diagnostics"}
#: What ekf_localizer and landmark_robot publish that a layout can show.
LANDMARKS = {"/pose", "/true_pose", "/odom", "/landmark_observations", "/diagnostics"}
LAYOUTS = {"tile_world.json": LIVE, "tracking_2d.json": LIVE, "grid_localization.json": GRID,
           "landmarks.json": LANDMARKS}
PANEL_TYPES = {"Plot", "3D", "StateTransitions", "DiagnosticSummary", "DiagnosticStatusPanel"}


def test_every_shipped_layout_is_listed_here():
    assert {p.name for p in (REPO / "foxglove").glob("*.json")} == set(LAYOUTS)


@pytest.mark.parametrize("name", sorted(LAYOUTS))
def test_a_layout_is_foxglove_json_naming_only_the_package_topics(name):
    layout = json.loads((REPO / "foxglove" / name).read_text(encoding="utf-8"))
    assert set(layout) == {"configById", "globalVariables", "userNodes", "playbackConfig",
                           "layout"}
    assert panels_in(layout["layout"]) == set(layout["configById"])
    assert {panel.split("!")[0] for panel in layout["configById"]} <= PANEL_TYPES
    allowed = set(LAYOUTS[name])
    for script in layout["userNodes"].values():
        inputs, output = script_topics(script["sourceCode"])
        assert inputs <= LAYOUTS[name], script["name"]
        assert output.startswith("/studio_script/")
        allowed.add(output)
    named = referenced_topics(layout["configById"])
    assert named <= allowed, f"{name} names {sorted(named - allowed)}"
    assert len(named) >= 3
