"""The Magellan emulator on its own: wire encoding, probe answers, playback, script files."""

from __future__ import annotations

import os
import sys
import tty

import pytest
import serial

from drivers.core.errors import ConfigError
from sim_backend.emulators.magellan.emulator import DEFAULT_VERSION, MagellanEmulator
from sim_backend.emulators.magellan.keyboard import drive_from_keyboard, steps_for_key
from sim_backend.emulators.magellan.protocol import encode_buttons, encode_motion
from sim_backend.emulators.magellan.script import Button, Motion, click, load_script

TIMEOUT_S = 5.0


def decode_motion_as_spacenavd(packet: bytes) -> list[int]:
    """What spacenavd 1.1 makes of a ``d`` packet (hardware notes): char & 0x0F nibbles,
    word - 0x8000, then Z and rZ negated."""
    assert packet[:1] == b"d" and packet[-1:] == b"\r" and len(packet) == 26
    body = packet[1:-1]
    values = []
    for i in range(6):
        word = 0
        for ch in body[4 * i: 4 * i + 4]:
            word = (word << 4) | (ch & 0x0F)
        values.append(word - 0x8000)
    return [v * s for v, s in zip(values, (1, 1, -1, 1, 1, -1), strict=True)]


@pytest.mark.parametrize("axes", [(0, 0, 0, 0, 0, 0), (1, -1, 350, -350, 32767, -32767),
                                  (-32768, 0, 12, 34, -56, 78)])
def test_motion_round_trips_through_the_daemons_decoding(axes):
    assert decode_motion_as_spacenavd(encode_motion(axes)) == list(axes)


def test_wire_uses_the_magellan_nibble_table_and_negates_z():
    assert encode_motion((0, 0, 0, 0, 0, 0)) == b"d" + b"H000" * 6 + b"\r"
    assert encode_motion((0, 0, 1, 0, 0, 0))[9:13] == b"G???"  # -1 -> 0x7FFF


def test_button_packets():
    assert encode_buttons([]) == b"k000\r"
    assert encode_buttons([0]) == b"kA00\r"
    assert encode_buttons([5, 11]) == b"k0BH\r"  # nibbles 0x0, 0x2, 0x8
    with pytest.raises(ValueError):
        encode_buttons([12])
    with pytest.raises(ValueError):
        encode_motion((40000, 0, 0, 0, 0, 0))


@pytest.fixture
def line():
    """The emulator and a serial port on its pty playing spacenavd's side."""
    with MagellanEmulator(report_period_s=0.01) as mouse, \
            serial.serial_for_url(mouse.url, timeout=TIMEOUT_S) as port:
        yield mouse, port


def probe(mouse: MagellanEmulator, port) -> None:
    port.write(b"\r@RESET\r")
    assert port.read_until(b"?\r") == b"\r?\r"
    port.write(b"vQ\r")
    assert port.read_until(b"\r") == DEFAULT_VERSION.encode() + b"\r"
    assert not mouse.wait_ready(0.0)
    port.write(b"m3\r")
    assert mouse.wait_ready(TIMEOUT_S)


def test_answers_the_probe_in_order_and_nothing_before(line):
    mouse, port = line
    probe(mouse, port)
    assert mouse.probe_log == ["@RESET", "vQ", "m3"]


def test_plays_motion_then_springs_back_and_buttons(line):
    mouse, port = line
    probe(mouse, port)
    mouse.play([Motion((100, 0, -20, 0, 0, 5), 0.05), *click(3)])
    assert mouse.wait_done(TIMEOUT_S)
    packets = []
    while port.in_waiting or not packets or packets[-1] != encode_motion((0,) * 6):
        packets.append(port.read_until(b"\r"))
    motions = [decode_motion_as_spacenavd(p) for p in packets if p.startswith(b"d")]
    keys = [p for p in packets if p.startswith(b"k")]
    assert motions[0] == [100, 0, -20, 0, 0, 5] and motions[-1] == [0] * 6
    assert set(map(tuple, motions[:-1])) == {(100, 0, -20, 0, 0, 5)}, "repeats while held"
    assert keys == [encode_buttons([3]), encode_buttons([])]


def test_nothing_is_played_before_the_daemon_is_ready(line):
    mouse, port = line
    mouse.play([Button(0, True)])
    assert not mouse.wait_done(0.05)
    probe(mouse, port)
    assert mouse.wait_done(TIMEOUT_S)
    assert port.read_until(b"\r") == encode_buttons([0])


def test_script_file(tmp_path):
    path = tmp_path / "jog.yaml"
    path.write_text("steps:\n"
                    "  - {axes: [120, 0, 0, 0, 0, 0], duration_s: 1.5}\n"
                    "  - {button: 0, pressed: true}\n"
                    "  - {button: 0, pressed: false}\n")
    assert load_script(path) == [Motion((120, 0, 0, 0, 0, 0), 1.5), *click(0)]
    path.write_text("steps:\n  - {axes: [1, 2, 3], duration_s: 1}\n")
    with pytest.raises(ConfigError, match=r"steps\[0\]"):
        load_script(path)


@pytest.mark.parametrize("key, expected", [
    ("d", [Motion((150, 0, 0, 0, 0, 0), 0.1)]),
    ("s", [Motion((0, 0, -150, 0, 0, 0), 0.1)]),
    ("q", [Motion((0, 0, 0, 0, 150, 0), 0.1)]),
    ("7", click(7)),
    ("x", []),
    ("\x1b", None),
])
def test_keyboard_keys(key, expected):
    assert steps_for_key(key, 150, 0.1) == expected


def test_keyboard_drives_the_mouse_from_a_terminal(line, monkeypatch):
    mouse, port = line
    probe(mouse, port)
    master, slave = os.openpty()
    tty.setcbreak(slave)  # as a user's terminal would be by the time keys are typed
    with os.fdopen(slave, "rb", buffering=0) as terminal:
        monkeypatch.setattr(sys, "stdin", terminal)
        os.write(master, b"d\x1b")
        drive_from_keyboard(mouse, deflection=150, hold_s=0.05)
        assert mouse.wait_done(TIMEOUT_S)
        os.write(master, b"2\x04")
        drive_from_keyboard(mouse)
        assert mouse.wait_done(TIMEOUT_S)
    os.close(master)
    packets = []
    while port.in_waiting or not packets or packets[-1] != encode_buttons([]):
        packets.append(port.read_until(b"\r"))
    motions = {tuple(decode_motion_as_spacenavd(p)) for p in packets if p.startswith(b"d")}
    assert motions == {(150, 0, 0, 0, 0, 0), (0,) * 6}
    assert [p for p in packets if p.startswith(b"k")] == [encode_buttons([2]), encode_buttons([])]
