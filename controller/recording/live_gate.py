"""The token gate in front of a live view bound off loopback: only clients with the token get in.

The Foxglove SDK's WebSocket server has no authentication, so off loopback it listens on a
private loopback port and ``TokenGate`` listens on the configured address. Each connection's
opening HTTP request (the WebSocket upgrade) must carry the service's TCP control token
(``service.tcp.token_file``), as ``Authorization: Bearer <token>`` or as ``token=<token>`` in
the URL's query (``ws://cell-pc:8765/?token=...``, for clients that send no headers, such as
Foxglove). Without it the answer is 401 and the connection is closed; with it the request and
everything after it is passed through unchanged, both ways.

One thread serves every connection with a selector. A client that stops reading does not hold
up the others: at most ``MAX_BUFFERED_BYTES`` wait for it, then its upstream is no longer read
(the SDK's queue for that client fills and drops messages). A request not complete within
``REQUEST_TIMEOUT_S``, or longer than ``MAX_REQUEST_BYTES``, is cut off.
"""

from __future__ import annotations

import hmac
import logging
import selectors
import socket
import time
import urllib.parse
from collections.abc import Callable

from drivers.core.lifecycle import ThreadedServer

logger = logging.getLogger(__name__)

MAX_REQUEST_BYTES = 8192  # the upgrade request: request line and headers
REQUEST_TIMEOUT_S = 5.0  # a client that sends no complete request within this is cut off
MAX_BUFFERED_BYTES = 1 << 20  # bytes waiting for a slow reader before its source is paused
_CHUNK = 65536
_POLL_S = 0.1  # how often the thread looks at deadlines and for close()
_UNAUTHORIZED = (b"HTTP/1.1 401 Unauthorized\r\nContent-Length: 0\r\n"
                 b"WWW-Authenticate: Bearer\r\nConnection: close\r\n\r\n")


def request_token(request: bytes) -> str | None:
    """The token an HTTP request carries (its ``Authorization: Bearer`` header, else its URL's
    ``token`` query parameter); None without one."""
    try:
        text = request.decode("latin-1")
    except UnicodeDecodeError:  # latin-1 decodes every byte; kept for clarity
        return None
    lines = text.split("\r\n")
    for line in lines[1:]:
        name, _, value = line.partition(":")
        if name.strip().lower() == "authorization":
            scheme, _, credentials = value.strip().partition(" ")
            if scheme.lower() == "bearer":
                return credentials.strip()
    parts = lines[0].split(" ")
    if len(parts) == 3:
        query = urllib.parse.urlsplit(parts[1]).query
        values = urllib.parse.parse_qs(query).get("token")
        if values:
            return values[0]
    return None


class _Pipe:
    """One client connection: its request until admitted, then its upstream connection."""

    def __init__(self, client: socket.socket) -> None:
        self.client = client
        self.upstream: socket.socket | None = None
        self.request = b""
        self.deadline = time.monotonic() + REQUEST_TIMEOUT_S
        self.to_client = bytearray()
        self.to_upstream = bytearray()
        self.watched: set[socket.socket] = {client}  # registered with the selector


