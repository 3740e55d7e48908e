"""The service records position jobs (``service.record_dir``) and shows every look on the live
view (``service.live_view_port``)."""

from __future__ import annotations

import socket
import urllib.request

from mcap.reader import make_reader

from controller.recording.channels import IMAGE_TOPIC, ITERATION_TOPIC
from drivers.core.pose import ToolStep
from tests.mocks.fakes import FakeArm, FakeCamera, FakeWrenchSensor

from .conftest import (
    client_for,
    copy_state,
    cube_view,
    device_opener,
    running_service,
    service_config,
)
from .test_faults import NOMINAL


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_position_job_is_recorded_and_shown_live(tmp_path, short_dir, cube_model_files):
    port = _free_port()
    config = service_config(tmp_path, short_dir, service={
        "record_dir": str(tmp_path / "rec"), "live_view_port": port})
    copy_state(cube_model_files, config)
    arm = FakeArm(start=NOMINAL.moved_in_tool_frame(ToolStep(-3.0, 2.0, 0.0, -8.0)))
    with running_service(config, device_opener(arm, FakeCamera(cube_view(arm)),
                                               FakeWrenchSensor())) \
            as service, client_for(service) as client:
        job = client.call("position", wait=True, max_loops=3)["job"]
        assert job["outcome"] == "done", job
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/stream.mjpg", timeout=5) as live:
            assert b"\xff\xd8" in live.read(4096)  # a JPEG frame of the last look
    files = sorted((tmp_path / "rec").glob("*.mcap"))
    assert [f.name for f in files] == [f"job-{job['id']:05d}-position.mcap"]
    with open(files[0], "rb") as f:
        topics = [channel.topic for _, channel, _ in make_reader(f).iter_messages()]
    looks = job["result"]["iterations"] + 1  # every move's look, and the final check
    assert topics.count(IMAGE_TOPIC) == topics.count(ITERATION_TOPIC) == looks


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
