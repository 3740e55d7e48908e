"""A stop (SIGTERM) never waits on a device: with the VAL link silent while the service polls the
idle arm, or while it reconnects after a fault, the whole run ends within
service.stop_timeout_s + 0.5 s, not at the exchange's timeout."""

from __future__ import annotations

import threading
import time

import pytest

from controller.service.service import Service
from drivers.safety import SafetyLimits
from drivers.val import ValArm, ValConfig
from sim_backend.emulators.val.server import DEFAULT_GARBAGE, ValEmulator, ValFaults
from tests.controller.service.conftest import (
    EVENT_TIMEOUT_S,
    START_TIMEOUT_S,
    device_opener,
    service_config,
    wait_for_state,
)
from tests.mocks.fakes import FakeCamera, FakeWrenchSensor

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
