"""A stop (SIGTERM) never waits on a device: the whole run ends within service.stop_timeout_s +
0.5 s, not at an exchange's or a job's end, in every device state: idle with a silent VAL link,
reconnecting after a fault, in fault, mid-move (a move the arm finishes whatever the halt),
training (which cannot be interrupted) and recording (the recording completed)."""

from __future__ import annotations

import threading
import time

import pytest
from mcap.reader import make_reader

from controller.service.jobs import BODIES
from controller.service.service import Service
from drivers.core.pose import ToolStep
from drivers.safety import SafetyLimits
from drivers.val import ValArm, ValConfig
from sim_backend.emulators.val.server import DEFAULT_GARBAGE, ValEmulator, ValFaults
from tests.controller.service.conftest import (
    EVENT_TIMEOUT_S,
    NOMINAL,
    START_TIMEOUT_S,
    client_for,
    copy_state,
    cube_view,
    device_opener,
    service_config,
    wait_for_state,
)
from tests.mocks.fakes import FakeArm, FakeCamera, FakeWrenchSensor

SLOW_LINK_TIMEOUT_S = 20.0  # the exchange a stop must not wait for (as on the real cell)
MARGIN_S = 0.5  # the target: stop_timeout_s + 0.5 s


def timed_stop(service: Service, thread: threading.Thread) -> float:
    """Seconds from ``stop`` to the end of ``run``."""
    t0 = time.monotonic()
    service.stop()
    thread.join(SLOW_LINK_TIMEOUT_S + START_TIMEOUT_S)
    assert not thread.is_alive(), "the service did not stop"
    return time.monotonic() - t0


@pytest.mark.parametrize("state", ["idle with a silent link", "reconnecting"])
def test_stop_does_not_wait_for_a_silent_link(tmp_path, short_dir, backing, state):
    config = service_config(tmp_path, short_dir, service={"idle_poll_s": 0.05})
    silent = threading.Event()
    with ValEmulator(backing) as emulator:
        emulator.add_listener(lambda event, what: silent.set() if what == "link_drop" else None)
        arm = ValArm(ValConfig(port=emulator.url, exchange_timeout_s=SLOW_LINK_TIMEOUT_S,
                               move_timeout_s=SLOW_LINK_TIMEOUT_S), SafetyLimits())
        service = Service(config, opener=device_opener(arm, FakeCamera(), FakeWrenchSensor()))
        thread = threading.Thread(target=service.run, name="service-under-test")
        thread.start()
        try:
            assert service.serving.wait(START_TIMEOUT_S)
            if state == "reconnecting":
                emulator.set_faults(ValFaults(garbage=DEFAULT_GARBAGE))  # the poll faults
                wait_for_state(service, "fault")
            # the next line (the idle poll's where, or the reconnection's wake-up) goes
            # unanswered
            emulator.set_faults(ValFaults(drop_link_after_lines=0))
            assert silent.wait(EVENT_TIMEOUT_S)
            elapsed_s = timed_stop(service, thread)
        finally:
            service.stop()
            thread.join(SLOW_LINK_TIMEOUT_S + START_TIMEOUT_S)
    assert elapsed_s <= config.service.stop_timeout_s + MARGIN_S, f"stop took {elapsed_s:.2f} s"


