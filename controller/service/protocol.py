"""The control socket's wire format: JSON lines, one request and one response per line.

Framing: ``LineReader`` returns each ``\\n``-terminated line of at most ``max_bytes`` bytes
(newline included); a longer line is skipped up to its newline and reported as ``TOO_LARGE``, so
every line sent gets exactly one response, in order. ``parse_request`` turns a line into a
``Request`` (the envelope: ``cmd``, optional ``args`` object and ``id``) and validates the
arguments (``controller.service.commands``); every failure is a ``RequestError`` with a code.
"""

from __future__ import annotations

import json
import socket
import time
from dataclasses import dataclass
from typing import Any

from controller.loop.iteration_log import to_json_line
from controller.service.commands import COMMANDS, validate_args
from drivers.core.errors import FineposError

MAX_ID_CHARS = 64
MAX_ID_INT = 2**53
_RECV_BYTES = 65536
TOO_LARGE = object()  # what LineReader.read returns for a line over the limit

# Error codes (``error.code`` of a response) and what they mean.
ERROR_CODES = {
    "too_large": "the request line is longer than service.max_request_bytes",
    "bad_json": "the line is not a UTF-8 JSON object",
    "bad_request": "the envelope or an argument is missing, of the wrong type or out of range",
    "unknown_command": "cmd names no command",
    "unauthorized": "the peer is not allowed, or a TCP connection did not authenticate",
    "too_many_clients": "service.max_clients (or max_clients_per_uid) connections are open "
                        "already: only one abort or status is answered on this connection",
    "not_ready": "the service is still starting",
    "busy": "a job is running (abort it, or wait for it to end)",
    "fault": "the service is in fault: motion is refused until a reset succeeds",
    "stopping": "the service is shutting down",
    "failed": "the command was valid but did not succeed (the message says why)",
}


class RequestError(FineposError):
    """A request that gets an error response; ``code`` is one of ERROR_CODES."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message


@dataclass(frozen=True)
class Request:
    """A validated request: the command, its arguments (defaults filled in) and the id."""

    cmd: str
    args: dict[str, Any]
    id: str | int | None = None


def _reject_constant(name: str) -> None:
    raise ValueError(f"{name} is not a number JSON allows")


def request_id(data: Any) -> str | int | None:
    """The request's id if it is an acceptable one (else None: the response carries null)."""
    if not isinstance(data, dict):
        return None
    value = data.get("id")
    if isinstance(value, str) and len(value) <= MAX_ID_CHARS:
        return value
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) <= MAX_ID_INT:
        return value
    return None


def decode(line: bytes) -> Any:
    """The JSON value of one line (raises RequestError ``bad_json``)."""
    try:
        return json.loads(line.decode("utf-8"), parse_constant=_reject_constant)
    except (ValueError, RecursionError) as exc:
        raise RequestError("bad_json", f"not a JSON request: {str(exc)[:200]}") from exc


def parse_request(data: Any) -> Request:
    """Validate a decoded request (raises RequestError)."""
    if not isinstance(data, dict):
        raise RequestError("bad_json", f"a request is a JSON object, got {type(data).__name__}")
    unknown = sorted(str(k)[:40] for k in data if k not in ("cmd", "args", "id"))
    if unknown:
        raise RequestError("bad_request", f"unknown field {unknown[0]!r} (allowed: cmd, args, id)")
    if "id" in data and data["id"] is not None and request_id(data) is None:
        raise RequestError("bad_request", f"id: a string of at most {MAX_ID_CHARS} characters, "
                                          "an integer or null")
    cmd = data.get("cmd")
    if not isinstance(cmd, str):
        raise RequestError("bad_request", "cmd: a command name (string) is required")
    if cmd not in COMMANDS:
        raise RequestError("unknown_command", f"unknown command {cmd[:40]!r} (one of "
                                              f"{', '.join(COMMANDS)})")
    args = data.get("args", {})
    if args is None:
        args = {}
    if not isinstance(args, dict):
        raise RequestError("bad_request", f"args: expected an object, got {type(args).__name__}")
    try:
        return Request(cmd, validate_args(cmd, args), request_id(data))
    except ValueError as exc:
        raise RequestError("bad_request", f"{cmd}: {exc}") from exc


