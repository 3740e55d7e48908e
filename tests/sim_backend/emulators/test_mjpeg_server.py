"""The MJPEG-over-HTTP server: snapshot, multipart stream framing, errors, teardown, command."""

from __future__ import annotations

import signal
import subprocess
import sys
import urllib.error
import urllib.request

import cv2
import numpy as np
import pytest

from drivers.camera.mjpeg_server import BOUNDARY, MjpegServer
from tests.mocks.fakes import FakeCamera

COLOUR_RGB = (200, 60, 20)
TIMEOUT_S = 5.0


def solid() -> np.ndarray:
    return np.tile(np.array(COLOUR_RGB, np.uint8), (144, 192, 1))


@pytest.fixture
def camera():
    with FakeCamera(solid) as cam:
        yield cam


def decode_rgb(jpeg: bytes) -> np.ndarray:
    bgr = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def read_part(response) -> bytes:
    """One multipart part: boundary line, headers, JPEG body, trailing CRLF."""
    assert response.readline() == f"--{BOUNDARY}\r\n".encode()
    headers = {}
    while (line := response.readline()) != b"\r\n":
        name, value = line.decode().split(":", 1)
        headers[name.strip().lower()] = value.strip()
    assert headers["content-type"] == "image/jpeg"
    body = response.read(int(headers["content-length"]))
    assert response.readline() == b"\r\n"
    return body


def test_snapshot_is_a_jpeg_of_the_current_frame(camera):
    with MjpegServer(camera) as server:
        with urllib.request.urlopen(server.snapshot_url, timeout=TIMEOUT_S) as response:
            assert response.headers["Content-Type"] == "image/jpeg"
            image = decode_rgb(response.read())
        assert server.frames_grabbed == 1
    assert image.shape == (144, 192, 3)
    assert np.abs(image.astype(int) - COLOUR_RGB).max() <= 3


def test_stream_is_multipart_x_mixed_replace(camera):
    with MjpegServer(camera, fps=50) as server:
        with urllib.request.urlopen(server.stream_url, timeout=TIMEOUT_S) as response:
            assert response.headers["Content-Type"] == \
                f"multipart/x-mixed-replace; boundary={BOUNDARY}"
            images = [decode_rgb(read_part(response)) for _ in range(3)]
    for image in images:
        assert image.shape == (144, 192, 3)
        assert np.abs(image.astype(int) - COLOUR_RGB).max() <= 3


def test_unknown_path_is_404(camera):
    with MjpegServer(camera) as server:
        with pytest.raises(urllib.error.HTTPError) as info:
            urllib.request.urlopen(f"http://127.0.0.1:{server.port}/nope", timeout=TIMEOUT_S)
        assert info.value.code == 404


def test_snapshot_of_a_stalled_camera_is_503(camera):
    camera.stalled = True
    with MjpegServer(camera) as server:
        with pytest.raises(urllib.error.HTTPError) as info:
            urllib.request.urlopen(server.snapshot_url, timeout=TIMEOUT_S)
        assert info.value.code == 503


def test_unencodable_frame_is_503_and_the_server_keeps_serving():
    current = {"image": np.zeros((144, 192, 3), np.float64)}  # OpenCV cannot convert it
    with FakeCamera(lambda: current["image"]) as cam, MjpegServer(cam) as server:
        with pytest.raises(urllib.error.HTTPError) as info:
            urllib.request.urlopen(server.snapshot_url, timeout=TIMEOUT_S)
        assert info.value.code == 503
        current["image"] = solid()
        with urllib.request.urlopen(server.snapshot_url, timeout=TIMEOUT_S) as response:
            assert decode_rgb(response.read()).shape == (144, 192, 3)


def test_close_ends_open_streams(camera):
    server = MjpegServer(camera, fps=50).start()
    try:
        response = urllib.request.urlopen(server.stream_url, timeout=TIMEOUT_S)
        read_part(response)
        server.paused.set()
    finally:
        server.close()
    with response:
        rest = response.read()  # returns at the end of the stream, else the socket times out
    assert rest.count(f"--{BOUNDARY}".encode()) <= 1, "paused server kept streaming"


@pytest.mark.slow
def test_command_streams_the_simulated_hand_camera_until_sigterm():
    with subprocess.Popen([sys.executable, "-m", "controller.cli", "sim", "camera-stream"],
                          stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                          text=True) as process:
        assert process.stdout is not None
        stream_url, snapshot_url = process.stdout.readline().split()
        try:
            with urllib.request.urlopen(snapshot_url, timeout=TIMEOUT_S) as response:
                assert decode_rgb(response.read()).shape == (144, 192, 3)
            with urllib.request.urlopen(stream_url, timeout=TIMEOUT_S) as response:
                assert decode_rgb(read_part(response)).shape == (144, 192, 3)
        finally:
            process.send_signal(signal.SIGTERM)
        assert process.wait(10) == 0


def test_gone_camera_ends_streams_and_refuses_requests_until_back(camera):
    with MjpegServer(camera, fps=50) as server:
        response = urllib.request.urlopen(server.stream_url, timeout=TIMEOUT_S)
        read_part(response)
        server.set_gone(True)
        with response:
            rest = response.read()  # the stream ends (else the socket times out)
        assert rest.count(f"--{BOUNDARY}".encode()) <= 1
        with pytest.raises(urllib.error.HTTPError) as info:
            urllib.request.urlopen(server.stream_url, timeout=TIMEOUT_S)
        assert info.value.code == 503
        assert server.refused == 2
        server.set_gone(False)
        with urllib.request.urlopen(server.stream_url, timeout=TIMEOUT_S) as response:
            assert decode_rgb(read_part(response)).shape == (144, 192, 3)
