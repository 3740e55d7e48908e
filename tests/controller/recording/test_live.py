"""Live view: the loop's looks served over the Foxglove WebSocket protocol, as recorded."""

import argparse
import time

import pytest
from mcap.reader import make_reader

from controller.commands.common import add_live_option
from controller.loop.positioning import LoopConfig, PositioningLoop
from controller.recording.channels import (
    ANNOTATIONS_TOPIC,
    IMAGE_TOPIC,
    ITERATION_TOPIC,
    TF_TOPIC,
    RecordingError,
)
from controller.recording.live import BACKLOG_MESSAGES, LiveServer, Tee
from controller.recording.writer import RunRecorder
from controller.service.config import LIVE_PORT
from drivers.core.pose import ToolStep
from tests.controller.loop.loop_fixtures import NOMINAL, TruthEstimator
from tests.controller.recording.foxglove_client import FoxgloveClient
from tests.mocks.fakes import FakeArm, FakeCamera

TOPICS = (IMAGE_TOPIC, ANNOTATIONS_TOPIC, ITERATION_TOPIC, TF_TOPIC)


def _run(recorder) -> None:
    arm = FakeArm(start=NOMINAL.moved_in_tool_frame(ToolStep(12.0, -8.0, 0.0, 20.0)))
    arm.connect()
    arm.activate()
    cam = FakeCamera()
    cam.connect()
    PositioningLoop(arm, cam, LoopConfig(), recorder=recorder).run(TruthEstimator(arm))


def _subscribed(live: LiveServer, topics=TOPICS, **options) -> FoxgloveClient:
    client = FoxgloveClient(live.url, **options)
    client.wait_channels(topics)
    client.subscribe_on(live, topics)
    return client


def test_a_client_sees_what_the_recording_holds(tmp_path):
    with LiveServer(port=0) as live, _subscribed(live) as client:
        with RunRecorder(tmp_path / "r.mcap") as recording:
            _run(Tee(recording, live))
        assert live.looks == recording.looks == 3
        seen = client.receive_until(lambda got: len(got) >= 3 * 3 + 2)
    with open(tmp_path / "r.mcap", "rb") as f:
        recorded = [(c.topic, m.log_time) for _, c, m in make_reader(f).iter_messages()]
    assert [(m.topic, m.log_time_ns) for m in seen] == recorded


def test_a_client_that_never_reads_holds_up_neither_the_loop_nor_the_others():
    # the watching client takes the records only: 300 messages, within its queue however
    # slowly this test reads them
    with LiveServer(port=0) as live, _subscribed(live, (ITERATION_TOPIC,)) as watching, \
            _subscribed(live, max_queue=1):
        started = time.monotonic()
        assert 4 * 300 > BACKLOG_MESSAGES
        for _ in range(100):  # 300 looks, 1200 messages: more than a client's queue holds
            _run(live)
        assert time.monotonic() - started < 30.0
        watching.receive_until(lambda got: sum(m.topic == ITERATION_TOPIC for m in got)
                               >= 300, timeout_s=20.0)


def test_a_port_in_use_is_one_line():
    with LiveServer(port=0) as first:
        with pytest.raises(RecordingError, match=f"live view on 127.0.0.1:{first.port}: "
                                                 "cannot listen"):
            LiveServer(port=first.port)
    with pytest.raises(RecordingError, match="needs the TCP control token"):
        LiveServer(port=0, address="0.0.0.0")


def test_the_live_option_takes_an_optional_port():
    parser = argparse.ArgumentParser()
    add_live_option(parser)
    assert parser.parse_args([]).live is None
    assert parser.parse_args(["--live"]).live == LIVE_PORT
    assert parser.parse_args(["--live", "9000"]).live == 9000
    with pytest.raises(SystemExit):
        parser.parse_args(["--live", "70000"])


def test_record_and_live_together_tee_one_run(tmp_path, capsys):
    from controller.commands.common import run_recorder

    args = argparse.Namespace(record=str(tmp_path / "r.mcap"), live=0)
    with run_recorder(args) as recorder:
        assert isinstance(recorder, Tee)
        live = next(r for r in recorder.recorders if isinstance(r, LiveServer))
        url = live.url
        with _subscribed(live) as client:
            _run(recorder)
            client.receive_until(lambda got: sum(m.topic == ITERATION_TOPIC for m in got) >= 3)
    assert f"live: {url} (Foxglove" in capsys.readouterr().err
    with open(tmp_path / "r.mcap", "rb") as f:
        assert sum(c.topic == ITERATION_TOPIC for _, c, _ in make_reader(f).iter_messages()) == 3
