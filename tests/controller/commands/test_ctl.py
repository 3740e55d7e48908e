"""``finepos ctl`` against bad arguments and a server that is not (or no longer) the finepos
service: one line on stderr and a non-zero exit, never an internal error, never a hang past
--timeout, never an unbounded read."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from controller import cli
from controller.service.client import MAX_LINE_BYTES

WAIT_S = 10.0  # bounds only


@contextmanager
def fake_server(path: Path, answer: Callable[[socket.socket, threading.Event], None]) \
        -> Iterator[None]:
    """A UNIX socket at ``path`` whose one connection is served by ``answer`` (after the
    request line) until the test ends."""
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(str(path))
    listener.listen(1)
    done = threading.Event()

    def serve() -> None:
        conn, _ = listener.accept()
        with conn:
            conn.makefile("rb").readline()
            try:
                answer(conn, done)
            except OSError:
                pass  # the client went away

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        listener.close()
        thread.join(WAIT_S)


def run_ctl(capsys, *argv: str) -> tuple[int, list[str]]:
    try:
        status = cli.main(["ctl", *argv])
    except SystemExit as exc:  # argparse
        status = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    return status, err


@pytest.mark.parametrize("argv", [["--timeout", "-1", "status"], ["--timeout", "nan", "status"],
                                  ["--timeout", "1e400", "status"], ["--timeout", "0", "status"],
                                  ["stream", "--count", "0"], ["stream", "--count", "-5"]])
def test_bad_arguments_are_refused_by_ctl_itself(capsys, argv):
    status, err = run_ctl(capsys, "--socket", "/nonexistent/fp.sock", *argv)
    assert status == 2 and "expected a" in err[-1]
    assert not any("internal error" in line for line in err)


@pytest.mark.parametrize("tcp", ["127.0.0.1:99999", "127.0.0.1:²"])
def test_a_bad_tcp_port_is_one_line(capsys, tmp_path, tcp):
    status, err = run_ctl(capsys, "--tcp", tcp, "--token-file", str(tmp_path / "t"), "status")
    assert status == 2 and "--tcp: expected HOST:PORT" in err[-1]


def test_a_token_file_that_never_ends_is_refused(capsys):
    status, err = run_ctl(capsys, "--tcp", "127.0.0.1:7878", "--token-file", "/dev/zero",
                          "status")
    assert status == 2 and err == ["finepos: error: service.tcp.token_file: /dev/zero: not a "
                                   "regular file (a character device)"]


def garbage(conn: socket.socket, done: threading.Event) -> None:
    conn.sendall(b"<html>not json</html>\n")
    done.wait(WAIT_S)


def endless(conn: socket.socket, done: threading.Event) -> None:
    while not done.wait(0.01):  # a byte every 10 ms: no socket timeout ever fires
        conn.sendall(b"x")


def too_long(conn: socket.socket, done: threading.Event) -> None:
    conn.sendall(b"[" * (MAX_LINE_BYTES + 10))
    done.wait(WAIT_S)


def not_an_object(conn: socket.socket, done: threading.Event) -> None:
    conn.sendall(b"[1, 2]\n")
    done.wait(WAIT_S)


@pytest.mark.parametrize(("answer", "text"), [
    (garbage, "the service sent a line that is not JSON"),
    (endless, "no complete answer from the service within 0.5 s"),
    (too_long, f"the service sent a line longer than {MAX_LINE_BYTES} bytes"),
    (not_an_object, "the service sent list, not a JSON object"),
])
def test_a_server_that_is_not_the_service_is_one_line(capsys, tmp_path, answer, text):
    path = tmp_path / "fp.sock"
    with fake_server(path, answer):
        t0 = time.monotonic()
        status, err = run_ctl(capsys, "--socket", str(path), "--timeout", "0.5", "status")
        elapsed_s = time.monotonic() - t0
    assert status == 2 and err[-1].startswith("finepos: error: " + text), err
    assert elapsed_s < 0.5 + WAIT_S / 2
    if answer is endless:
        assert elapsed_s < 2.0, f"--timeout 0.5 ignored: {elapsed_s:.1f} s"


def test_stream_count_stops_after_n_events(capsys, tmp_path):
    def events(conn: socket.socket, done: threading.Event) -> None:
        conn.sendall(b'{"id": 1, "ok": true, "result": {"streaming": true}}\n')
        while not done.wait(0.01):
            conn.sendall(b'{"event": "state", "state": "idle"}\n')

    path = tmp_path / "fp.sock"
    with fake_server(path, events):
        assert cli.main(["ctl", "--socket", str(path), "stream", "--count", "3"]) == 0
    assert len(capsys.readouterr().out.strip().splitlines()) == 3
