"""The VAL emulator's listeners (what the arm really received, and when a fault knob acted) and
its TCP link closing with a client still connected."""

from __future__ import annotations

import threading

import pytest
import serial

from sim_backend.emulators.val.server import DEFAULT_GARBAGE, ValEmulator, ValFaults
from tests.mocks.fakes import FakeArm

WAIT_S = 5.0  # bound on waiting for the emulator thread; no assertion depends on it


class Heard:
    """Collects (event, text) pairs from the serving thread."""

    def __init__(self) -> None:
        self.events: list[tuple[str, str]] = []
        self.changed = threading.Condition()

    def __call__(self, event: str, text: str) -> None:
        with self.changed:
            self.events.append((event, text))
            self.changed.notify_all()

    def wait_for(self, pair: tuple[str, str]) -> None:
        with self.changed:
            assert self.changed.wait_for(lambda: pair in self.events, WAIT_S), self.events


@pytest.fixture
def backing():
    with FakeArm() as arm:
        yield arm


def read_prompt(port: serial.Serial) -> bytes:
    data = b""
    while not data.endswith(b"\r\n."):
        chunk = port.read(1)
        assert chunk, f"no prompt: {data!r}"
        data += chunk
    return data


def test_listener_hears_each_line_run_and_its_end(backing):
    heard = Heard()
    with ValEmulator(backing, tcp_port=0) as emu:
        emu.add_listener(heard)
        with serial.serial_for_url(emu.url, timeout=WAIT_S) as port:
            port.write(b"where\r")
            read_prompt(port)
    assert heard.events[:2] == [("command", "where"), ("done", "where")]


def test_listener_hears_garbage_and_a_dropped_link(backing):
    heard = Heard()
    with ValEmulator(backing, tcp_port=0) as emu:
        emu.add_listener(heard)
        emu.set_faults(ValFaults(garbage=DEFAULT_GARBAGE))
        with serial.serial_for_url(emu.url, timeout=WAIT_S) as port:
            port.write(b"where\r")
            heard.wait_for(("fault", "garbage"))
            emu.set_faults(ValFaults(drop_link_after_lines=0))
            port.write(b"do ready\r")
            heard.wait_for(("fault", "link_drop"))
    assert ("command", "do ready") not in heard.events  # a dropped line never runs


def test_listener_hears_a_held_back_reply(backing):
    heard = Heard()
    with ValEmulator(backing, tcp_port=0) as emu:
        emu.add_listener(heard)
        emu.set_faults(ValFaults(reply_delay_s=60.0))
        with serial.serial_for_url(emu.url, timeout=WAIT_S) as port:
            port.write(b"where\r")
            heard.wait_for(("fault", "reply_delay"))
            emu.set_faults(ValFaults())  # ends the delay: the reply comes now
            read_prompt(port)


def test_close_with_a_tcp_client_connected(backing):
    emu = ValEmulator(backing, tcp_port=0).start()
    port = serial.serial_for_url(emu.url, timeout=WAIT_S)
    try:
        port.write(b"where\r")
        read_prompt(port)
        emu.close()  # must not fail on the client still connected
    finally:
        port.close()