class GatedArm(FakeArm):
    """A FakeArm whose moves, once ``gate`` is set, do not end until ``release`` (at most
    SLOW_LINK_TIMEOUT_S): ``moving`` tells that one is under way. ``halt_ends_move``: a halt
    releases it (a halted move returns); otherwise it runs to its end whatever the halt, as the
    segment under way on VAL does."""

    def __init__(self, *args, halt_ends_move: bool = False, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.gate, self.moving, self.release = (threading.Event() for _ in range(3))
        self.halt_ends_move = halt_ends_move

    def _move_to(self, target):
        if self.gate.is_set():
            self.moving.set()
            self.release.wait(SLOW_LINK_TIMEOUT_S)
        return super()._move_to(target)

    def _halt(self) -> None:
        super()._halt()
        if self.halt_ends_move:
            self.release.set()


class _Running:
    """``service.run`` in a thread; stopped and joined on exit whatever the test did."""

    def __init__(self, config, opener) -> None:
        self.service = Service(config, opener=opener)
        self.thread = threading.Thread(target=self.service.run, name="service-under-test")

    def __enter__(self) -> Service:
        self.thread.start()
        assert self.service.serving.wait(START_TIMEOUT_S)
        return self.service

    def stop_timed(self) -> float:
        return timed_stop(self.service, self.thread)

    def __exit__(self, *exc) -> None:
        self.service.stop()
        self.thread.join(SLOW_LINK_TIMEOUT_S + START_TIMEOUT_S)


TEACH = {"grasp_depth_mm": 5.0, "object_width_mm": 30.0}


@pytest.mark.parametrize("link", ["answering", "silent"])
def test_stop_mid_move_does_not_wait_for_the_move(tmp_path, short_dir, link):
    config = service_config(tmp_path, short_dir)
    backing = GatedArm(object_width_mm=30.0)  # halts reach it, the move goes on
    with backing, ValEmulator(backing) as emulator:
        arm = ValArm(ValConfig(port=emulator.url, exchange_timeout_s=SLOW_LINK_TIMEOUT_S,
                               move_timeout_s=SLOW_LINK_TIMEOUT_S), SafetyLimits())
        running = _Running(config, device_opener(arm, FakeCamera(), FakeWrenchSensor()))
        try:
            with running as service, client_for(service) as client:
                assert client.call("teach", wait=True, **TEACH)["job"]["outcome"] == "done"
                backing.gate.set()
                client.call("acquire", set="nn1")  # its first move does not end
                assert backing.moving.wait(EVENT_TIMEOUT_S)
                if link == "silent":  # nor is the halt answered
                    emulator.set_faults(ValFaults(drop_link_after_lines=0))
                elapsed_s = running.stop_timed()
        finally:
            backing.release.set()
    assert elapsed_s <= config.service.stop_timeout_s + MARGIN_S, f"stop took {elapsed_s:.2f} s"


def test_stop_in_fault(tmp_path, short_dir):
    config = service_config(tmp_path, short_dir, service={"idle_poll_s": 0.05})
    arm = FakeArm()
    running = _Running(config, device_opener(arm, FakeCamera(), FakeWrenchSensor()))
    with running as service:
        arm.lose_feedback = True  # the idle poll faults, every reconnection fails
        wait_for_state(service, "fault")
        elapsed_s = running.stop_timed()
    assert elapsed_s <= config.service.stop_timeout_s + MARGIN_S, f"stop took {elapsed_s:.2f} s"


def test_stop_while_training_does_not_wait_for_the_train(tmp_path, short_dir, monkeypatch):
    started, release = threading.Event(), threading.Event()

    def train_in_native_code(ctx):
        """A train deep in a native call: deaf to the abort until it returns."""
        started.set()
        release.wait(SLOW_LINK_TIMEOUT_S)
        return {}

    monkeypatch.setitem(BODIES, "train", train_in_native_code)
    config = service_config(tmp_path, short_dir)
    running = _Running(config, device_opener(FakeArm(), FakeCamera(), FakeWrenchSensor()))
    try:
        with running as service, client_for(service) as client:
            assert client.call("teach", wait=True, **TEACH)["job"]["outcome"] == "done"
            client.call("train")
            assert started.wait(EVENT_TIMEOUT_S)
            elapsed_s = running.stop_timed()
            assert service.job_still_running()  # serve then ends the process (os._exit)
    finally:
        release.set()
    assert elapsed_s <= config.service.stop_timeout_s + MARGIN_S, f"stop took {elapsed_s:.2f} s"


def test_stop_while_recording_completes_the_recording(tmp_path, short_dir, cube_model_files):
    record_dir = tmp_path / "rec"
    config = service_config(tmp_path, short_dir, service={"record_dir": str(record_dir)},
                            controller={"loop": {"converge_mm": 0.0, "converge_deg": 0.0}})
    copy_state(cube_model_files, config)
    arm = GatedArm(start=NOMINAL.moved_in_tool_frame(ToolStep(-8.0, 6.0, 0.0, -12.0)),
                   halt_ends_move=True)
    running = _Running(config, device_opener(arm, FakeCamera(cube_view(arm)),
                                             FakeWrenchSensor()))
    try:
        with running as service, client_for(service) as client:
            arm.gate.set()  # the first look is recorded, then its move does not end
            client.call("position", max_loops=50)
            assert arm.moving.wait(EVENT_TIMEOUT_S)
            elapsed_s = running.stop_timed()
    finally:
        arm.release.set()
    assert elapsed_s <= config.service.stop_timeout_s + MARGIN_S, f"stop took {elapsed_s:.2f} s"
    (recording,) = record_dir.glob("job-*-position.mcap")  # renamed into place, no temp file
    assert not list(record_dir.glob(".*.tmp"))
    with open(recording, "rb") as f:
        assert make_reader(f).get_summary() is not None  # finished: summary and index written
