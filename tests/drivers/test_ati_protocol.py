"""The ATI reply parser: known replies, and arbitrary bytes give a result or ProtocolError only."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.ati.protocol import (
    Record,
    check_silent_reply,
    parse_query_reply,
    parse_record,
    reply_lines,
)
from drivers.core.errors import ProtocolError


def test_parses_the_manual_example():
    record = parse_record("0,  -102,   -99,  -225,   -20,    39,   -39")
    assert record == Record(0, (-102, -99, -225, -20, 39, -39))


@pytest.mark.parametrize("reply", [
    b"QR\r\n0,     1,     2,     3,     4,     5,     6\r\n>",  # echo, CL 1
    b"QR\r0,1,2,3,4,5,6\r>",  # CL 0
    b"0, 1, 2, 3, 4, 5, 6\r\n>",  # no echo
    b"\r\nqr\r\n\r\n+0,+1,2,3,4,5,6\r\n>",
])
def test_query_reply_framings(reply):
    assert parse_query_reply("QR", reply) == Record(0, (1, 2, 3, 4, 5, 6))


@pytest.mark.parametrize("reply, match", [
    (b"QR\r\n0,1,2,3,4,5\r\n>", "7 fields"),
    (b"QR\r\n0,1,2,3,4,5,6.5\r\n>", "not a whole number"),
    (b"QR\r\n0,1,2,3,4,5,6\r\n", "prompt"),
    (b"QR\r\n0,1,2,3,4,5,6\r\n0,1,2,3,4,5,6\r\n>", "one record"),
    (b"QR\r\n\xff\xfe>", "not ASCII"),
    (b"QR\r\n>", "one record"),
])
def test_bad_query_replies(reply, match):
    with pytest.raises(ProtocolError, match=match):
        parse_query_reply("QR", reply)


def test_silent_reply_accepts_echo_and_prompt_only():
    check_silent_reply("CD A", b"CD A\r\n>")
    check_silent_reply("", b"\r\n>")
    with pytest.raises(ProtocolError, match="Error: unknown"):
        check_silent_reply("XX", b"XX\r\nError: unknown command XX\r\n>")


@given(st.text())
def test_record_parser_never_raises_anything_else(line):
    try:
        record = parse_record(line)
    except ProtocolError:
        return
    assert isinstance(record.status, int) and len(record.counts) == 6


@given(st.binary(max_size=200), st.sampled_from(["QR", "SB", "CD A", ""]))
def test_reply_parsers_never_raise_anything_else(reply, command):
    for parse in (parse_query_reply, check_silent_reply, reply_lines):
        try:
            parse(command, reply)
        except ProtocolError:
            pass


@given(st.lists(st.integers(-(10**9), 10**9), min_size=7, max_size=7),
       st.sampled_from([b"\r\n", b"\r"]), st.booleans())
def test_emitted_records_round_trip(values, eol, echo):
    line = ",".join(f"{v:6d}" for v in values).encode()
    reply = (b"QR" + eol if echo else b"") + line + eol + b">"
    assert parse_query_reply("QR", reply) == Record(values[0], tuple(values[1:]))
