"""The bench's live-view clients speak the protocol the live view serves."""

import time

from controller.recording.channels import ITERATION_TOPIC, TF_TOPIC
from controller.recording.live import LiveServer
from controller.service.live_bench import LiveClient
from tests.controller.recording.test_live import _run


def test_a_reading_client_counts_messages_and_a_stalled_one_holds_nothing_up():
    with LiveServer(port=0) as live:
        stalled = LiveClient(live.port, (ITERATION_TOPIC, TF_TOPIC), reading=False,
                             subscribed=False)
        reader = LiveClient(live.port, (ITERATION_TOPIC, TF_TOPIC), reading=True)
        try:
            _wait(lambda: {ITERATION_TOPIC, TF_TOPIC} <= live.subscribed())
            stalled.subscribe()
            for _ in range(5):
                _run(live)
            stalled.unsubscribe()
            _run(live)
            _wait(lambda: reader.messages >= 6 * 5)  # each run's three records, two poses
        finally:
            reader.close()
            stalled.close()


def _wait(condition, timeout_s: float = 5.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)
