"""Live-view clients for ``finepos bench service``: Foxglove WebSocket clients that subscribe to
every channel and then read everything (``reading``) or nothing at all (a stalled viewer).

A minimal client of the Foxglove WebSocket protocol on a plain socket (RFC 6455 framing; the
server's ``advertise`` gives the channels, the client's ``subscribe`` asks for them), so the
bench needs no WebSocket package.
"""

from __future__ import annotations

import base64
import json
import os
import socket
import struct
import threading

SUBPROTOCOL = "foxglove.sdk.v1"
OPEN_TIMEOUT_S = 5.0
_TEXT, _BINARY, _CLOSE = 0x1, 0x2, 0x8
SMALL_BUFFER_BYTES = 4096  # a stalled client's receive buffer: it fills after a few frames


class LiveClient:
    """One connection to the live view at 127.0.0.1:``port``, subscribed to ``topics``.

    Args:
        reading: read (and count) every message in a thread of its own; otherwise never read
            after the channels are advertised (its socket's receive buffer is made small, so
            it stalls soon).
        subscribed: subscribe at once (else ``subscribe`` does).
    """

    def __init__(self, port: int, topics: tuple[str, ...], reading: bool,
                 subscribed: bool = True) -> None:
        self.messages = 0
        self._closing = threading.Event()
        self._sock = socket.create_connection(("127.0.0.1", port), timeout=OPEN_TIMEOUT_S)
        if not reading:
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SMALL_BUFFER_BYTES)
        self._buffer = b""
        key = base64.b64encode(os.urandom(16)).decode()
        self._sock.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                            f"Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: "
                            f"{SUBPROTOCOL}\r\n\r\n").encode())
        while b"\r\n\r\n" not in self._buffer:
            self._fill()
        head, self._buffer = self._buffer.split(b"\r\n\r\n", 1)
        if b" 101 " not in head.split(b"\r\n", 1)[0]:
            raise ConnectionError(f"live view: no WebSocket upgrade: {head[:80]!r}")
        channels: dict[str, int] = {}
        while not set(topics) <= set(channels):
            opcode, payload = self._frame()
            if opcode == _TEXT:
                body = json.loads(payload)
                if body.get("op") == "advertise":
                    channels.update({c["topic"]: c["id"] for c in body["channels"]})
        self._channel_ids = [channels[t] for t in topics]
        if subscribed:
            self.subscribe()
        self._thread = None
        if reading:
            self._sock.settimeout(0.2)
            self._thread = threading.Thread(target=self._read_all, name="live-bench-client",
                                            daemon=True)
            self._thread.start()

    def subscribe(self) -> None:
        """Subscribe to every topic (subscription ids 1..n)."""
        self._send_text(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": i + 1, "channelId": c} for i, c in enumerate(self._channel_ids)]}))

    def unsubscribe(self) -> None:
        """End the subscriptions ``subscribe`` made (a stalled client can still send)."""
        self._send_text(json.dumps({"op": "unsubscribe", "subscriptionIds": list(
            range(1, len(self._channel_ids) + 1))}))

    def _fill(self) -> None:
        data = self._sock.recv(65536)
        if not data:
            raise ConnectionError("live view: the server closed the connection")
        self._buffer += data

    def _frame(self) -> tuple[int, bytes]:
        """The next frame's opcode and payload; the buffer keeps a partial frame (a read that
        times out loses nothing)."""
        while True:
            buffer = self._buffer
            if len(buffer) >= 2:
                length, start = buffer[1] & 0x7F, 2
                if length == 126 and len(buffer) >= 4:
                    (length,), start = struct.unpack(">H", buffer[2:4]), 4
                elif length == 127 and len(buffer) >= 10:
                    (length,), start = struct.unpack(">Q", buffer[2:10]), 10
                if length < 126 or start > 2:
                    if len(buffer) >= start + length:
                        self._buffer = buffer[start + length:]
                        return buffer[0] & 0x0F, buffer[start:start + length]
            self._fill()

    def _send_text(self, text: str) -> None:
        payload = text.encode()
        mask = os.urandom(4)
        n = len(payload)
        header = bytes([0x80 | _TEXT]) + (bytes([0x80 | n]) if n < 126 else
                                          bytes([0x80 | 126]) + struct.pack(">H", n))
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self._sock.sendall(header + mask + masked)

    def _read_all(self) -> None:
        while not self._closing.is_set():
            try:
                opcode, _ = self._frame()
            except TimeoutError:
                continue
            except OSError:
                return
            if opcode == _BINARY:
                self.messages += 1
            elif opcode == _CLOSE:
                return

    def close(self) -> None:
        self._closing.set()
        if self._thread is not None:
            self._thread.join(2.0)
        self._sock.close()
