"""The service records position jobs (``service.record_dir``) and serves every look live to a
Foxglove WebSocket client (``service.live``)."""

from __future__ import annotations

import json

import pytest
from mcap.reader import make_reader

from controller.recording import protobuf
from controller.recording.channels import (
    ANNOTATIONS_TOPIC,
    IMAGE_TOPIC,
    ITERATION_TOPIC,
    TF_TOPIC,
    WRENCH_TOPIC,
)
from drivers.core.errors import ConfigError
from drivers.core.pose import ToolStep
from drivers.interfaces import Frame
from tests.controller.recording.foxglove_client import FoxgloveClient
from tests.mocks.fakes import FakeArm, FakeCamera, FakeWrenchSensor

from .conftest import (
    TOKEN,
    client_for,
    copy_state,
    cube_view,
    device_opener,
    free_port,
    running_service,
    service_config,
    token_file,
)
from .test_faults import NOMINAL

LOOK_TOPICS = (IMAGE_TOPIC, ANNOTATIONS_TOPIC, ITERATION_TOPIC)
CELL_EPOCH_S = 5000.0  # the test camera's clock starts here, far from the process's


class CellClockCamera(FakeCamera):
    """FakeCamera whose frames are stamped by a clock of their own: 0.1 s a frame from
    CELL_EPOCH_S."""

    def __init__(self, render) -> None:
        super().__init__(render)
        self.stamps: list[float] = []

    def _grab(self) -> Frame:
        frame = super()._grab()
        self.stamps.append(CELL_EPOCH_S + 0.1 * len(self.stamps))
        return Frame(frame.image, self.stamps[-1])


def _positioning(config, camera=None):
    arm = FakeArm(start=NOMINAL.moved_in_tool_frame(ToolStep(-3.0, 2.0, 0.0, -8.0)))
    camera = camera(cube_view(arm)) if camera else FakeCamera(cube_view(arm))
    return camera, running_service(config, device_opener(arm, camera, FakeWrenchSensor()))


def test_a_foxglove_client_sees_each_look_in_order_on_the_cell_clock(tmp_path, short_dir,
                                                                     cube_model_files):
    config = service_config(tmp_path, short_dir, service={
        "record_dir": str(tmp_path / "rec"), "live": {"port": free_port()}})
    copy_state(cube_model_files, config)
    camera, service_context = _positioning(config, CellClockCamera)
    with service_context as service, client_for(service) as client, \
            FoxgloveClient(f"ws://127.0.0.1:{config.service.live.port}") as live:
        assert live.subprotocol in ("foxglove.sdk.v1", "foxglove.websocket.v1")
        channels = live.wait_channels(LOOK_TOPICS + (TF_TOPIC, WRENCH_TOPIC))
        assert channels[IMAGE_TOPIC]["schemaName"] == "foxglove.CompressedImage"
        assert channels[ANNOTATIONS_TOPIC]["schemaName"] == "foxglove.ImageAnnotations"
        assert channels[TF_TOPIC]["schemaName"] == "foxglove.FrameTransform"
        assert channels[ITERATION_TOPIC]["encoding"] == "json"
        live.subscribe_on(service._live_view, LOOK_TOPICS + (TF_TOPIC,))
        job = client.call("position", wait=True, max_loops=3)["job"]
        assert job["outcome"] == "done", job
        looks = job["result"]["iterations"] + 1  # every move's look, and the final check
        messages = live.receive_until(
            lambda got: sum(m.topic == ITERATION_TOPIC for m in got) >= looks)
    # each look: its image, annotations and record at the frame's time, then the tool pose
    # after its move; log times never go back
    frame_ns = [round(t * 1e9) for t in camera.stamps]
    per_look = [m for m in messages if m.topic in LOOK_TOPICS]
    assert [m.topic for m in per_look] == list(LOOK_TOPICS) * looks
    assert {m.log_time_ns for m in per_look} <= set(frame_ns)
    times = [m.log_time_ns for m in messages]
    assert times == sorted(times) and times[0] >= CELL_EPOCH_S * 1e9
    tf = [m for m in messages if m.topic == TF_TOPIC]
    assert len(tf) >= looks - 1
    image = next(m for m in messages if m.topic == IMAGE_TOPIC)
    data, image_format = protobuf.compressed_image(image.data)
    assert image_format == "jpeg" and data.startswith(b"\xff\xd8")
    stamp = dict((n, v) for n, _, v in protobuf.fields(
        next(v for n, _, v in protobuf.fields(image.data) if n == protobuf.IMAGE_TIMESTAMP)))
    assert stamp.get(1, 0) * 10**9 + stamp.get(2, 0) == image.log_time_ns
    records = [m for m in messages if m.topic == ITERATION_TOPIC]
    assert [json.loads(m.data)["iteration"] for m in records] == list(range(1, looks + 1))
    files = sorted((tmp_path / "rec").glob("*.mcap"))
    assert [f.name for f in files] == [f"job-{job['id']:05d}-position.mcap"]
    with open(files[0], "rb") as f:
        recorded = [(channel.topic, message.log_time)
                    for _, channel, message in make_reader(f).iter_messages()]
    # the recording holds what the client saw
    assert [(m.topic, m.log_time_ns) for m in per_look] == \
        [r for r in recorded if r[0] in LOOK_TOPICS]


