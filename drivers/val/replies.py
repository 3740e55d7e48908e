"""Classify what the VAL II monitor sent back after one command line (pure functions).

A reply is the bytes received after a command was sent: the echo of the command line (when the
monitor echoes), output lines, and a last line that says what the monitor waits for:

- ``.`` at the start of a line: the monitor prompt, the command is done (OK);
- a line ending in ``?``: a question waiting for an answer (QUESTION);
- a line ending in ``:``: wrong input, the monitor asks again (WRONG_INPUT).

An OK reply is further classified by its output lines: a line ``*text*`` is a controller error
(ERROR, message = text); a line ``D`` or one ending in ``HOLD`` is a program hold (HOLD).
``parse_reply`` only ever returns a Reply or raises ProtocolError.
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass

from drivers.core.errors import ProtocolError

# Printable ASCII plus the control bytes a terminal line may carry. NUL (padding) and BEL (the
# controller's bell) are dropped; anything else is line noise.
_ALLOWED_CONTROL = frozenset(b"\r\n\t\x00\x07")
_DROPPED = str.maketrans("", "", "\x00\x07")
_LINE_BREAK = re.compile(r"\r\n|\n\r|\r|\n")
_ERROR_LINE = re.compile(r"^\*(.*)\*$")


class ReplyKind(enum.Enum):
    OK = "ok"
    QUESTION = "question"
    WRONG_INPUT = "wrong input"
    ERROR = "error"
    HOLD = "hold"


@dataclass(frozen=True)
class Reply:
    """One classified reply.

    kind: see the module docstring. lines: the output lines between the echo and the last line,
    without trailing blanks and without empty lines. message: the error text between the
    asterisks (ERROR), the question or wrong-input line (QUESTION, WRONG_INPUT), the hold line
    (HOLD), or "" (OK).
    """

    kind: ReplyKind
    lines: tuple[str, ...]
    message: str = ""


def _normalized(line: str) -> str:
    return " ".join(line.split()).casefold()


def _is_echo(line: str, wanted: str) -> bool:
    text = _normalized(line)
    # After stale bytes the echo follows their prompt on the same line: ".where", or
    # "*listp fpstop" after the prompt of a program that was still running.
    return text == wanted or (text[:1] in (".", "*") and text[1:].lstrip() == wanted)


def _after_echo(lines: list[str], command: str) -> list[str] | None:
    """The lines after the last finished echo of ``command``; None without one.

    ``lines`` is a split text whose last element is the unfinished line (maybe "").
    """
    wanted = _normalized(command)
    echoes = [i for i, line in enumerate(lines[:-1]) if _is_echo(line, wanted)]
    return lines[echoes[-1] + 1:] if echoes else None


def reply_complete(data: bytes, command: str | None = None) -> bool:
    """Whether ``data`` holds a whole reply: its last line is a prompt, question or wrong-input.

    With ``command`` (an echoing monitor) only what follows the finished echo line counts, so a
    command ending in ``:`` or ``?`` does not look like a finished reply and stale bytes before
    the echo are ignored.
    """
    lines = _LINE_BREAK.split(data.decode("latin-1").translate(_DROPPED))
    if command is not None:
        rest = _after_echo(lines, command)
        if rest is None:
            return False
        lines = rest
    filled = [stripped for line in lines if (stripped := line.rstrip())]
    if not filled:
        return False
    last = filled[-1]
    return last == "." or last.endswith(("?", ":"))


def parse_reply(data: bytes, command: str | None = None) -> Reply:
    """Classify ``data``, the bytes received after sending one line.

    Args:
        data: everything received for this command.
        command: the command line sent, when the monitor echoes it. The reply then starts after
            the last line equal to it (case and spacing ignored), so stale bytes from an earlier,
            timed-out exchange are skipped; a reply without the echo is a ProtocolError.

    Raises:
        ProtocolError: line noise (bytes that are not ASCII text), a missing echo, or no
            prompt/question at the end.
    """
    for offset, byte in enumerate(data):
        if not (0x20 <= byte <= 0x7E or byte in _ALLOWED_CONTROL):
            raise ProtocolError(f"line noise in reply: byte 0x{byte:02x} at offset {offset} of "
                                f"{data[:80]!r}")
    text = data.decode("ascii").translate(_DROPPED)
    lines = _LINE_BREAK.split(text)
    if command is not None:
        rest = _after_echo(lines, command)
        if rest is None:
            raise ProtocolError(f"reply does not start with the echo of {command!r}: {text[:80]!r}")
        lines = rest
    filled = [stripped for line in lines if (stripped := line.rstrip())]
    if not filled:
        raise ProtocolError(f"empty reply{f' to {command!r}' if command is not None else ''}")
    last, body = filled[-1], tuple(filled[:-1])
    if last.endswith("?"):
        return Reply(ReplyKind.QUESTION, body, last.strip())
    if last.endswith(":"):
        return Reply(ReplyKind.WRONG_INPUT, body, last.strip())
    if last != ".":
        raise ProtocolError(f"reply does not end with the '.' prompt or a question: {last[:80]!r}")
    for line in body:
        error = _ERROR_LINE.match(line.strip())
        if error:
            return Reply(ReplyKind.ERROR, body, error.group(1).strip())
    for line in body:
        stripped = line.strip()
        if stripped == "D" or stripped.upper().endswith("HOLD"):
            return Reply(ReplyKind.HOLD, body, stripped)
    return Reply(ReplyKind.OK, body)
