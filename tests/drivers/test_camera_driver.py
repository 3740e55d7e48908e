"""The OpenCV camera driver against the MJPEG server (FFmpeg over HTTP) and a video file."""

from __future__ import annotations

import itertools
import threading
import time

import cv2
import numpy as np
import pytest

from drivers.camera import OpenCvCamera, OpenCvCameraConfig
from drivers.camera.drop_counter import DropCounter
from drivers.camera.frame_reader import to_rgb
from drivers.camera.mjpeg_server import MjpegServer
from drivers.contract import check_camera
from drivers.core.errors import (
    ConfigError,
    DeviceFaultError,
    DeviceNotConnectedError,
    DeviceTimeoutError,
)
from drivers.core.typed_config import from_mapping
from drivers.interfaces import Lifecycle
from sim_backend.cell.scene_config import SceneConfig
from sim_backend.cell.sim_cell import SimCell
from sim_backend.devices import SimCamera
from tests.mocks.fakes import FakeCamera

LARGE_RGB = (30, 120, 220)


def large_frame() -> np.ndarray:
    """A 320x240 frame: left half one colour, right half black (the driver must resize it)."""
    image = np.zeros((240, 320, 3), np.uint8)
    image[:, :160] = LARGE_RGB
    return image


@pytest.fixture
def server():
    with FakeCamera(large_frame) as cam, MjpegServer(cam, fps=30) as srv:
        yield srv


def make_camera(source, timeout_s: float = 2.0) -> OpenCvCamera:
    return OpenCvCamera(OpenCvCameraConfig(source=source, timeout_s=timeout_s))


def test_frames_are_resized_rgb(server):
    with make_camera(server.stream_url) as cam:
        frame = cam.grab()
    assert frame.image.shape == (144, 192, 3) and frame.image.dtype == np.uint8
    left, right = frame.image[:, :90].reshape(-1, 3), frame.image[:, 102:].reshape(-1, 3)
    assert np.abs(np.median(left, axis=0) - LARGE_RGB).max() <= 4, "colour order must be RGB"
    assert right.max() <= 12


def test_grab_returns_a_frame_that_arrived_after_the_call(server):
    with make_camera(server.stream_url) as cam:
        frames = [cam.grab() for _ in range(3)]
        assert cam.stats.received >= 3 and cam.stats.failed_reads == 0
    stamps = [f.timestamp_s for f in frames]
    assert stamps == sorted(stamps) and len(set(stamps)) == 3


def test_grab_skips_frames_arriving_within_the_settle_time(server):
    # a frame arriving sooner after the call may have been exposed before it (stream latency)
    settle_s = 0.15
    with OpenCvCamera(OpenCvCameraConfig(source=server.stream_url, settle_s=settle_s)) as cam:
        cam.grab()
        called_s = time.monotonic()
        frame = cam.grab()
    assert frame.timestamp_s >= called_s + settle_s


def test_stalled_stream_times_out_into_fault_until_reset(server):
    cam = make_camera(server.stream_url, timeout_s=0.5)
    with cam:
        cam.grab()
        server.paused.set()
        with pytest.raises(DeviceTimeoutError, match="no frame within 0.5 s"):
            cam.grab()
        assert cam.state is Lifecycle.FAULT
        with pytest.raises(DeviceFaultError):
            cam.grab()
        server.paused.clear()
        cam.reset()
        assert cam.grab().image.shape == (144, 192, 3)


def test_a_stream_that_ends_and_comes_back_is_opened_again_without_a_reset(server):
    with make_camera(server.stream_url, timeout_s=3.0) as cam:
        cam.grab()
        server.set_gone(True)  # the stream ends; a new request gets 503
        threading.Timer(0.6, server.set_gone, args=(False,)).start()
        gone_s = time.monotonic()
        frame = cam.grab()  # late, not a fault
        assert frame.timestamp_s > gone_s + 0.5
        assert cam.state is Lifecycle.ACTIVE
        assert cam.stats.reopened >= 1 and cam.stats.failed_reads >= 1


def test_unopenable_source_is_not_connected():
    cam = make_camera("http://127.0.0.1:9/stream.mjpg")
    with pytest.raises(DeviceNotConnectedError, match="cannot be opened"):
        cam.connect()
    assert cam.state is Lifecycle.DISCONNECTED


def test_video_file_is_read_one_frame_per_grab(tmp_path):
    path = str(tmp_path / "clip.avi")
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 10, (320, 240))
    for grey in (40, 120, 200):
        writer.write(np.full((240, 320, 3), grey, np.uint8))
    writer.release()
    with make_camera(path, timeout_s=0.3) as cam:
        greys = [int(np.median(cam.grab().image)) for _ in range(3)]
        with pytest.raises(DeviceTimeoutError):
            cam.grab()  # end of the file
    assert greys == pytest.approx([40, 120, 200], abs=4)


def test_config_accepts_index_or_string():
    assert from_mapping(OpenCvCameraConfig, {"source": 0}, "camera").source == 0
    url = "http://127.0.0.1:8080/stream.mjpg"
    assert from_mapping(OpenCvCameraConfig, {"source": url}, "camera").source == url
    with pytest.raises(ConfigError, match=r"^camera\.source"):
        from_mapping(OpenCvCameraConfig, {"source": 1.5}, "camera")
    with pytest.raises(ConfigError, match=r"^camera\.timeout_s: must be > 0"):
        from_mapping(OpenCvCameraConfig, {"source": 0, "timeout_s": 0}, "camera")


@pytest.mark.parametrize("image, expected_rgb", [
    (np.full((480, 640), 90, np.uint8), (90, 90, 90)),
    (np.tile(np.array([10, 20, 30, 255], np.uint8), (144, 192, 1)), (30, 20, 10)),
    (np.tile(np.array([10, 20, 30], np.uint8), (100, 100, 1)), (30, 20, 10)),
])
def test_to_rgb_handles_grey_bgra_and_other_sizes(image, expected_rgb):
    rgb = to_rgb(image, 192, 144)
    assert rgb.shape == (144, 192, 3) and rgb.dtype == np.uint8
    assert tuple(int(v) for v in rgb[72, 96]) == expected_rgb


def test_drop_counter_counts_frames_missing_from_gaps():
    counter = DropCounter(gap_factor=2.5)
    arrivals = [i * 0.1 for i in range(8)]  # 10 fps
    arrivals += [arrivals[-1] + 0.4]  # three frames missing
    arrivals += [arrivals[-1] + 0.1 * k for k in range(1, 4)]
    found = [counter.observe(t) for t in arrivals]
    assert found == [0] * 8 + [3] + [0] * 3 and counter.dropped == 3


def test_drop_counter_gives_no_verdict_before_it_knows_the_rate():
    counter = DropCounter()
    assert [counter.observe(t) for t in itertools.accumulate([0, 0.1, 1.0, 0.1])] == [0] * 4


def test_meets_camera_contract_on_the_simulated_hand_camera_stream():
    with SimCell(SceneConfig()) as cell:
        # The reference view is rendered before the server's grabber starts: the cell is
        # one physics client and is not to be rendered from two threads at once.
        rendered = cell.render(noisy=False).astype(int)
        with SimCamera(cell) as sim_camera, \
                MjpegServer(sim_camera, fps=30, jpeg_quality=95) as server:
            check_camera(lambda: make_camera(server.stream_url))
            with make_camera(server.stream_url) as cam:
                streamed = cam.grab().image.astype(int)
    assert streamed.shape == rendered.shape == (144, 192, 3)
    assert np.abs(streamed - rendered).mean() < 6.0, "the stream must show the rendered view"
