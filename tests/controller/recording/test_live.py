"""Live view: the annotated latest look, served by the MJPEG camera-stream server."""

import urllib.request

import cv2
import numpy as np

from controller.loop.positioning import LoopConfig, PositioningLoop
from controller.recording.live import LiveView, Tee
from controller.recording.writer import RunRecorder
from drivers.camera.mjpeg_server import MjpegServer
from drivers.core.pose import ToolStep
from tests.controller.loop.loop_fixtures import NOMINAL, TruthEstimator
from tests.mocks.fakes import FakeArm, FakeCamera


def test_the_live_view_serves_the_annotated_last_look_over_mjpeg(tmp_path):
    arm = FakeArm(start=NOMINAL.moved_in_tool_frame(ToolStep(12.0, -8.0, 0.0, 20.0)))
    arm.connect()
    arm.activate()
    cam = FakeCamera()
    cam.connect()
    live = LiveView(scale=2)
    before = live.grab().image.copy()
    with RunRecorder(tmp_path / "r.mcap") as recording:
        PositioningLoop(arm, cam, LoopConfig(), recorder=Tee(recording, live)).run(
            TruthEstimator(arm))
    assert live.looks == recording.looks == 3
    with MjpegServer(live) as server:
        with urllib.request.urlopen(server.snapshot_url, timeout=5) as reply:
            served = cv2.imdecode(np.frombuffer(reply.read(), np.uint8), cv2.IMREAD_COLOR)
    assert served.shape == (288, 384, 3) == before.shape
    # the scripted part sits at (96, 72): the red centre marker is drawn there
    b, g, r = (served[:, :, i].astype(int) for i in range(3))
    ys, xs = np.nonzero((r > 180) & (g < 110) & (b < 110))
    assert abs(xs.mean() - (96.5 * 2 - 0.5)) < 2 and abs(ys.mean() - (72.5 * 2 - 0.5)) < 2
    assert not (before[:, :, 0] > 180).any()  # nothing drawn before the first look
