"""Property tests (hypothesis) over everything that parses bytes from outside: the control
socket's request parser, the VAL reply classifier and ``where`` parser, and the ATI reply
parsers. Whatever arrives, each returns a result or raises its one typed error; a pose read is
always finite and within range; a request that passes is within its documented ranges."""

from __future__ import annotations

import json
import math

from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from controller.service.commands import COMMANDS
from controller.service.protocol import RequestError, decode, parse_request
from drivers.ati.protocol import parse_query_reply, parse_record
from drivers.core.errors import ProtocolError
from drivers.val.replies import Reply, parse_reply, reply_complete
from drivers.val.where import parse_where

SETTINGS = settings(max_examples=150, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])

# -- the request parser ------------------------------------------------------------------------
HUGE_INTS = st.integers(min_value=-(10**400), max_value=10**400)
NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), HUGE_INTS,
                    st.integers(-(2**64), 2**64))
JSON_VALUES = st.recursive(
    st.one_of(st.none(), st.booleans(), NUMBERS, st.text(max_size=20)),
    lambda inner: st.one_of(st.lists(inner, max_size=4),
                            st.dictionaries(st.text(max_size=10), inner, max_size=4)),
    max_leaves=12)
ARG_NAMES = sorted({name for args in COMMANDS.values() for name in args} | {"x"})
REQUESTS = st.fixed_dictionaries(
    {"cmd": st.one_of(st.sampled_from(sorted(COMMANDS)), JSON_VALUES)},
    optional={"args": st.one_of(st.dictionaries(st.sampled_from(ARG_NAMES), JSON_VALUES,
                                                max_size=4), JSON_VALUES),
              "id": JSON_VALUES})


def _dumps(value) -> str:
    # Python's json writes NaN/Infinity; a client may send them, so they are kept.
    return json.dumps(value)


def _in_range(request) -> None:
    for name, value in request.args.items():
        spec = COMMANDS[request.cmd][name]
        if isinstance(value, float):
            assert math.isfinite(value)
        if spec.low is not None and value is not None and not isinstance(value, (bool, list)):
            assert spec.low <= value <= spec.high


@SETTINGS
@given(REQUESTS)
def test_request_parser_returns_a_valid_request_or_a_request_error(data):
    line = _dumps(data).encode()
    try:
        request = parse_request(decode(line))
    except RequestError as exc:
        assert exc.code in ("bad_json", "bad_request", "unknown_command")
        return
    assert request.cmd in COMMANDS
    _in_range(request)


@SETTINGS
@given(st.binary(max_size=300))
def test_request_parser_on_raw_bytes(line):
    try:
        parse_request(decode(line))
    except RequestError:
        pass


# -- VAL ---------------------------------------------------------------------------------------
VAL_TOKENS = st.sampled_from([b".", b"*", b"?", b":", b"\r", b"\n", b"\r\n", b" ", b"where",
                              b"X Y Z O A T", b"JT1 JT2 JT3 JT4 JT5 JT6", b"1.5", b"-2e3",
                              b"1e999", b"nan", b"*Position out of range*", b"D", b"HOLD",
                              b"\x00", b"\x07", b"\xff", b"Change?", b"1" * 400])
VAL_REPLIES = st.one_of(st.binary(max_size=200),
                        st.lists(VAL_TOKENS, max_size=30).map(b"".join))


@SETTINGS
@given(VAL_REPLIES, st.sampled_from([None, "where", "speed 50", ""]))
def test_val_reply_is_classified_or_a_protocol_error(data, command):
    reply_complete(data, command)  # never raises
    try:
        reply = parse_reply(data, command)
    except ProtocolError:
        return
    assert isinstance(reply, Reply)


LINE_TOKENS = st.one_of(
    st.sampled_from(["X Y Z O A T", "JT1 JT2 JT3 JT4 JT5 JT6", "X/JT1 Y/JT2 Z/JT3 O/JT4 A/JT5 "
                     "T/JT6", "", "  "]),
    st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr),
                       st.sampled_from(["1e999", "-1e308", "1" * 400, ".5", "+3.", "x"])),
             min_size=5, max_size=7).map(" ".join),
    st.text(max_size=30))


@SETTINGS
@given(st.lists(LINE_TOKENS, max_size=8))
@example(["X Y Z O A T", "1e308 0 0 0 0 0"])
@example(["X Y Z O A T", "0 0 0 0 0 0", "JT1 JT2 JT3 JT4 JT5 JT6", "1e999 0 0 0 0 0"])
def test_where_gives_a_finite_bounded_pose_or_a_protocol_error(lines):
    try:
        reading = parse_where(lines)
    except ProtocolError:
        return
    values = reading.pose.as_dict().values()
    assert all(math.isfinite(v) and abs(v) <= 1e5 for v in values)
    if reading.joints_deg is not None:
        assert all(math.isfinite(v) and abs(v) <= 1e5 for v in reading.joints_deg)


# -- ATI ---------------------------------------------------------------------------------------
ATI_TOKENS = st.sampled_from([b"0", b"-102", b",", b" ", b"\r\n", b"\r", b">", b"QR",
                              b"99999999999", b"+5", b"1e3", b"\xff", b"\x00", b"-"])


@SETTINGS
@given(st.one_of(st.binary(max_size=120), st.lists(ATI_TOKENS, max_size=40).map(b"".join)))
def test_ati_reply_is_a_record_or_a_protocol_error(data):
    try:
        record = parse_query_reply("QR", data)
    except ProtocolError:
        return
    assert len(record.counts) == 6 and all(abs(c) < 10**10 for c in record.counts)


@SETTINGS
@given(st.text(max_size=80))
def test_ati_record_parser_on_any_text(line):
    try:
        parse_record(line)
    except ProtocolError:
        pass