class EncodedResult(bytes):
    """A result already encoded as one JSON object (e.g. the ``status`` snapshot): ``ok_line``
    splices it in as is instead of encoding it for every request."""


def ok_line(request_id_: str | int | None, result: dict[str, Any] | EncodedResult) -> bytes:
    """The success response line (newline-terminated bytes) carrying ``result``."""
    if isinstance(result, EncodedResult):
        return b"".join((b'{"id":', json.dumps(request_id_).encode(), b',"ok":true,"result":',
                         result, b"}\n"))
    return (to_json_line({"id": request_id_, "ok": True, "result": result}) + "\n").encode()


def error_line(request_id_: str | int | None, code: str, message: str) -> bytes:
    """The error response line (newline-terminated bytes); ``code`` is one of ERROR_CODES."""
    return (to_json_line({"id": request_id_, "ok": False,
                          "error": {"code": code, "message": message}}) + "\n").encode()


def event_line(event: dict[str, Any]) -> bytes:
    """One stream event as a newline-terminated JSON line (bytes)."""
    return (to_json_line(event) + "\n").encode()


class PeerTimeout(Exception):
    """The peer sent no request for ``idle_timeout_s``, or a line took over ``line_timeout_s``."""


class LineReader:
    """Splits what a socket receives into request lines of at most ``max_bytes``.

    ``idle_timeout_s``: longest wait for the first byte of a request; ``line_timeout_s``: a line
    must be complete this long after its first byte (bytes trickling in do not extend it); both
    raise PeerTimeout (None: wait for ever).
    """

    def __init__(self, sock: socket.socket, max_bytes: int, idle_timeout_s: float | None = None,
                 line_timeout_s: float | None = None) -> None:
        self._sock = sock
        self._max_bytes = max_bytes
        self._buffer = bytearray()
        self._skipping = False
        self._idle_timeout_s = idle_timeout_s
        self._line_timeout_s = line_timeout_s
        self._line_deadline_s: float | None = None

    def _recv(self) -> bytes:
        if self._buffer or self._skipping:
            if self._line_deadline_s is None and self._line_timeout_s is not None:
                self._line_deadline_s = time.monotonic() + self._line_timeout_s
            timeout_s = None if self._line_deadline_s is None else \
                self._line_deadline_s - time.monotonic()
            what = f"a request line not complete within {self._line_timeout_s} s"
        else:
            timeout_s, what = self._idle_timeout_s, f"no request for {self._idle_timeout_s} s"
        if timeout_s is not None and timeout_s <= 0:
            raise PeerTimeout(what)
        if self._idle_timeout_s is not None or self._line_timeout_s is not None:
            self._sock.settimeout(timeout_s)
        try:
            return self._sock.recv(_RECV_BYTES)
        except TimeoutError as exc:
            raise PeerTimeout(what) from exc

    def read(self) -> bytes | object | None:
        """The next line (without its newline), TOO_LARGE for one over the limit, or None at
        the end of the stream (an unterminated last line is dropped).

        Raises:
            PeerTimeout: see the class docstring.
        """
        while True:
            end = self._buffer.find(b"\n")
            if end >= 0:
                line = bytes(self._buffer[:end])
                del self._buffer[:end + 1]
                self._line_deadline_s = None  # (the rest of the buffer: a fresh line's clock)
                if self._skipping or end + 1 > self._max_bytes:
                    self._skipping = False
                    return TOO_LARGE
                return line
            if len(self._buffer) >= self._max_bytes:
                self._skipping = True
                self._buffer.clear()
            chunk = self._recv()
            if not chunk:
                return None
            self._buffer += chunk
