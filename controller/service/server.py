"""The control server: accepts on the UNIX socket (and the optional loopback TCP port), checks
each UNIX peer's credentials, and serves every connection in its own thread.

An accept thread waits on a selector with a wake-up pipe, so ``close()`` stops it at once;
``close()`` then shuts the reading side of every open connection (a blocked read returns, a
stream sends its last event), joins their threads and removes the socket file. At most
``max_clients`` authenticated connections, and ``max_clients_per_uid`` per UNIX peer uid, are
served in threads. An authorised UNIX peer over either limit is kept by the accept thread itself
(no thread, up to ``max_waiting`` of them, each for ``request_timeout_s``) for one request:
``abort`` or ``status`` is answered (abort in a short-lived thread), anything else
``too_many_clients``; then it is closed. When all ``max_waiting`` places are taken, the uid
holding the most of them gives up its oldest (after what that peer sent already is read, so
an abort it sent is still obeyed): a new peer always gets a place, and one uid's flood cannot
push out another uid's peers. So no number of idle or reconnecting connections can lock out
an abort. A peer the policy refuses gets ``unauthorized``. TCP connections that have not
authenticated yet do not count: they have their own MAX_UNAUTHENTICATED slots (and
AUTH_TIMEOUT_S each); when those are full the oldest is closed to make room, so peers without
the token cannot keep out one that has it.
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
from controller.service.listeners import ListenerError, bind_tcp, bind_unix, unlink_if_ours
from controller.service.pacing import RequestPacer
from controller.service.peer import PeerPolicy, peer_credentials, resolve_gid
from controller.service.protocol import (
    Request,
    RequestError,
    decode,
    error_line,
    ok_line,
    parse_request,
)

logger = logging.getLogger(__name__)

JOIN_TIMEOUT_S = 2.0
# TCP connections still to authenticate are served up to this many at once, apart from
# max_clients: peers without the token can never take the slots of those who have it.
MAX_UNAUTHENTICATED = 4
# What a peer over the connection limits may still send (once), answered by the accept thread.
OVER_LIMIT_COMMANDS = ("abort", "status")
WAITING_SEND_TIMEOUT_S = 1.0


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
        # TCP connections not yet authenticated, oldest first (a dict keeps insertion order)
        self._pending: dict[socket.socket, None] = {}
        self._evicted: set[socket.socket] = set()  # closed unauthenticated, thread still ending
        self._uids: dict[socket.socket, int] = {}  # the peer uid of each served UNIX connection
        # Authorised peers over the limits, oldest first: (name, buffer, deadline, uid), served
        # by the accept thread.
        self._waiting: dict[socket.socket, tuple[str, bytearray, float, int]] = {}
        self._selector: selectors.BaseSelector | None = None
        self._lock = threading.Lock()
        self._closing = threading.Event()
        self._wake_r, self._wake_w = -1, -1
        self._accept_thread = threading.Thread(target=self._accept_loop, name="control-accept",
                                               daemon=True)

    @property
    def client_count(self) -> int:
        """The number of authenticated connections being served now."""
        with self._lock:
            return len(self._connections) - len(self._pending) - len(self._evicted)

    def _admit_authenticated(self, connection: Connection) -> tuple[str, str] | None:
        """A TCP connection just authenticated: it takes a client slot if one is free."""
        with self._lock:
            self._pending.pop(connection.sock, None)
            if connection.sock in self._evicted:
                return ("too_many_clients", f"closed: more than {MAX_UNAUTHENTICATED} "
                                            "connections were authenticating at once")
            served = len(self._connections) - len(self._pending) - len(self._evicted)
            if served > self.config.max_clients:
                return ("too_many_clients", f"{self.config.max_clients} clients connected "
                                            "already")
        return None

    def start(self) -> ControlServer:
        """Bind the UNIX socket (and the TCP listener if configured), start accepting; returns self.

        Raises:
            ListenerError: the socket path is not a socket, another service answers on it, or
                the TCP port cannot be bound (in use): the socket file is removed again.
            ConfigError: ``service.socket_group`` names no group on this system.
            OSError: the UNIX socket cannot be bound.
        """
        group = self.config.socket_group
        gid = resolve_gid(group, "service.socket_group") if group is not None else None
        sock, self._inode = bind_unix(self.socket_path, gid)
        self._listeners[sock] = "unix"
        logger.info("control socket %s (mode 0660, group %s)", self.socket_path,
                    group if group is not None else "of the service")
        if self.config.tcp is not None:
            try:
                self._listeners[bind_tcp(self.config.tcp)] = "tcp"
            except OSError as exc:  # e.g. another service on the port: leave no socket file
                sock.close()
                self._listeners.clear()
                unlink_if_ours(self.socket_path, self._inode)
                raise ListenerError(f"service.tcp: cannot listen on {self.config.tcp.host}:"
                                    f"{self.config.tcp.port}: {exc.strerror or exc}") from exc
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
            self._selector = selector
            selector.register(self._wake_r, selectors.EVENT_READ)
            for listener in self._listeners:
                selector.register(listener, selectors.EVENT_READ)
            while not self._closing.is_set():
                now_s = time.monotonic()
                timeout_s = min((w[2] - now_s for w in self._waiting.values()), default=None)
                for key, _ in selector.select(None if timeout_s is None else max(0, timeout_s)):
                    if self._closing.is_set():
                        break
                    if key.fileobj in self._listeners:
                        self._accept(key.fileobj)
                    elif key.fileobj in self._waiting:
                        self._read_waiting(key.fileobj)
                now_s = time.monotonic()
                for sock in [s for s, w in self._waiting.items() if w[2] <= now_s]:
                    logger.info("%s: disconnected: no abort or status within %g s",
                                self._waiting[sock][0], self.config.request_timeout_s)
                    self._drop_waiting(sock)
            for sock in list(self._waiting):
                self._drop_waiting(sock)

    # -- peers over the limits: one abort or status each, answered here -----------------------
    def _wait(self, sock: socket.socket, name: str, uid: int) -> bool:
        """Keep an authorised peer over the limits for one ``abort`` or ``status``, making
        room first when every place is taken (``_evict_waiting``)."""
        if self._selector is None:
            return False
        while len(self._waiting) >= self.config.max_waiting:
            self._evict_waiting()
        sock.setblocking(False)
        self._waiting[sock] = (name, bytearray(),
                               time.monotonic() + self.config.request_timeout_s, uid)
        self._selector.register(sock, selectors.EVENT_READ)
        return True

    def _evict_waiting(self) -> None:
        """Free one waiting place: the oldest peer of the uid holding the most places. What it
        sent already is read first, so a complete ``abort`` or ``status`` is still answered."""
        counts: dict[int, int] = {}
        for entry in self._waiting.values():
            counts[entry[3]] = counts.get(entry[3], 0) + 1
        heaviest = max(counts, key=counts.__getitem__)
        victim = next(s for s, entry in self._waiting.items() if entry[3] == heaviest)
        self._read_waiting(victim)
        if victim in self._waiting:
            logger.info("%s: disconnected: its waiting place went to a newer peer",
                        self._waiting[victim][0])
            self._drop_waiting(victim)

    def _drop_waiting(self, sock: socket.socket) -> None:
        self._waiting.pop(sock, None)
        if self._selector is not None:
            with contextlib.suppress(KeyError, ValueError):
                self._selector.unregister(sock)
        sock.close()

    def _read_waiting(self, sock: socket.socket) -> None:
        name, buffer = self._waiting[sock][:2]
        try:
            chunk = sock.recv(4096)
        except BlockingIOError:
            return
        except OSError:
            chunk = b""
        buffer += chunk
        end = buffer.find(b"\n")
        if not chunk or (end < 0 and len(buffer) > self.config.max_request_bytes):
            self._drop_waiting(sock)
            return
        if end < 0:
            return
        self._waiting.pop(sock)
        with contextlib.suppress(KeyError, ValueError):
            self._selector.unregister(sock)
        line = bytes(buffer[:end])
        try:
            request = parse_request(decode(line))
        except RequestError as exc:
            self._answer_waiting(sock, error_line(None, exc.code, exc.message))
            return
        if request.cmd not in OVER_LIMIT_COMMANDS:
            self._answer_waiting(sock, error_line(request.id, "too_many_clients", (
                f"over the connection limits (service.max_clients {self.config.max_clients}, "
                f"max_clients_per_uid {self.config.max_clients_per_uid}): only "
                f"{' and '.join(OVER_LIMIT_COMMANDS)} are answered")))
            return
        if request.cmd == "status":
            self._answer_waiting(sock, self._respond(request))
            return
        logger.warning("%s: abort over the connection limits", name)
        threading.Thread(target=lambda: self._answer_waiting(sock, self._respond(request)),
                         name=f"{name} abort", daemon=True).start()

    def _respond(self, request: Request) -> bytes:
        try:
            return ok_line(request.id, self._handler.handle(request))
        except RequestError as exc:
            return error_line(request.id, exc.code, exc.message)
        except Exception as exc:  # a bug must not end the accept thread
            logger.exception("%s failed", request.cmd)
            return error_line(request.id, "failed", f"internal error: {type(exc).__name__}")

    def _answer_waiting(self, sock: socket.socket, data: bytes) -> None:
        """Send the one answer (a short blocking write) and close."""
        try:
            sock.settimeout(WAITING_SEND_TIMEOUT_S)
            sock.sendall(data)
        except OSError as exc:
            logger.debug("answer to a peer over the limits not sent: %s", exc)
        finally:
            sock.close()

    def _accept(self, listener: socket.socket) -> None:
        try:
            sock, _ = listener.accept()
        except OSError as exc:
            logger.warning("accept failed: %s", exc)
            return
        kind = self._listeners[listener]
        name, refusal, uid = self._admit(sock, kind)
        if refusal is not None and refusal[0] == "too_many_clients" and uid is not None and \
                self._wait(sock, name, uid):
            return
        if refusal is not None:
            logger.warning("%s: refused: %s", name, refusal[1])
            with contextlib.suppress(OSError):
                sock.sendall(error_line(None, *refusal))
            sock.close()
            return
        tcp = kind == "tcp"
        cfg = self.config
        connection = Connection(sock, name, self._handler, cfg.max_request_bytes,
                                self._closing, self._token if tcp else None,
                                self._admit_authenticated if tcp else None,
                                RequestPacer(cfg.request_rate_hz, cfg.request_burst),
                                cfg.idle_timeout_s, cfg.request_timeout_s)
        thread = threading.Thread(target=self._serve, args=(connection,), name=name,
                                  daemon=True)
        with self._lock:
            self._connections[sock] = thread
            if uid is not None:
                self._uids[sock] = uid
            if tcp:
                self._pending[sock] = None
        thread.start()

    def _admit(self, sock: socket.socket,
               kind: str) -> tuple[str, tuple[str, str] | None, int | None]:
        """The connection's name for the log, (code, message) if it is refused, and the
        peer's uid once the policy allowed it (UNIX peers)."""
        if kind == "tcp":
            host, port = sock.getpeername()[:2]
            name = f"tcp {host}:{port}"
            self._evict_unauthenticated()
            return name, None, None
        try:
            peer = peer_credentials(sock)
        except OSError as exc:
            return "unix peer", ("unauthorized", f"cannot read peer credentials: {exc}"), None
        name = f"unix pid {peer.pid} uid {peer.uid}"
        refusal = self.policy.refusal(peer)
        if refusal is not None:
            return name, ("unauthorized", refusal), None
        if self.client_count >= self.config.max_clients:
            return name, ("too_many_clients", f"{self.config.max_clients} clients connected "
                                              "already"), peer.uid
        with self._lock:
            same_uid = sum(1 for uid in self._uids.values() if uid == peer.uid)
        if same_uid >= self.config.max_clients_per_uid:
            return name, ("too_many_clients", f"uid {peer.uid} has {same_uid} connections "
                                              "already (service.max_clients_per_uid)"), peer.uid
        return name, None, peer.uid

    def _evict_unauthenticated(self) -> None:
        """Make room for a new TCP connection: while MAX_UNAUTHENTICATED are still to
        authenticate, close the oldest of them (its thread ends at its next read)."""
        with self._lock:
            while len(self._pending) >= MAX_UNAUTHENTICATED:
                oldest = next(iter(self._pending))
                del self._pending[oldest]
                self._evicted.add(oldest)
                logger.warning("an unauthenticated TCP connection closed to make room for a "
                               "new one")
                with contextlib.suppress(OSError):
                    oldest.shutdown(socket.SHUT_RDWR)

    def _serve(self, connection: Connection) -> None:
        logger.debug("%s: connected", connection.name)
        try:
            connection.serve()
        finally:
            with self._lock:
                self._connections.pop(connection.sock, None)
                self._pending.pop(connection.sock, None)
                self._evicted.discard(connection.sock)
                self._uids.pop(connection.sock, None)
            connection.sock.close()
            logger.debug("%s: disconnected", connection.name)
