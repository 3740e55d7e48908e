"""The control socket under bad input and load: 10,000 generated malformed, oversized and unknown
requests each get an error and the service carries on; concurrent clients are all served; the
client limit and the loopback TCP listener's token hold."""

from __future__ import annotations

import json
import os
import random
import socket
import threading
from pathlib import Path

import pytest

from controller.service.client import ServiceClient, ServiceError, ServiceUnavailable
from controller.service.commands import COMMANDS
from controller.service.listeners import read_token
from controller.service.service import Service
from drivers.core.errors import ConfigError
from tests.controller.service.conftest import (
    EVENT_TIMEOUT_S,
    client_for,
    device_opener,
    running_service,
    service_config,
)
from tests.mocks.fakes import FakeArm, FakeCamera, FakeWrenchSensor

MAX_REQUEST_BYTES = 2048
GENERATED = 10_000


@pytest.fixture
def fakes():
    return FakeArm(), FakeCamera(), FakeWrenchSensor()


@pytest.fixture
def service(tmp_path, short_dir, fakes):
    config = service_config(tmp_path, short_dir,
                            service={"max_request_bytes": MAX_REQUEST_BYTES, "max_clients": 12,
                                     "max_clients_per_uid": 12,  # all clients here are ours
                                     "request_rate_hz": 0})  # unpaced: 10,000 requests below
    with running_service(config, device_opener(*fakes)) as running:
        yield running


# Each value is invalid for every command that has an argument of that name (and an unknown
# argument for the others).
BAD_ARGS = (("no_such_arg", 1), ("wait", "yes"), ("wait", 1), ("set", 3), ("set", "nn9"),
            ("seed", -1), ("seed", 1.5), ("seed", True), ("max_loops", 0.0),
            ("max_loops", "6"), ("max_loops", 1e999), ("offset", [1, 2]),
            ("offset", [0, 0, 999]), ("offset", "1,2,3"), ("system", "svm"),
            ("grasp_depth_mm", -5), ("object_width_mm", [30]), ("token", 7), ("auto", "true"))


def generate(rng: random.Random) -> tuple[bytes, set[str]]:
    """One malformed request line (no newline inside) and the error codes it may get."""
    kind = rng.randrange(9)
    if kind == 0:  # random bytes
        return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 120))).replace(
            b"\n", b" "), {"bad_json", "bad_request", "unknown_command"}
    if kind == 1:  # truncated request
        text = json.dumps({"cmd": "acquire", "args": {"set": "nn1"}, "id": 5})
        return text[:rng.randrange(len(text) - 1)].encode(), {"bad_json"}
    if kind == 2:  # JSON that is not an object
        value = rng.choice([1, -2.5, "status", [], ["status"], None, True, {"a": [1]}])
        codes = {"bad_json", "bad_request"}
        return json.dumps(value).encode(), codes
    if kind == 3:  # a broken envelope
        value = rng.choice([{}, {"cmd": 5}, {"cmd": None}, {"cmd": "status", "args": []},
                            {"cmd": "status", "extra": 1}, {"cmd": "status", "id": [1]},
                            {"cmd": "status", "id": "x" * 100}, {"cmd": "status", "id": 2**60},
                            {"cmd": "status", "args": "x"}])
        return json.dumps(value).encode(), {"bad_request"}
    if kind == 4:  # an unknown command
        name = "".join(rng.choice("abcdefghijk_ .") for _ in range(rng.randrange(1, 20)))
        codes = {"unknown_command"} if name not in COMMANDS else {"bad_request"}
        return json.dumps({"cmd": name + "!"}).encode(), codes
    if kind == 5:  # a bad argument
        name, value = rng.choice(BAD_ARGS)
        request = {"cmd": rng.choice(sorted(COMMANDS)), "args": {name: value}, "id": 1}
        return json.dumps(request).encode(), {"bad_request", "bad_json"}  # 1e999: Infinity
    if kind == 6:  # longer than the limit
        size = rng.randrange(MAX_REQUEST_BYTES, 3 * MAX_REQUEST_BYTES)
        text = json.dumps({"cmd": "status", "id": "x" * size})
        return text.encode(), {"too_large"}
    if kind == 7:  # numbers JSON does not allow, deep nesting, bad UTF-8
        return rng.choice([b'{"cmd": "position", "args": {"max_loops": NaN}}',
                           b'{"cmd": "position", "args": {"max_loops": Infinity}}',
                           b"[" * 1500, b'{"cmd": "st\xffatus"}', b"",
                           b'{"cmd": "status", "args": {"a": ' * 60]), \
            {"bad_json", "bad_request"}
    return b"\x00" * rng.randrange(1, 50), {"bad_json"}


def test_ten_thousand_malformed_requests_get_errors_and_status_still_works(service, fakes):
    rng = random.Random(6)
    counts: dict[str, int] = {}
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as raw:
        raw.settimeout(EVENT_TIMEOUT_S)
        raw.connect(str(service.socket_path))
        replies = raw.makefile("rb")
        for _ in range(GENERATED):
            line, codes = generate(rng)
            assert b"\n" not in line
            raw.sendall(line + b"\n")
            response = json.loads(replies.readline())
            assert response["ok"] is False, (line[:80], response)
            assert response["error"]["code"] in codes, (line[:80], response)
            counts[response["error"]["code"]] = counts.get(response["error"]["code"], 0) + 1
        raw.sendall(b'{"cmd": "status", "id": "after"}\n')
        after = json.loads(replies.readline())
    assert after["ok"] and after["id"] == "after" and after["result"]["state"] == "idle"
    assert sum(counts.values()) == GENERATED and {"bad_json", "bad_request", "too_large",
                                                  "unknown_command"} <= set(counts)
    assert fakes[0].moves == [], "no malformed request may move the arm"
    with client_for(service) as client:
        assert client.call("status")["state"] == "idle"


