"""A Foxglove WebSocket protocol client for tests, on the ``websockets`` package.

Speaks the published protocol (https://github.com/foxglove/ws-protocol, subprotocols
``foxglove.sdk.v1`` and ``foxglove.websocket.v1``): the server's ``serverInfo`` and
``advertise`` text messages, the client's ``subscribe``, and binary ``messageData`` frames
(opcode 1, subscription id uint32 LE, log time uint64 LE ns, payload).
"""

from __future__ import annotations

import contextlib
import json
import struct
import time
from dataclasses import dataclass

from websockets.sync.client import connect

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01


@dataclass(frozen=True)
class Message:
    """One message received: its channel's topic, log time (ns) and payload."""

    topic: str
    log_time_ns: int
    data: bytes


class FoxgloveClient:
    """Connected on construction; use as a context manager.

    Args:
        url: ``ws://host:port`` (a query such as ``?token=...`` is sent as is).
        headers: extra HTTP headers of the opening request.
        max_queue: frames the connection buffers before it stops reading the socket (a client
            that never calls ``receive`` then applies back-pressure, as a stalled viewer does).
    """

    def __init__(self, url: str, headers: dict[str, str] | None = None,
                 max_queue: int = 1024) -> None:
        self._stack = contextlib.ExitStack()
        self._ws = self._stack.enter_context(connect(
            url, subprotocols=SUBPROTOCOLS, additional_headers=headers, open_timeout=5,
            max_queue=max_queue, max_size=None, close_timeout=0.5))
        self.subprotocol = self._ws.subprotocol
        self.server_info: dict | None = None
        self.channels: dict[str, dict] = {}  # topic -> the advertised channel
        self._subscriptions: dict[int, str] = {}  # subscription id -> topic
        self.messages: list[Message] = []

    def close(self) -> None:
        self._stack.close()

    def __enter__(self) -> FoxgloveClient:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def _handle(self, frame: str | bytes) -> None:
        if isinstance(frame, str):
            body = json.loads(frame)
            if body["op"] == "serverInfo":
                self.server_info = body
            elif body["op"] == "advertise":
                for channel in body["channels"]:
                    self.channels[channel["topic"]] = channel
            elif body["op"] == "unadvertise":
                ids = set(body["channelIds"])
                self.channels = {t: c for t, c in self.channels.items() if c["id"] not in ids}
        elif frame[0] == MESSAGE_DATA:
            subscription, log_time = struct.unpack_from("<IQ", frame, 1)
            self.messages.append(Message(self._subscriptions[subscription], log_time,
                                         bytes(frame[13:])))

    def wait_channels(self, topics, timeout_s: float = 5.0) -> dict[str, dict]:
        """Read until every topic of ``topics`` is advertised; their channels.

        Raises:
            TimeoutError: not all advertised within ``timeout_s``.
        """
        deadline = time.monotonic() + timeout_s
        while not set(topics) <= set(self.channels):
            self._handle(self._ws.recv(timeout=max(0.0, deadline - time.monotonic())))
        return {t: self.channels[t] for t in topics}

    def subscribe(self, topics) -> None:
        """Subscribe to the advertised channels of ``topics``."""
        subscriptions = []
        for topic in topics:
            sub_id = len(self._subscriptions) + 1
            self._subscriptions[sub_id] = topic
            subscriptions.append({"id": sub_id, "channelId": self.channels[topic]["id"]})
        self._ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))

    def subscribe_on(self, live, topics, timeout_s: float = 5.0) -> None:
        """Subscribe to ``topics`` and wait until ``live`` (a LiveServer) has them subscribed.

        Raises:
            TimeoutError: the server did not see the subscription within ``timeout_s``.
        """
        self.subscribe(topics)
        deadline = time.monotonic() + timeout_s
        while not set(topics) <= live.subscribed():
            if time.monotonic() > deadline:
                raise TimeoutError(f"the live view did not see the subscription to {topics}")
            time.sleep(0.01)

    def receive_until(self, done, timeout_s: float = 10.0) -> list[Message]:
        """Read until ``done(messages)`` holds; the messages received.

        Raises:
            TimeoutError: it did not hold within ``timeout_s``.
        """
        deadline = time.monotonic() + timeout_s
        while not done(self.messages):
            self._handle(self._ws.recv(timeout=max(0.0, deadline - time.monotonic())))
        return self.messages
