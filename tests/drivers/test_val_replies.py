"""Classification of VAL monitor replies: the five kinds, echo handling, and arbitrary bytes."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.core.errors import ProtocolError
from drivers.val.replies import ReplyKind, parse_reply, reply_complete


def test_prompt_is_ok_with_output_lines():
    reply = parse_reply(b"where\r\n  X  Y\r\n  1  2\r\n.", "where")
    assert reply.kind is ReplyKind.OK
    assert reply.lines == ("  X  Y", "  1  2")


def test_error_between_asterisks_carries_the_message():
    reply = parse_reply(b"do move a\r\n*Position out of range*\r\n.", "do move a")
    assert (reply.kind, reply.message) == (ReplyKind.ERROR, "Position out of range")


@pytest.mark.parametrize("data, kind, message", [
    (b"\r\nLoad VAL from floppy (Y/N)? ", ReplyKind.QUESTION, "Load VAL from floppy (Y/N)?"),
    (b"cal\r\nAre you sure?\n", ReplyKind.QUESTION, "Are you sure?"),
    (b"x\r\nInvalid answer:", ReplyKind.WRONG_INPUT, "Invalid answer:"),
    (b"x\r\nProgram HOLD\r\n.", ReplyKind.HOLD, "Program HOLD"),
    (b"x\r\nD\r\n.", ReplyKind.HOLD, "D"),
    (b"\r\n.", ReplyKind.OK, ""),
])
def test_reply_kinds(data, kind, message):
    reply = parse_reply(data)
    assert (reply.kind, reply.message) == (kind, message)


@pytest.mark.parametrize("ending", [b"\r\n", b"\n\r", b"\r", b"\n"])
def test_any_line_ending(ending):
    data = ending.join([b"speed 50", b"*Value out of range*", b"."])
    assert parse_reply(data, "speed 50").message == "Value out of range"


def test_echo_is_case_and_space_insensitive_and_skips_stale_bytes():
    stale = b"where\r\n  X\r\n  1\r\n.\r\n."  # a late reply, then a late prompt
    reply = parse_reply(stale + b"SPEED  50\r\n.", "speed 50")
    assert reply.kind is ReplyKind.OK and reply.lines == ()


def test_nul_padding_and_bell_are_dropped():
    assert parse_reply(b"x\r\n\x07*Bad*\x00\r\n.", "x").message == "Bad"


@pytest.mark.parametrize("data", [
    b"where\r\n\xfe\x80 noise\r\n.",      # not ASCII
    b"where\r\n\x1b[2J\r\n.",             # control bytes
    b"  1  2\r\n.",                       # no echo of the command
    b"where\r\n  X  Y\r\n",               # no prompt
    b"where\r\n",                         # nothing after the echo
])
def test_bad_replies_raise_protocol_error(data):
    with pytest.raises(ProtocolError):
        parse_reply(data, "where")


@pytest.mark.parametrize("data, command, complete", [
    (b"where\r\n  X\r\n", "where", False),
    (b"where\r\n  X\r\n.", "where", True),
    (b"do move here:", "do move here:", False),     # the echo is not a wrong-input line
    (b"do move here:\r\n.", "do move here:", True),
    (b"\r\n.", "speed 5", False),                     # a stale prompt before the echo
    # the prompt of a program still running when the command went, ending as it replied
    (b"*listp fpstop\r\nPROGRAM fpstop\r\n  1  STOP\r\nEND\r\n.", "listp fpstop", True),
    (b"\r\nInitialize (Y/N)? ", None, True),
    (b"   300.", None, False),                         # a number is not the prompt
])
def test_reply_complete(data, command, complete):
    assert reply_complete(data, command) is complete


@given(st.binary(max_size=300), st.sampled_from([None, "", "where", "do move trans(1,2,3,4,5,6)"]))
def test_parser_only_returns_a_reply_or_raises_protocol_error(data, command):
    try:
        reply = parse_reply(data, command)
    except ProtocolError:
        return
    assert reply.kind in ReplyKind
    assert all(isinstance(line, str) and line for line in reply.lines)
    assert reply_complete(data, command) or command is None


@given(st.lists(st.sampled_from([b"where", b"*Position out of range*", b".", b"?", b":",
                                 b"Change? ", b"D", b" 1.5 ", b"\r", b"\n", b"\x00", b"\x07",
                                 b"\xff", b"HOLD"]), max_size=30),
       st.sampled_from([None, "where"]))
def test_parser_on_protocol_like_fragments(fragments, command):
    data = b"".join(fragments)
    reply_complete(data, command)
    try:
        parse_reply(data, command)
    except ProtocolError:
        pass
