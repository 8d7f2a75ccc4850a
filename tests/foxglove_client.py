"""A Foxglove WebSocket client for the tests, written from the protocol, not from foxglove-sdk.

The protocol (github.com/foxglove/ws-protocol, docs/spec.md) over the
``websockets`` package: the server sends JSON text frames ``serverInfo`` and
``advertise`` (channels: id, topic, encoding, schemaName, schemaEncoding,
schema); the client sends ``{"op": "subscribe", "subscriptions": [{"id",
"channelId"}]}``; message data comes as binary frames: opcode 0x01, uint32
subscription id, uint64 timestamp (ns), then the payload, little-endian.
Payloads are decoded with the advertised ros2msg schema by mcap_ros2, not by
rclpy.

foxglove-sdk 0.30 refuses the subprotocol name ``foxglove.websocket.v1`` (HTTP
400) and accepts the same protocol as ``foxglove.sdk.v1``: this client offers
both, as the Foxglove app does.
"""

from __future__ import annotations

import asyncio
import json
import struct
import time
from dataclasses import dataclass, field
from typing import Any

import websockets
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01
_HEADER = struct.Struct("<BIQ")


@dataclass
class Received:
    topic: str
    timestamp_ns: int
    payload: bytes


@dataclass
class FoxgloveClient:
    """One connection: what the server advertised, what this client subscribed to."""

    ws: Any
    server_info: dict
    channels: dict[str, dict] = field(default_factory=dict)
    subscriptions: dict[int, str] = field(default_factory=dict)

    @classmethod
    async def connect(cls, url: str, timeout: float = 30.0, **options: Any) -> FoxgloveClient:
        """Connect, retrying until the server is up, and read its serverInfo."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                ws = await websockets.connect(url, subprotocols=SUBPROTOCOLS,
                                              max_size=None, **options)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.1)
        info = json.loads(await asyncio.wait_for(ws.recv(), timeout))
        assert info["op"] == "serverInfo", info
        return cls(ws, info)

    async def wait_for_channels(self, topics: list[str], timeout: float = 10.0) -> None:
        """Read advertise messages until each of ``topics`` has a channel."""
        deadline = time.monotonic() + timeout
        while not set(topics) <= set(self.channels):
            frame = await asyncio.wait_for(self.ws.recv(), deadline - time.monotonic())
            self._handle_text(frame)

    def _handle_text(self, frame: str | bytes) -> None:
        if isinstance(frame, bytes):
            return
        message = json.loads(frame)
        if message["op"] == "advertise":
            self.channels.update({channel["topic"]: channel for channel in message["channels"]})

    async def subscribe(self, topics: list[str]) -> None:
        await self.wait_for_channels(topics)
        new = {len(self.subscriptions) + i + 1: topic for i, topic in enumerate(topics)}
        self.subscriptions.update(new)
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": sub_id, "channelId": self.channels[topic]["id"]}
            for sub_id, topic in new.items()]}))

    async def receive(self, count: dict[str, int], timeout: float,
                      quiet: float = 0.0) -> list[Received]:
        """Message data until ``count[topic]`` messages of each topic came, or ``timeout``;
        then more, until none came for ``quiet`` seconds (an estimate republished after a
        late input can follow the count)."""
        received: list[Received] = []
        deadline = time.monotonic() + timeout

        def done() -> bool:
            return all(sum(r.topic == t for r in received) >= n for t, n in count.items())

        while time.monotonic() < deadline:
            wait = deadline - time.monotonic()
            if done():
                if quiet <= 0.0:
                    break
                wait = min(wait, quiet)
            try:
                frame = await asyncio.wait_for(self.ws.recv(), wait)
            except (TimeoutError, websockets.ConnectionClosed):
                break
            if isinstance(frame, bytes):
                received.append(self.parse(frame))
            else:
                self._handle_text(frame)
        return received

    def parse(self, frame: bytes) -> Received:
        opcode, sub_id, timestamp = _HEADER.unpack_from(frame)
        assert opcode == MESSAGE_DATA, opcode
        return Received(self.subscriptions[sub_id], timestamp, frame[_HEADER.size:])

    def decoder(self, topic: str):
        """A function from the topic's payloads to messages, built from its advertised schema."""
        channel = self.channels[topic]
        schema = Schema(id=channel["id"], name=channel["schemaName"],
                        encoding=channel["schemaEncoding"], data=channel["schema"].encode())
        return DecoderFactory().decoder_for(channel["encoding"], schema)

    async def close(self) -> None:
        await self.ws.close()
