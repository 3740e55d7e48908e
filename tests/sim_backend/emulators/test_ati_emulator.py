"""The emulated ATI F/T controller: its command set, streaming over a real pty, the command."""

from __future__ import annotations

import signal
import struct
import subprocess
import sys

import pytest
import serial

from drivers.ati import AtiConfig, AtiWrenchSensor
from drivers.ati.protocol import parse_query_reply, parse_record
from drivers.interfaces import Wrench
from sim_backend.emulators.ati.emulator import AtiEmulator
from sim_backend.emulators.ati.protocol import AtiController
from tests.mocks.fakes import FakeWrenchSensor

LOAD = Wrench(1.0, -2.0, 3.0, 0.3, -0.6, 0.9)
COUNTS = (20, -40, 60, 100, -200, 300)  # LOAD in counts at 20 / 333.33


@pytest.fixture
def backing():
    with FakeWrenchSensor(lambda: LOAD) as sensor:
        yield sensor


@pytest.fixture
def controller(backing):
    return AtiController(backing)


def query(controller: AtiController) -> bytes:
    return controller.execute("QR")


def test_ascii_record_in_the_manual_layout(controller):
    assert query(controller) == (b"QR\r\n0,    20,   -40,    60,   100,  -200,   300\r\n>")
    assert parse_query_reply("QR", query(controller)).counts == COUNTS


def test_bias_stack(controller, backing):
    controller.execute("SB")
    assert parse_query_reply("QR", query(controller)).counts == (0,) * 6
    controller.execute("SU")
    assert parse_query_reply("QR", query(controller)).counts == COUNTS
    controller.execute("sb")
    controller.execute("SZ")
    assert parse_query_reply("QR", query(controller)).counts == COUNTS


def test_output_modes(controller):
    controller.execute("CL 0")
    assert controller.execute("CD A") == b"CD A\r>"
    controller.execute("CV 5")  # Fx and Fz
    assert query(controller) == b"QR\r0,    20,    60\r>"
    controller.execute("CV 3F")
    controller.execute("CD H")
    assert query(controller) == b"QR\r0,0014,FFD8,003C,0064,FF38,012C\r>"
    controller.execute("CD D")
    controller.execute("SB")
    assert parse_record(query(controller)[3:-2].decode()).counts == COUNTS, \
        "gauges are unbiased"
    controller.execute("CD R")
    controller.execute("SZ")
    controller.execute("CD B")
    reply = query(controller)
    assert reply[3:-1] == struct.pack(">H6h", 0, *COUNTS)


def test_moving_average_reads_n_samples(controller, backing):
    controller.execute("SA 4")
    before = next(backing.count)
    query(controller)
    assert next(backing.count) - before == 1 + 4


@pytest.mark.parametrize("line", ["XY", "CD Q", "SA x", "CL 2", "CV"])
def test_bad_commands_answer_with_an_error_line(controller, line):
    reply = controller.execute(line)
    assert reply.startswith(line.encode() + b"\r\nError: ") and reply.endswith(b"\r\n>")


def test_failing_backing_sensor_answers_an_error(backing):
    backing.disconnect()
    reply = AtiController(backing).execute("QR")
    assert b"Error: " in reply and reply.endswith(b">")


def test_stream_runs_until_a_carriage_return(backing):
    with AtiEmulator(backing, stream_period_s=0.01) as emu, \
            serial.serial_for_url(emu.url, timeout=5.0) as port:
        port.write(b"QS\r")
        assert port.read_until(b"\r\n") == b"QS\r\n"
        records = [parse_record(port.read_until(b"\r\n").decode()) for _ in range(3)]
        assert all(r.counts == COUNTS for r in records)
        port.write(b"\r")
        tail = port.read_until(b">")
        assert tail.endswith(b"\r\n>")
        assert not emu.controller.streaming
        port.write(b"QR\r")
        assert parse_query_reply("QR", port.read_until(b">")).counts == COUNTS


@pytest.mark.slow
def test_command_serves_the_simulated_sensor_until_sigterm():
    with subprocess.Popen([sys.executable, "-m", "controller.cli", "sim", "ati-emulator"],
                          stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                          text=True) as process:
        assert process.stdout is not None
        port = process.stdout.readline().strip()
        try:
            with AtiWrenchSensor(AtiConfig(port=port)) as sensor:
                sensor.bias()
                assert sensor.read().force_n < 0.5
        finally:
            process.send_signal(signal.SIGTERM)
        assert process.wait(10) == 0


# -- monitor conditions ----------------------------------------------------------------------
def test_a_monitor_condition_drives_its_output_on_the_biased_reading(controller, backing):
    assert not controller.output_high(1)  # no condition: low
    assert controller.execute("MC FZ GT 50 1") == b"MC FZ GT 50 1\r\n>"
    assert controller.output_high(1)  # Fz 60 counts > 50
    assert not controller.output_high(2)
    controller.execute("SB")  # biased: Fz 0 counts
    assert not controller.output_high(1)
    controller.execute("MC FX LT 5 2")
    assert controller.output_high(2)
    controller.execute("MC")
    assert not controller.output_high(1) and not controller.output_high(2)


@pytest.mark.parametrize("line", ["MC FZ 50 1", "MC QQ LT 5 1", "MC FZ LT x 1", "MC FZ < 5 1",
                                  "MC FZ LT 5 9"])
def test_a_bad_monitor_condition_is_an_error_line(controller, line):
    assert b"Error:" in controller.execute(line)
