"""The control server: accepts on the UNIX socket (and the optional loopback TCP port), checks
each UNIX peer's credentials, and serves every connection in its own thread.

An accept thread waits on a selector with a wake-up pipe, so ``close()`` stops it at once;
``close()`` then shuts the reading side of every open connection (a blocked read returns, a
stream sends its last event), joins their threads and removes the socket file. At most
``max_clients`` authenticated connections are served; one more is answered ``too_many_clients``
and closed, as is a peer the policy refuses. TCP connections that have not authenticated yet
do not count: they have their own MAX_UNAUTHENTICATED slots (and AUTH_TIMEOUT_S each).
"""

from __future__ import annotations

import contextlib
import logging
import os
import selectors
import socket
import threading
import time
from pathlib import Path

from controller.service.config import ServiceConfig
from controller.service.connection import Connection, RequestHandler
from controller.service.listeners import bind_tcp, bind_unix, unlink_if_ours
from controller.service.peer import PeerPolicy, peer_credentials, resolve_gid
from controller.service.protocol import error_line

logger = logging.getLogger(__name__)

JOIN_TIMEOUT_S = 2.0
# TCP connections still to authenticate are served up to this many at once, apart from
# max_clients: peers without the token can never take the slots of those who have it.
MAX_UNAUTHENTICATED = 4


