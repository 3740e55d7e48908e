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
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from drivers.core.errors import FineposError


class ServiceError(FineposError):
    """The service answered with an error; ``code`` is one of protocol.ERROR_CODES."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(f"{code}: {message}")
        self.code = code
        self.message = message


class ServiceUnavailable(FineposError):
    """No service answers at the given address (not running, wrong path, no permission)."""


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
        self._file = self._sock.makefile("rb")
        self._ids = itertools.count(1)
        if token is not None:
            self.call("auth", token=token)

    def close(self) -> None:
        """Close the connection to the service."""
        self._file.close()
        self._sock.close()

    def __enter__(self) -> ServiceClient:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def send_line(self, line: bytes, timeout_s: float | None = 30.0) -> dict[str, Any]:
        """Send raw bytes (one line, newline added) and return the parsed response line."""
        self._sock.settimeout(timeout_s)
        try:
            self._sock.sendall(line + b"\n")
        except (BrokenPipeError, ConnectionResetError):
            pass  # refused at connect: the service's one answer is waiting to be read
        return self._read()

    def request(self, cmd: str, args: dict[str, Any] | None = None,
                timeout_s: float | None = 30.0) -> dict[str, Any]:
        """Send one request; the whole response (``ok``, ``result`` or ``error``)."""
        message = {"id": next(self._ids), "cmd": cmd, "args": args or {}}
        return self.send_line(json.dumps(message).encode(), timeout_s)

    def call(self, cmd: str, timeout_s: float | None = 30.0, **args: Any) -> dict[str, Any]:
        """The result of one request (raises ServiceError on an error response)."""
        response = self.request(cmd, args, timeout_s)
        if not response.get("ok"):
            error = response.get("error") or {}
            raise ServiceError(str(error.get("code")), str(error.get("message")))
        return response["result"]

    def events(self, timeout_s: float | None = None) -> Iterator[dict[str, Any]]:
        """Start streaming now; the iterator yields events until the service ends the stream
        (``timeout_s`` bounds the wait for each)."""
        self.call("stream")
        self._sock.settimeout(timeout_s)
        return self._events()

    def _events(self) -> Iterator[dict[str, Any]]:
        while True:
            event = self._read()
            yield event
            if event.get("event") == "end":
                return

    def _read(self) -> dict[str, Any]:
        try:
            line = self._file.readline()
        except ConnectionResetError:
            line = b""
        if not line:
            raise ServiceUnavailable("the finepos service closed the connection")
        return json.loads(line)
