"""The ATI F/T controller's ASCII serial protocol: reply framing and record parsing (pure).

A command is sent as ``<text>\\r``; the controller may echo it, prints its output lines (ended
by ``\\r\\n``, or ``\\r`` alone after ``CL 0``) and then the prompt ``>``. In ``CD A`` / ``CD R``
mode one record is ``status, Fx, Fy, Fz, Tx, Ty, Tz`` as decimal counts, e.g.
``0,  -102,   -99,  -225,   -20,    39,   -39``; status 0 means healthy.

Every function here either returns a result or raises ``ProtocolError``; nothing else escapes,
whatever bytes arrive (property-tested with hypothesis).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from drivers.core.errors import DeviceFaultError, ProtocolError

PROMPT = b">"
AXES = ("fx", "fy", "fz", "tx", "ty", "tz")
_RECORD_FIELDS = 1 + len(AXES)
_INT_RE = re.compile(r"[+-]?[0-9]{1,10}")
_LINE_BREAK_RE = re.compile(r"[\r\n]+")


class AtiStatusError(DeviceFaultError):
    """The controller flagged a record with a nonzero status word (saturation, broken gauge...).

    Attributes:
        status: the status word as sent.
    """

    def __init__(self, status: int):
        super().__init__(f"ATI F/T status word {status} (0x{status & 0xFFFFFFFF:X}): sensor error")
        self.status = status


@dataclass(frozen=True)
class Record:
    """One resolved force/torque record: status word and Fx, Fy, Fz, Tx, Ty, Tz in counts."""

    status: int
    counts: tuple[int, int, int, int, int, int]


def parse_record(line: str) -> Record:
    """Parse ``status, Fx, Fy, Fz, Tx, Ty, Tz`` (decimal counts, spaces allowed)."""
    fields = [f.strip() for f in line.split(",")]
    if len(fields) != _RECORD_FIELDS:
        raise ProtocolError(f"ATI record needs {_RECORD_FIELDS} fields, got {len(fields)}: "
                            f"{line!r}")
    for field in fields:
        if not _INT_RE.fullmatch(field):
            raise ProtocolError(f"ATI record field {field!r} is not a whole number: {line!r}")
    values = [int(f) for f in fields]
    return Record(values[0], (values[1], values[2], values[3], values[4], values[5], values[6]))


def reply_lines(command: str, reply: bytes) -> list[str]:
    """The output lines of ``reply`` (bytes up to and including the prompt).

    Drops the prompt, empty lines and the controller's echo of ``command``.
    """
    if not reply.endswith(PROMPT):
        raise ProtocolError(f"ATI reply to {command!r} does not end with the prompt: {reply!r}")
    try:
        text = reply[: -len(PROMPT)].decode("ascii")
    except UnicodeDecodeError as exc:
        raise ProtocolError(f"ATI reply to {command!r} is not ASCII: {reply!r}") from exc
    lines = [line.strip() for line in _LINE_BREAK_RE.split(text)]
    echo = command.strip().upper()
    return [line for line in lines if line and line.upper() != echo]


def parse_query_reply(command: str, reply: bytes) -> Record:
    """The single record in the reply to ``QR``."""
    lines = reply_lines(command, reply)
    if len(lines) != 1:
        raise ProtocolError(f"ATI reply to {command!r} must hold one record, got {lines!r}")
    return parse_record(lines[0])


def check_silent_reply(command: str, reply: bytes) -> None:
    """A set-up command (``CD A``, ``SB``...) answers with its echo and the prompt only."""
    lines = reply_lines(command, reply)
    if lines:
        raise ProtocolError(f"ATI controller answered {command!r} with {lines!r}")
