"""The ATI F/T driver against the emulated controller over a real pty (backed by a fake and by
the simulated wrist sensor): contract, scaling, start-up, every fault knob and recovery."""

from __future__ import annotations

import pytest

from drivers.ati import AtiConfig, AtiStatusError, AtiWrenchSensor
from drivers.contract import check_wrench
from drivers.core.errors import (
    ConfigError,
    DeviceFaultError,
    DeviceNotConnectedError,
    DeviceTimeoutError,
    ProtocolError,
)
from drivers.core.typed_config import from_mapping
from drivers.interfaces import Lifecycle, Wrench
from sim_backend.cell.scene_config import SceneConfig
from sim_backend.cell.sim_cell import SimCell
from sim_backend.devices import SimWrenchSensor
from sim_backend.emulators.ati.emulator import AtiEmulator
from tests.mocks.fakes import FakeWrenchSensor

LOAD = Wrench(1.5, -2.25, 9.81, 0.12, -0.2, 0.05)
WAIT_S = 5.0  # generous bound for the emulator thread; no assertion depends on it


@pytest.fixture
def emulator():
    with FakeWrenchSensor(lambda: LOAD) as backing, AtiEmulator(backing) as emu:
        yield emu


def make_sensor(emu: AtiEmulator, **overrides) -> AtiWrenchSensor:
    return AtiWrenchSensor(AtiConfig(port=emu.url, **overrides))


def assert_close(w: Wrench, expected: Wrench) -> None:
    for name, value in w.as_dict().items():
        resolution = 1 / 20.0 if name.startswith("f") else 1 / 333.33
        assert value == pytest.approx(getattr(expected, name), abs=resolution), name


def test_driver_meets_wrench_contract_over_a_socket_url():
    # (over a pty: the backend contract test, tests/controller/test_backend_contract.py)
    with FakeWrenchSensor(lambda: LOAD) as backing, AtiEmulator(backing, tcp_port=0) as emu:
        assert emu.url.startswith("socket://127.0.0.1:")
        check_wrench(lambda: make_sensor(emu))


def test_readings_are_counts_scaled_by_the_calibration(emulator):
    with make_sensor(emulator) as sensor:
        assert_close(sensor.read(), LOAD)
        sensor.bias()
        assert_close(sensor.read(), Wrench(0, 0, 0, 0, 0, 0))


def test_startup_restores_ascii_resolved_output(emulator):
    emulator.controller.execute("CD B")
    emulator.controller.execute("CD H")
    with make_sensor(emulator) as sensor:
        assert emulator.controller.mode.ascii and emulator.controller.mode.data == "resolved"
        assert_close(sensor.read(), LOAD)


def test_startup_ends_a_stream_left_running(emulator):
    emulator.controller.execute("QS")
    with make_sensor(emulator) as sensor:
        assert not emulator.controller.streaming
        assert_close(sensor.read(), LOAD)


def test_configured_startup_commands_are_sent(emulator):
    with make_sensor(emulator, startup_commands=("CD A", "CD R", "SA 4")):
        assert emulator.controller.average_n == 4


def test_config_loads_strictly_with_key_paths():
    cfg = from_mapping(AtiConfig, {"port": "loop://", "counts_per_force": 40}, "wrench")
    assert cfg.counts_per_force == 40.0 and cfg.baud == 9600
    with pytest.raises(ConfigError, match=r"^wrench\.baudrate: unknown key"):
        from_mapping(AtiConfig, {"port": "loop://", "baudrate": 9600}, "wrench")
    with pytest.raises(ConfigError, match=r"^wrench\.counts_per_torque: must be > 0"):
        from_mapping(AtiConfig, {"port": "loop://", "counts_per_torque": 0}, "wrench")
    with pytest.raises(ConfigError, match="startup_commands"):
        from_mapping(AtiConfig, {"port": "loop://", "startup_commands": ["SB\rQS"]}, "wrench")


def test_unopenable_port_is_not_connected():
    sensor = AtiWrenchSensor(AtiConfig(port="/dev/does-not-exist"))
    with pytest.raises(DeviceNotConnectedError, match="cannot open"):
        sensor.connect()
    assert sensor.state is Lifecycle.DISCONNECTED


def test_silent_line_times_out_at_startup():
    # loop:// echoes what we send but never prints a prompt: the start-up must give up.
    sensor = AtiWrenchSensor(AtiConfig(port="loop://", timeout_s=0.05))
    with pytest.raises((DeviceTimeoutError, ProtocolError)):
        sensor.connect()
    assert sensor.state is Lifecycle.DISCONNECTED


def expect_fault_then_recover(emulator, sensor, error_type, clear_knob) -> None:
    with pytest.raises(error_type):
        sensor.read()
    assert sensor.state is Lifecycle.FAULT and sensor.fault_reason
    with pytest.raises(DeviceFaultError):
        sensor.read()
    with pytest.raises(DeviceFaultError):
        sensor.bias()
    clear_knob()
    sensor.reset()
    assert sensor.state is Lifecycle.INACTIVE
    assert_close(sensor.read(), LOAD)


