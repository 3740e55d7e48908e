"""A client of the control socket (used by ``finepos ctl``, the tests and the benchmark).

``ServiceClient(path)`` connects to the UNIX socket (``tcp=(host, port), token=...``: the loopback
TCP listener, authenticating first). ``call(cmd, **args)`` sends one request and returns its
result, raising ServiceError with the response's code and message on an error response;
``events()`` turns the connection into the event stream.
"""

from __future__ import annotations

import itertools
import json
import socket
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from drivers.core.errors import FineposError

# Longest answer or event line read from the service (a status or an iteration record is a few
# KB); a longer one is refused before it grows further.
MAX_LINE_BYTES = 1 << 20
_RECV_BYTES = 65536


class ServiceError(FineposError):
    """The service answered with an error; ``code`` is one of protocol.ERROR_CODES."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(f"{code}: {message}")
        self.code = code
        self.message = message


class ServiceUnavailable(FineposError):
    """No service answers at the given address (not running, wrong path, no permission)."""


class ServiceTimeout(FineposError, TimeoutError):
    """No complete answer line within the timeout (bytes trickling in do not extend it)."""


class ServiceProtocolError(FineposError):
    """What came back is no answer of the control protocol: not JSON, not a JSON object, or
    a line longer than MAX_LINE_BYTES."""


class ServiceClient:
    """One connection; requests are answered in order. Use as a context manager."""

    def __init__(self, socket_path: str | Path | None = None, *,
                 tcp: tuple[str, int] | None = None, token: str | None = None,
                 timeout_s: float | None = 30.0) -> None:
        if (socket_path is None) == (tcp is None):
            raise ValueError("give either socket_path or tcp")
        where = str(socket_path) if socket_path is not None else f"{tcp[0]}:{tcp[1]}"
        try:
            if tcp is not None:
                self._sock = socket.create_connection(tcp, timeout=timeout_s)
            else:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                self._sock.settimeout(timeout_s)
                self._sock.connect(str(socket_path))
        except OSError as exc:
            raise ServiceUnavailable(f"cannot connect to the finepos service at {where}: "
                                     f"{exc.strerror or exc}") from exc
        self._buffer = bytearray()  # received, not yet returned as a line
        self._event_timeout_s: float | None = None
        self._ids = itertools.count(1)
        if token is not None:
            self.call("auth", token=token)

    def close(self) -> None:
        """Close the connection to the service."""
        self._sock.close()

    def __enter__(self) -> ServiceClient:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def send_line(self, line: bytes, timeout_s: float | None = 30.0) -> dict[str, Any]:
        """Send raw bytes (one line, newline added) and return the parsed response line,
        complete within ``timeout_s`` (None: no limit).

        Raises:
            ServiceTimeout: no complete line within ``timeout_s``.
            ServiceProtocolError: the line is not a JSON object, or longer than MAX_LINE_BYTES.
            ServiceUnavailable: the service closed the connection.
        """
        self._sock.settimeout(timeout_s)
        try:
            self._sock.sendall(line + b"\n")
        except (BrokenPipeError, ConnectionResetError):
            pass  # refused at connect: the service's one answer is waiting to be read
        except TimeoutError as exc:
            raise ServiceTimeout(f"the service took no request within {timeout_s:g} s") from exc
        return self._read(timeout_s)

    def request(self, cmd: str, args: dict[str, Any] | None = None,
                timeout_s: float | None = 30.0) -> dict[str, Any]:
        """Send one request; the whole response (``ok``, ``result`` or ``error``)."""
        message = {"id": next(self._ids), "cmd": cmd, "args": args or {}}
        return self.send_line(json.dumps(message).encode(), timeout_s)

    def call(self, cmd: str, timeout_s: float | None = 30.0, **args: Any) -> dict[str, Any]:
        """The result of one request (raises ServiceError on an error response)."""
        response = self.request(cmd, args, timeout_s)
        if not response.get("ok"):
            error = response.get("error")
            if not isinstance(error, dict):
                raise ServiceProtocolError(f"the service's answer to {cmd} has neither a result "
                                           "nor an error")
            raise ServiceError(str(error.get("code")), str(error.get("message")))
        if "result" not in response:
            raise ServiceProtocolError(f"the service's answer to {cmd} has no result")
        return response["result"]

    def events(self, timeout_s: float | None = None) -> Iterator[dict[str, Any]]:
        """Start streaming now; the iterator yields events until the service ends the stream
        (``timeout_s`` bounds the wait for each)."""
        self.call("stream")
        return self._events(timeout_s)

    def _events(self, timeout_s: float | None) -> Iterator[dict[str, Any]]:
        while True:
            event = self._read(timeout_s)
            yield event
            if event.get("event") == "end":
                return

    def _read(self, timeout_s: float | None) -> dict[str, Any]:
        """The next line as a JSON object, complete within ``timeout_s`` (None: no limit)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while (end := self._buffer.find(b"\n")) < 0:
            if len(self._buffer) > MAX_LINE_BYTES:
                raise ServiceProtocolError(f"the service sent a line longer than "
                                           f"{MAX_LINE_BYTES} bytes")
            if deadline is not None:
                remaining_s = deadline - time.monotonic()
                if remaining_s <= 0:
                    raise ServiceTimeout(f"no complete answer from the service within "
                                         f"{timeout_s:g} s")
                self._sock.settimeout(remaining_s)
            else:
                self._sock.settimeout(None)
            try:
                chunk = self._sock.recv(_RECV_BYTES)
            except TimeoutError:
                continue  # the deadline check above says so
            except ConnectionResetError:
                chunk = b""
            if not chunk:
                raise ServiceUnavailable("the finepos service closed the connection")
            self._buffer += chunk
        line = bytes(self._buffer[:end])
        del self._buffer[:end + 1]
        try:
            message = json.loads(line)
        except (ValueError, RecursionError) as exc:
            raise ServiceProtocolError(f"the service sent a line that is not JSON: "
                                       f"{line[:60]!r}") from exc
        if not isinstance(message, dict):
            raise ServiceProtocolError(f"the service sent {type(message).__name__}, not a JSON "
                                       "object")
        return message
