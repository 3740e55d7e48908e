"""The wire format: line framing with a size limit, the envelope, argument validation."""

from __future__ import annotations

import json
import socket
import threading

import pytest

from controller.service.commands import COMMANDS, JOB_COMMANDS, validate_args
from controller.service.protocol import (
    TOO_LARGE,
    LineReader,
    RequestError,
    decode,
    error_line,
    ok_line,
    parse_request,
)


def parse(text: str):
    return parse_request(decode(text.encode()))


def test_a_valid_request_gets_its_defaults():
    request = parse('{"cmd": "acquire", "args": {"set": "nn2"}, "id": "a"}')
    assert (request.cmd, request.args, request.id) == \
        ("acquire", {"part": None, "set": "nn2", "seed": 0, "wait": False}, "a")
    assert parse('{"cmd": "status"}').args == {}
    assert parse('{"cmd": "position", "args": {"offset": [1, -2.5, 30]}}').args == \
        {"part": None, "max_loops": None, "offset": [1.0, -2.5, 30.0], "grasp": False,
         "wait": False}
    assert parse('{"cmd": "grasp", "args": {"part": "nut"}}').args == {"part": "nut",
                                                                        "wait": False}


@pytest.mark.parametrize(("text", "code", "message"), [
    ("{", "bad_json", "not a JSON request"),
    ("[1]", "bad_json", "a request is a JSON object, got list"),
    ('{"cmd": "status", "x": 1}', "bad_request", "unknown field 'x'"),
    ('{"args": {}}', "bad_request", "cmd: a command name (string) is required"),
    ('{"cmd": "fly"}', "unknown_command", "unknown command 'fly'"),
    ('{"cmd": "status", "id": true}', "bad_request", "id: a string"),
    ('{"cmd": "status", "args": {"verbose": true}}', "bad_request",
     "status: unknown argument 'verbose' (allowed: none)"),
    ('{"cmd": "acquire"}', "bad_request", "acquire: set: required"),
    ('{"cmd": "acquire", "args": {"set": "nn1", "seed": true}}', "bad_request",
     "seed: expected an integer, got bool"),
    ('{"cmd": "position", "args": {"max_loops": NaN}}', "bad_json", "NaN is not a number"),
    ('{"cmd": "position", "args": {"max_loops": 1e999}}', "bad_request", "finite"),
    ('{"cmd": "position", "args": {"max_loops": 0.1}}', "bad_request",
     "max_loops: must be within [0.5, 1000], got 0.1"),
    ('{"cmd": "position", "args": {"offset": [0, 0, 181]}}', "bad_request",
     "offset[2]: must be within [-180, 180], got 181"),
    ('{"cmd": "train", "args": {"system": "svm"}}', "bad_request",
     "system: one of gabor, pca, hough, align, got 'svm'"),
    # a part the cell does not know is refused by the service, which knows the cell's parts
    # (tests/controller/service/test_parts.py)
    ('{"cmd": "position", "args": {"part": 7}}', "bad_request",
     "part: expected a string, got int"),
    ('{"cmd": "position", "args": {"part": "' + "b" * 40 + '"}}', "bad_request",
     "part: longer than 32 characters"),
])
def test_bad_requests_are_refused_with_a_code_and_the_reason(text, code, message):
    with pytest.raises(RequestError) as refused:
        parse(text)
    assert refused.value.code == code and message in refused.value.message


def test_every_job_command_can_wait_and_every_argument_has_help():
    assert all("wait" in COMMANDS[cmd] for cmd in JOB_COMMANDS)
    assert all("part" in COMMANDS[cmd] for cmd in JOB_COMMANDS)
    assert all(spec.help for specs in COMMANDS.values() for spec in specs.values())
    with pytest.raises(ValueError, match="wait: expected true or false"):
        validate_args("grasp", {"wait": 1})


def test_responses_are_single_json_lines():
    line = ok_line(3, {"pose": {"x_mm": float("nan")}})
    assert line.endswith(b"\n") and line.count(b"\n") == 1
    assert json.loads(line) == {"id": 3, "ok": True, "result": {"pose": {"x_mm": None}}}
    assert json.loads(error_line(None, "busy", "job 1\nrunning"))["error"]["message"] == \
        "job 1\nrunning"


def test_line_reader_skips_an_oversized_line_and_carries_on():
    server, client = socket.socketpair()
    reader = LineReader(server, max_bytes=16)
    payload = b'{"cmd": "a"}\n' + b"x" * 100_000 + b"\n" + b"y" * 15 + b"\n" + b"partial"
    sender = threading.Thread(target=lambda: (client.sendall(payload), client.close()))
    sender.start()
    assert reader.read() == b'{"cmd": "a"}'
    assert reader.read() is TOO_LARGE
    assert reader.read() == b"y" * 15
    assert reader.read() is None  # an unterminated last line is dropped
    sender.join()
    server.close()


def test_a_stream_sends_what_was_published_before_the_service_stopped_then_its_end():
    """The service publishes its "stopping" state and closes at once: a stream that has
    not yet read it from its queue still sends it, and the events before it, then the end."""
    from controller.service.connection import Connection
    from controller.service.events import EventHub

    hub, closing = EventHub(), threading.Event()
    published = [{"event": "iteration", "record": {"iteration": 7}},
                 {"event": "state", "state": "stopping"}]

    class StoppingService:
        def handle(self, request):
            raise AssertionError("only the stream is asked for")

        def subscribe(self):
            subscription = hub.subscribe()
            for event in published:
                hub.publish(event)
            closing.set()  # the service stops before the stream reads its queue
            return subscription

    ours, theirs = socket.socketpair()
    with ours, theirs:
        connection = Connection(ours, "test", StoppingService(), 4096, closing)
        thread = threading.Thread(target=connection.serve, daemon=True)
        thread.start()
        theirs.sendall(b'{"cmd": "stream", "id": 1}\n')
        thread.join(5.0)
        assert not thread.is_alive()
        ours.shutdown(socket.SHUT_WR)
        lines = theirs.makefile("rb").read().decode().splitlines()
    answer, *events = (json.loads(line) for line in lines)
    assert answer["ok"] is True and answer["result"] == {"streaming": True}
    assert events == [*published, {"event": "end", "reason": "service stopping"}]