class ControlServer:
    """Serves ``handler`` on ``socket_path``; ``policy`` may be replaced while it runs."""

    def __init__(self, socket_path: str | Path, config: ServiceConfig, policy: PeerPolicy,
                 handler: RequestHandler, token: str | None = None) -> None:
        self.socket_path = Path(socket_path)
        self.config = config
        self.policy = policy
        self._handler = handler
        self._token = token
        self._listeners: dict[socket.socket, str] = {}
        self._inode: int | None = None
        self._connections: dict[socket.socket, threading.Thread] = {}
        self._pending: set[socket.socket] = set()  # TCP connections not yet authenticated
        self._lock = threading.Lock()
        self._closing = threading.Event()
        self._wake_r, self._wake_w = -1, -1
        self._accept_thread = threading.Thread(target=self._accept_loop, name="control-accept",
                                               daemon=True)

    @property
    def client_count(self) -> int:
        """The number of authenticated connections being served now."""
        with self._lock:
            return len(self._connections) - len(self._pending)

    def _admit_authenticated(self, connection: Connection) -> tuple[str, str] | None:
        """A TCP connection just authenticated: it takes a client slot if one is free."""
        with self._lock:
            self._pending.discard(connection.sock)
            if len(self._connections) - len(self._pending) > self.config.max_clients:
                return ("too_many_clients", f"{self.config.max_clients} clients connected "
                                            "already")
        return None

    def start(self) -> ControlServer:
        """Bind the UNIX socket (and the TCP listener if configured), start accepting; returns self.

        Raises:
            ListenerError: the socket path is not a socket, or another service answers on it.
            ConfigError: ``service.socket_group`` names no group on this system.
            OSError: a socket cannot be bound (e.g. the TCP port is in use).
        """
        group = self.config.socket_group
        gid = resolve_gid(group, "service.socket_group") if group is not None else None
        sock, self._inode = bind_unix(self.socket_path, gid)
        self._listeners[sock] = "unix"
        logger.info("control socket %s (mode 0660, group %s)", self.socket_path,
                    group if group is not None else "of the service")
        if self.config.tcp is not None:
            self._listeners[bind_tcp(self.config.tcp)] = "tcp"
            logger.warning("TCP control listener on %s:%d (token required)",
                           self.config.tcp.host, self.config.tcp.port)
        self._wake_r, self._wake_w = os.pipe()
        self._accept_thread.start()
        return self

    def close(self, timeout_s: float = 2 * JOIN_TIMEOUT_S) -> None:
        """Stop accepting, end every connection, remove the socket file; idempotent.

        Ends within about ``timeout_s`` whatever the clients do: every connection's reading side
        is shut at once (a blocked read returns, a stream sends its "end"), and after half of
        ``timeout_s`` the connections still busy (writing to a client that does not read) are
        shut both ways, all together.
        """
        if self._closing.is_set():
            return
        self._closing.set()
        deadline = time.monotonic() + timeout_s
        if self._wake_w >= 0:
            os.write(self._wake_w, b"x")
            self._accept_thread.join()
            os.close(self._wake_r)
            os.close(self._wake_w)
        for listener in self._listeners:
            listener.close()
        if self._inode is not None:
            unlink_if_ours(self.socket_path, self._inode)
        with self._lock:
            connections = dict(self._connections)
        for sock in connections:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RD)
        half = time.monotonic() + (deadline - time.monotonic()) / 2
        for thread in connections.values():
            thread.join(max(0.0, half - time.monotonic()))
        for sock, thread in connections.items():
            if thread.is_alive():
                with contextlib.suppress(OSError):
                    sock.shutdown(socket.SHUT_RDWR)
        for thread in connections.values():
            thread.join(max(0.0, deadline - time.monotonic()))
            if thread.is_alive():
                logger.warning("connection thread %s still busy at shutdown", thread.name)

    def __enter__(self) -> ControlServer:
        return self.start()

    def __exit__(self, *exc_info) -> None:
        self.close()

    # -- accepting ---------------------------------------------------------------------------
    def _accept_loop(self) -> None:
        with selectors.DefaultSelector() as selector:
            selector.register(self._wake_r, selectors.EVENT_READ)
            for listener in self._listeners:
                selector.register(listener, selectors.EVENT_READ)
            while not self._closing.is_set():
                for key, _ in selector.select():
                    if key.fileobj in self._listeners and not self._closing.is_set():
                        self._accept(key.fileobj)

    def _accept(self, listener: socket.socket) -> None:
        try:
            sock, _ = listener.accept()
        except OSError as exc:
            logger.warning("accept failed: %s", exc)
            return
        kind = self._listeners[listener]
        name, refusal = self._admit(sock, kind)
        if refusal is not None:
            logger.warning("%s: refused: %s", name, refusal[1])
            with contextlib.suppress(OSError):
                sock.sendall(error_line(None, *refusal))
            sock.close()
            return
        tcp = kind == "tcp"
        connection = Connection(sock, name, self._handler, self.config.max_request_bytes,
                                self._closing, self._token if tcp else None,
                                self._admit_authenticated if tcp else None)
        thread = threading.Thread(target=self._serve, args=(connection,), name=name,
                                  daemon=True)
        with self._lock:
            self._connections[sock] = thread
            if tcp:
                self._pending.add(sock)
        thread.start()

    def _admit(self, sock: socket.socket, kind: str) -> tuple[str, tuple[str, str] | None]:
        """The connection's name for the log, and (code, message) if it is refused."""
        if kind == "tcp":
            host, port = sock.getpeername()[:2]
            name = f"tcp {host}:{port}"
            with self._lock:
                waiting = len(self._pending)
            if waiting >= MAX_UNAUTHENTICATED:
                return name, ("too_many_clients", f"{waiting} connections are authenticating "
                                                  "already")
            return name, None
        else:
            try:
                peer = peer_credentials(sock)
            except OSError as exc:
                return "unix peer", ("unauthorized", f"cannot read peer credentials: {exc}")
            name = f"unix pid {peer.pid} uid {peer.uid}"
            refusal = self.policy.refusal(peer)
            if refusal is not None:
                return name, ("unauthorized", refusal)
        if self.client_count >= self.config.max_clients:
            return name, ("too_many_clients", f"{self.config.max_clients} clients connected "
                                              "already")
        return name, None

    def _serve(self, connection: Connection) -> None:
        logger.debug("%s: connected", connection.name)
        try:
            connection.serve()
        finally:
            with self._lock:
                self._connections.pop(connection.sock, None)
                self._pending.discard(connection.sock)
            connection.sock.close()
            logger.debug("%s: disconnected", connection.name)