def test_off_loopback_the_live_view_needs_the_token(tmp_path, short_dir):
    with pytest.raises(ConfigError, match="live.address: 0.0.0.0 is not loopback: that needs "
                                          "service.tcp.token_file"):
        service_config(tmp_path, short_dir, service={"live": {"address": "0.0.0.0"}})
    with pytest.raises(ConfigError, match="service.live: address: expected an IP address"):
        service_config(tmp_path, short_dir, service={"live": {"address": "cell-pc"}})
    port = free_port()
    config = service_config(tmp_path, short_dir, service={
        "live": {"port": port, "address": "0.0.0.0"},
        "tcp": {"port": free_port(), "token_file": str(token_file(tmp_path))}})
    with running_service(config, device_opener(FakeArm(), FakeCamera(), FakeWrenchSensor())):
        from websockets.exceptions import InvalidStatus

        with pytest.raises(InvalidStatus, match="401"):
            FoxgloveClient(f"ws://127.0.0.1:{port}")
        with pytest.raises(InvalidStatus, match="401"):
            FoxgloveClient(f"ws://127.0.0.1:{port}/?token=wrong-token-0123456789")
        for url, headers in ((f"ws://127.0.0.1:{port}/?token={TOKEN}", None),
                             (f"ws://127.0.0.1:{port}", {"Authorization": f"Bearer {TOKEN}"})):
            with FoxgloveClient(url, headers) as live:
                assert ITERATION_TOPIC in live.wait_channels([ITERATION_TOPIC])


def test_a_live_port_in_use_stops_the_start_in_one_line(tmp_path, short_dir):
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        config = service_config(tmp_path, short_dir, service={"live": {"port": port}})
        from controller.recording.channels import RecordingError
        from controller.service.service import Service

        service = Service(config, opener=device_opener(FakeArm(), FakeCamera(),
                                                       FakeWrenchSensor()))
        with pytest.raises(RecordingError, match=f"live view on 127.0.0.1:{port}: cannot "
                                                 "listen"):
            service.run()


def test_job_ids_continue_after_the_recordings_of_an_earlier_run(tmp_path, short_dir):
    record_dir = tmp_path / "rec"
    record_dir.mkdir()
    (record_dir / "job-00007-position.mcap").write_bytes(b"an earlier run's recording")
    config = service_config(tmp_path, short_dir, service={"record_dir": str(record_dir)})
    with running_service(config, device_opener(FakeArm(), FakeCamera(), FakeWrenchSensor())) \
            as service, client_for(service) as client:
        job = client.call("teach", wait=True, grasp_depth_mm=5.0, object_width_mm=30.0)["job"]
    assert job["id"] == 8 and job["outcome"] == "done", job


def test_a_recording_that_fails_is_reported_in_the_job_result(tmp_path, short_dir,
                                                              cube_model_files, monkeypatch):
    from controller.recording import writer

    def failing_close(self):
        raise writer.RecordingError(f"recording {self.path} not written: No space left on "
                                    "device")

    monkeypatch.setattr(writer.RunRecorder, "close", failing_close)
    config = service_config(tmp_path, short_dir, service={"record_dir": str(tmp_path / "rec")})
    copy_state(cube_model_files, config)
    arm = FakeArm(start=NOMINAL.moved_in_tool_frame(ToolStep(-3.0, 2.0, 0.0, -8.0)))
    with running_service(config, device_opener(arm, FakeCamera(cube_view(arm)),
                                               FakeWrenchSensor())) \
            as service, client_for(service) as client:
        job = client.call("position", wait=True, max_loops=1)["job"]
    assert "job-00001-position.mcap not written" in job["result"]["recording_error"], job
