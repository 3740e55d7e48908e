"""One client connection: read request lines, answer each, or turn into an event stream.

Every line gets exactly one response line. A TCP connection must authenticate first
(``auth`` with the token, within AUTH_TIMEOUT_S of connecting: an absolute deadline that bytes
trickling in do not extend; anything else, or a wrong token, is answered ``unauthorized`` and
the connection closed). ``stream`` answers once, then sends events until
the client or the service goes away; a stream connection takes no further requests (what the
client sends is discarded).
Errors in a request never end the connection; an unexpected error in the service is logged with
its traceback and answered ``failed``.
"""

from __future__ import annotations

import contextlib
import hmac
import logging
import socket
import threading
from collections.abc import Callable
from typing import Any, Protocol

from controller.service.events import Subscription
from controller.service.pacing import RequestPacer
from controller.service.protocol import (
    TOO_LARGE,
    LineReader,
    PeerTimeout,
    Request,
    RequestError,
    decode,
    error_line,
    event_line,
    ok_line,
    parse_request,
    request_id,
)

logger = logging.getLogger(__name__)

STREAM_POLL_S = 0.05  # how often an idle stream checks whether its client or the service left
AUTH_TIMEOUT_S = 10.0  # a TCP connection that has not authenticated by then is closed


class RequestHandler(Protocol):
    """What a connection needs from the service."""

    def handle(self, request: Request) -> dict[str, Any]:
        """The result of one validated request (``stream`` and ``auth`` never get here).

        Raises:
            RequestError: the request is refused or fails; its code goes into the error response.
        """
        ...

    def subscribe(self) -> Subscription:
        """A new event subscription for a ``stream`` connection (which closes it)."""
        ...