class TokenGate(ThreadedServer):
    """Listens on ``address``:``port``; passes connections carrying ``token`` to
    127.0.0.1:``upstream_port``. Use as a context manager (``start()`` binds)."""

    def __init__(self, address: str, port: int, upstream_port: int, token: str) -> None:
        super().__init__()
        self.address = address
        self._requested_port = port
        self.upstream_port = upstream_port
        self._token = token.encode()
        self._listener: socket.socket | None = None
        self._selector: selectors.BaseSelector | None = None
        self._pipes: set[_Pipe] = set()
        self.refused = 0

    @property
    def port(self) -> int:
        """The port the gate listens on."""
        assert self._listener is not None, "TokenGate is not started"
        return self._listener.getsockname()[1]

    def _open(self) -> dict[str, Callable[[], object]]:
        family = socket.AF_INET6 if ":" in self.address else socket.AF_INET
        self._listener = socket.create_server((self.address, self._requested_port),
                                              family=family, backlog=64)
        self._listener.setblocking(False)
        self._selector = selectors.DefaultSelector()
        self._selector.register(self._listener, selectors.EVENT_READ)
        return {"serve": self._serve}

    def _interrupt(self) -> None:
        """The serving thread looks at ``_closing`` every ``_POLL_S``."""

    def _release(self) -> None:
        for pipe in list(self._pipes):
            self._drop(pipe)
        assert self._selector is not None and self._listener is not None
        self._selector.close()
        self._listener.close()
        self._selector = self._listener = None

    # -- the serving thread ------------------------------------------------------------------
    def _serve(self) -> None:
        assert self._selector is not None
        while not self._closing.is_set():
            for key, events in self._selector.select(_POLL_S):
                if key.fileobj is self._listener:
                    self._accept()
                elif key.data is not None and key.data in self._pipes:
                    self._handle(key.data, key.fileobj, events)
            now = time.monotonic()
            for pipe in [p for p in self._pipes if p.upstream is None and p.deadline < now]:
                logger.info("live view: a client sent no complete request in %.0f s",
                            REQUEST_TIMEOUT_S)
                self._drop(pipe)

    def _accept(self) -> None:
        assert self._listener is not None and self._selector is not None
        try:
            client, _ = self._listener.accept()
        except (BlockingIOError, InterruptedError):
            return
        client.setblocking(False)
        pipe = _Pipe(client)
        self._pipes.add(pipe)
        self._selector.register(client, selectors.EVENT_READ, pipe)

    def _handle(self, pipe: _Pipe, sock, events: int) -> None:
        try:
            if pipe.upstream is None:
                self._read_request(pipe)
            elif sock is pipe.client:
                self._move(pipe, events, pipe.client, pipe.upstream, pipe.to_upstream,
                           pipe.to_client)
            else:
                self._move(pipe, events, pipe.upstream, pipe.client, pipe.to_client,
                           pipe.to_upstream)
        except OSError as exc:
            logger.debug("live view: a connection ended: %s", exc)
            self._drop(pipe)

    def _read_request(self, pipe: _Pipe) -> None:
        data = pipe.client.recv(_CHUNK)
        if not data:
            self._drop(pipe)
            return
        pipe.request += data
        end = pipe.request.find(b"\r\n\r\n")
        if end < 0:
            if len(pipe.request) > MAX_REQUEST_BYTES:
                self._drop(pipe)
            return
        token = request_token(pipe.request[:end])
        if token is None or not hmac.compare_digest(token.encode(), self._token):
            self.refused += 1
            logger.warning("live view: a connection without the token refused")
            try:
                pipe.client.send(_UNAUTHORIZED)
            finally:
                self._drop(pipe)
            return
        upstream = socket.create_connection(("127.0.0.1", self.upstream_port), timeout=2.0)
        upstream.setblocking(False)
        pipe.upstream = upstream
        pipe.to_upstream += pipe.request
        pipe.request = b""
        self._update(pipe)

    def _move(self, pipe: _Pipe, events: int, source: socket.socket, sink: socket.socket,
              outgoing: bytearray, incoming: bytearray) -> None:
        """``source`` is ready: read what it sent into ``outgoing`` (for ``sink``) and write
        what waits for it (``incoming``)."""
        if events & selectors.EVENT_READ and len(outgoing) < MAX_BUFFERED_BYTES:
            data = source.recv(_CHUNK)
            if not data:
                self._drop(pipe)
                return
            outgoing += data
        if events & selectors.EVENT_WRITE and incoming:
            sent = source.send(incoming)
            del incoming[:sent]
        self._update(pipe)

    def _update(self, pipe: _Pipe) -> None:
        """Each socket waits for writing while bytes wait for it, for reading while its
        peer's buffer has room."""
        assert self._selector is not None and pipe.upstream is not None
        for sock, waiting, peer_buffer in ((pipe.client, pipe.to_client, pipe.to_upstream),
                                           (pipe.upstream, pipe.to_upstream, pipe.to_client)):
            events = (selectors.EVENT_WRITE if waiting else 0) | (
                selectors.EVENT_READ if len(peer_buffer) < MAX_BUFFERED_BYTES else 0)
            if not events:  # nothing to send it, and its peer reads too slowly: not watched
                if sock in pipe.watched:
                    self._selector.unregister(sock)
                    pipe.watched.discard(sock)
            elif sock in pipe.watched:
                self._selector.modify(sock, events, pipe)
            else:
                self._selector.register(sock, events, pipe)
                pipe.watched.add(sock)

    def _drop(self, pipe: _Pipe) -> None:
        self._pipes.discard(pipe)
        for sock in (pipe.client, pipe.upstream):
            if sock is None:
                continue
            if sock in pipe.watched and self._selector is not None:
                self._selector.unregister(sock)
            sock.close()
        pipe.watched.clear()