def test_reply_delay_beyond_timeout_faults_until_reset(emulator):
    sensor = make_sensor(emulator, timeout_s=0.3)
    with sensor:
        emulator.faults.reply_delay_s = 0.9
        sent = emulator.replies_sent

        def clear():
            assert emulator.wait_replies(sent + 1, WAIT_S), "the late reply never came"
            emulator.faults.reply_delay_s = 0.0

        expect_fault_then_recover(emulator, sensor, DeviceTimeoutError, clear)


def test_garbage_is_a_protocol_error_and_faults(emulator):
    with make_sensor(emulator) as sensor:
        emulator.faults.garbage = True

        def clear():
            emulator.faults.garbage = False

        expect_fault_then_recover(emulator, sensor, ProtocolError, clear)


def test_nonzero_status_word_is_a_fault_with_the_status(emulator):
    with make_sensor(emulator) as sensor:
        emulator.faults.status_word = 0x24
        with pytest.raises(AtiStatusError) as info:
            sensor.read()
        assert info.value.status == 0x24 and isinstance(info.value, DeviceFaultError)
        assert sensor.state is Lifecycle.FAULT
        emulator.faults.status_word = 0
        sensor.reset()
        assert_close(sensor.read(), LOAD)


def test_dropped_link_times_out_and_reconnect_waits_for_the_link(emulator):
    sensor = make_sensor(emulator, timeout_s=0.3)
    with sensor:
        emulator.faults.drop_after = emulator.commands_received + 1
        assert_close(sensor.read(), LOAD)
        with pytest.raises(DeviceTimeoutError):
            sensor.read()
        assert sensor.state is Lifecycle.FAULT
        with pytest.raises(DeviceTimeoutError):
            sensor.reset()  # the cable is still out
        with pytest.raises(DeviceNotConnectedError):
            sensor.read()
        emulator.faults.drop_after = None
        sensor.connect()
        assert_close(sensor.read(), LOAD)


def test_dropped_tcp_link_is_a_lost_link_fault():
    with FakeWrenchSensor(lambda: LOAD) as backing, AtiEmulator(backing, tcp_port=0) as emu:
        assert emu.url.startswith("socket://127.0.0.1:")
        with make_sensor(emu) as sensor:
            emu.faults.drop_after = emu.commands_received
            with pytest.raises(DeviceFaultError, match="link lost"):
                sensor.read()
            assert sensor.state is Lifecycle.FAULT
            emu.faults.drop_after = None
            sensor.reset()
            assert_close(sensor.read(), LOAD)


def test_driver_meets_wrench_contract_on_the_simulated_wrist_sensor():
    with SimCell(SceneConfig()) as cell, SimWrenchSensor(cell) as backing, \
            AtiEmulator(backing) as emu:
        with make_sensor(emu) as sensor:
            reading = sensor.read()  # unbiased: the controller keeps a bias across connections
        expected = Wrench(*cell.wrench(noisy=False))
        for name, value in reading.as_dict().items():
            noise = 0.2 if name.startswith("f") else 0.02  # sensor noise and count resolution
            assert value == pytest.approx(getattr(expected, name), abs=noise), name
        check_wrench(lambda: make_sensor(emu))


def test_read_mean_is_one_query_under_the_controllers_own_average(emulator):
    with make_sensor(emulator, startup_commands=("CD A", "CD R", "SA 2")) as sensor:
        before = emulator.commands_received
        assert_close(sensor.read_mean(16), LOAD)
        assert emulator.commands_received - before == 3  # SA 16, QR, SA 2
        assert emulator.controller.average_n == 2


def test_the_monitor_condition_goes_to_the_controller_in_counts(emulator):
    from drivers.interfaces import MonitorCondition

    with make_sensor(emulator) as sensor:
        sensor.set_monitor_condition(MonitorCondition("fz_n", "<", -3.0))
        assert emulator.controller.conditions == {1: (2, "LT", -60)}
        assert not emulator.controller.output_high(1)  # Fz +9.81 N
        sensor.set_monitor_condition(MonitorCondition("fz_n", ">", 5.0))
        assert emulator.controller.output_high(1)
        sensor.set_monitor_condition(None)
        assert emulator.controller.conditions == {}


def test_the_guard_setup_runs_in_a_thread_of_its_own_and_hands_back_the_mean(emulator):
    from drivers.interfaces import MonitorCondition

    with make_sensor(emulator) as sensor:
        setup = sensor.prepare_contact_guard(MonitorCondition("fz_n", "<", -3.0), 16)
        assert setup.background
        assert_close(setup.wait(), Wrench(0, 0, 0, 0, 0, 0))  # the mean after the bias
        assert emulator.controller.conditions == {1: (2, "LT", -60)}
        assert_close(sensor.read(), Wrench(0, 0, 0, 0, 0, 0))  # the line is free again


def test_a_guard_setup_that_fails_raises_at_the_wait_and_faults(emulator):
    from drivers.interfaces import MonitorCondition

    sensor = make_sensor(emulator, timeout_s=0.3)
    with sensor:
        emulator.faults.garbage = True
        setup = sensor.prepare_contact_guard(MonitorCondition("fz_n", "<", -3.0), 16)
        setup.join()
        with pytest.raises(ProtocolError):
            setup.wait()
        assert sensor.state is Lifecycle.FAULT
        emulator.faults.garbage = False