class Connection:
    """Serves one accepted socket until it closes (``serve`` runs in the connection's thread)."""

    def __init__(self, sock: socket.socket, name: str, handler: RequestHandler, max_bytes: int,
                 closing: threading.Event, token: str | None = None,
                 admit: Callable[[Connection], tuple[str, str] | None] | None = None,
                 pacer: RequestPacer | None = None, idle_timeout_s: float | None = None,
                 line_timeout_s: float | None = None) -> None:
        """``admit`` (TCP): called once the token was accepted; returns (code, message) to
        refuse the now authenticated connection (the server's client limit), else None.
        ``pacer``: spaces this connection's answers (all but ``abort``'s); None: unpaced.
        ``idle_timeout_s`` / ``line_timeout_s``: see ``protocol.LineReader`` (a peer that times
        out is disconnected; a ``stream`` connection has no idle timeout)."""
        self.sock = sock
        self.name = name
        self._handler = handler
        self._reader = LineReader(sock, max_bytes, idle_timeout_s, line_timeout_s)
        self._max_bytes = max_bytes
        self._closing = closing
        self._token = token  # None: authenticated by its peer credentials already
        self._admit = admit
        self._pacer = pacer
        self._auth_timer: threading.Timer | None = None
        if token is not None:
            self._auth_timer = threading.Timer(AUTH_TIMEOUT_S, self._auth_expired)
            self._auth_timer.daemon = True

    @property
    def authenticated(self) -> bool:
        """Whether the peer may send commands (a UNIX peer always; TCP after ``auth``)."""
        return self._token is None

    def _auth_expired(self) -> None:
        if self._token is not None:
            logger.warning("%s: refused: no auth within %g s", self.name, AUTH_TIMEOUT_S)
            with contextlib.suppress(OSError):
                self.sock.shutdown(socket.SHUT_RDWR)

    def serve(self) -> None:
        """Answer requests until the client or the server ends the connection."""
        if self._auth_timer is not None:
            self._auth_timer.start()
        try:
            self._serve()
        except PeerTimeout as exc:
            logger.info("%s: disconnected: %s", self.name, exc)
        except OSError as exc:  # the client went away mid-write, or the server shut us down
            logger.debug("%s: connection ended: %s", self.name, exc)
        finally:
            if self._auth_timer is not None:
                self._auth_timer.cancel()

    def _serve(self) -> None:
        while not self._closing.is_set():
            line = self._reader.read()
            if line is None:
                return
            if line is TOO_LARGE:
                self._paced_send(error_line(None, "too_large",
                                      f"request longer than {self._max_bytes} bytes"))
                continue
            data = None
            try:
                data = decode(line)
                request = parse_request(data)
            except RequestError as exc:
                self._paced_send(error_line(request_id(data), exc.code, exc.message))
                if self._token is not None:
                    return  # not authenticated: no second chance on this connection
                continue
            except Exception as exc:  # a parser bug must not end the connection unanswered
                logger.exception("%s: parsing a request failed", self.name)
                self._paced_send(error_line(request_id(data), "bad_request",
                                            f"request not understood: {type(exc).__name__}"))
                if self._token is not None:
                    return
                continue
            if self._token is not None:
                if not self._authenticate(request):
                    return
                continue
            if request.cmd == "stream":
                self._stream(request.id)
                return
            if request.cmd == "auth":
                self._paced_send(ok_line(request.id, {"authenticated": True}))
                continue
            if request.cmd == "abort":
                self._send(self._answer(request))  # never paced: it must always get through
            else:
                self._paced_send(self._answer(request))

    def _answer(self, request: Request) -> bytes:
        try:
            return ok_line(request.id, self._handler.handle(request))
        except RequestError as exc:
            return error_line(request.id, exc.code, exc.message)
        except Exception as exc:  # a bug must not take the service down with the connection
            logger.exception("%s: %s failed", self.name, request.cmd)
            return error_line(request.id, "failed", f"internal error: {type(exc).__name__}: "
                                                    f"{exc}")

    def _authenticate(self, request: Request) -> bool:
        token = self._token or ""
        if request.cmd == "auth" and hmac.compare_digest(request.args["token"].encode(),
                                                         token.encode()):
            self._token = None
            if self._auth_timer is not None:
                self._auth_timer.cancel()
            refusal = self._admit(self) if self._admit is not None else None
            if refusal is not None:
                self._send(error_line(request.id, *refusal))
                return False
            self._send(ok_line(request.id, {"authenticated": True}))
            return True
        logger.warning("%s: refused: %s", self.name, "wrong token" if request.cmd == "auth"
                       else "no auth before the first request")
        self._send(error_line(request.id, "unauthorized",
                              'authenticate first: {"cmd": "auth", "args": {"token": ...}}'))
        return False

    def _stream(self, rid: str | int | None) -> None:
        self.sock.settimeout(None)  # a listener may stay quiet for ever
        subscription = self._handler.subscribe()
        try:
            self._send(ok_line(rid, {"streaming": True}))
            while not self._closing.is_set():
                event = subscription.get(STREAM_POLL_S)
                if event is not None:
                    self._send(event_line(event))
                elif self._client_left() and not self._closing.is_set():
                    return  # (when closing, the server shut our reading side: not the client)
            # what was published before the service stopped (its "stopping" state among it),
            # then the end; a client that does not read is cut off by the server's close
            subscription.close()
            while (event := subscription.get(0.0)) is not None:
                self._send(event_line(event))
            self._send(event_line({"event": "end", "reason": "service stopping"}))
        finally:
            subscription.close()

    def _client_left(self) -> bool:
        """Discard what the client sent; True once it closed its end."""
        try:
            return self.sock.recv(4096, socket.MSG_DONTWAIT) == b""
        except BlockingIOError:
            return False

    def _paced_send(self, data: bytes) -> None:
        """Send after the pacer's delay (sleeping, so a fast poller slows only itself)."""
        delay_s = self._pacer.delay_s() if self._pacer is not None else 0.0
        if delay_s > 0 and self._closing.wait(delay_s):
            return  # the service is stopping: the connection ends without this answer
        self._send(data)

    def _send(self, data: bytes) -> None:
        self.sock.sendall(data)