def test_error_responses_echo_the_request_id(service):
    with client_for(service) as client:
        response = client.send_line(b'{"cmd": "acquire", "args": {"set": "x"}, "id": "r-1"}')
    assert response == {"id": "r-1", "ok": False, "error": {
        "code": "bad_request", "message": "acquire: set: one of nn1, nn2, test, got 'x'"}}


def test_concurrent_clients_are_all_served(service):
    failures: list[str] = []
    served = [0] * 8
    start = threading.Barrier(9)

    def hammer(index: int) -> None:
        with client_for(service) as client:
            start.wait(EVENT_TIMEOUT_S)
            for n in range(100):
                response = client.request("status", timeout_s=EVENT_TIMEOUT_S)
                if not response["ok"] or response["id"] != n + 1:
                    failures.append(repr(response)[:200])
                served[index] += 1

    def garbage() -> None:
        with client_for(service) as client:
            start.wait(EVENT_TIMEOUT_S)
            for _ in range(200):
                if client.send_line(b"{not json")["ok"]:
                    failures.append("garbage accepted")

    threads = [threading.Thread(target=hammer, args=(i,)) for i in range(8)]
    threads.append(threading.Thread(target=garbage))
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(EVENT_TIMEOUT_S)
    assert not failures and served == [100] * 8


def test_clients_beyond_the_limit_get_only_abort_and_status_once(tmp_path, short_dir, fakes):
    config = service_config(tmp_path, short_dir, service={"max_clients": 2})
    with running_service(config, device_opener(*fakes)) as service, \
            client_for(service) as first, client_for(service) as second:
        assert first.call("status") and second.call("status")
        with client_for(service) as third, pytest.raises(ServiceError) as refused:
            third.call("teach", auto=False)
        assert refused.value.code == "too_many_clients"
        assert "only abort and status" in refused.value.message
        with client_for(service) as fourth:
            assert fourth.call("status")["state"] == "idle"
            with pytest.raises(ServiceUnavailable):  # one request, then closed
                fourth.call("status")
        with client_for(service) as fifth:
            assert fifth.call("abort")["halted"] is True


@pytest.fixture
def token_file(tmp_path):
    path = tmp_path / "token"
    path.write_text("s3cret-token-0123456789\n")
    path.chmod(0o600)
    return path


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_tcp_listener_is_loopback_only_and_needs_the_token(tmp_path, short_dir, fakes,
                                                          token_file):
    port = free_port()
    config = service_config(tmp_path, short_dir, service={
        "tcp": {"port": port, "token_file": str(token_file)}})
    with running_service(config, device_opener(*fakes)):
        with ServiceClient(tcp=("127.0.0.1", port), timeout_s=EVENT_TIMEOUT_S) as anonymous:
            assert anonymous.request("status")["error"]["code"] == "unauthorized"
        with pytest.raises(ServiceError, match="unauthorized"):
            ServiceClient(tcp=("127.0.0.1", port), token="wrong-token-0123456789")
        with ServiceClient(tcp=("127.0.0.1", port), token=read_token(token_file),
                           timeout_s=EVENT_TIMEOUT_S) as client:
            assert client.call("status")["state"] == "idle"


def test_tcp_config_refuses_other_hosts_and_open_token_files(tmp_path, short_dir, token_file):
    with pytest.raises(ConfigError, match="service.tcp: host: the TCP listener must be bound"):
        service_config(tmp_path, short_dir, service={
            "tcp": {"host": "0.0.0.0", "port": 7878, "token_file": str(token_file)}})
    token_file.chmod(0o644)
    with pytest.raises(ConfigError, match="must not be accessible to group or others"):
        read_token(token_file)


@pytest.mark.parametrize("kind", ["fifo", "device", "too large", "not utf-8"])
def test_token_files_are_read_bounded_and_never_block(tmp_path, kind):
    path = tmp_path / "token"
    if kind == "fifo":
        os.mkfifo(path, 0o600)  # no writer: a blocking open would never return
        expected = "token_file: .*not a regular file \\(a FIFO\\)"
    elif kind == "device":
        path = Path("/dev/zero")
        expected = "token_file: /dev/zero: not a regular file \\(a character device\\)"
    elif kind == "too large":
        path.write_text("s3cret-token-0123456789\n" + "x" * 10**6)
        expected = "token_file: .*larger than 4096 bytes"
    else:
        path.write_bytes(b"\xff" * 20)
        expected = "token_file: .* is not UTF-8 text"
    if path.exists() and not path.is_char_device():
        path.chmod(0o600)
    with pytest.raises(ConfigError, match=expected):
        read_token(path)


def test_a_second_service_on_the_same_tcp_port_leaves_no_socket_file(tmp_path, short_dir, fakes,
                                                                      token_file):
    from controller.service.listeners import ListenerError

    port = free_port()
    config = service_config(tmp_path, short_dir, service={
        "tcp": {"port": port, "token_file": str(token_file)}})
    second = service_config(tmp_path / "second", short_dir, service={
        "socket_path": str(short_dir / "second.sock"),
        "tcp": {"port": port, "token_file": str(token_file)}})
    with running_service(config, device_opener(*fakes)):
        with pytest.raises(ListenerError, match=f"service.tcp: cannot listen on 127.0.0.1:{port}"):
            Service(second, opener=device_opener(FakeArm(), FakeCamera(),
                                                 FakeWrenchSensor())).run()
        assert not (short_dir / "second.sock").exists()
