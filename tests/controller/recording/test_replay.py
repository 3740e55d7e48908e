"""Replay: the video decodes with one frame per look, and the overlays fall on the part."""

import dataclasses
import json

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader

from controller.cli import main
from controller.config import load_config
from controller.devices import open_devices
from controller.fine_positioner import FinePositioner
from controller.loop.positioning import PositioningLoop
from controller.recording.replay import read_looks, write_sheet, write_video
from controller.recording.writer import RecordingError, RunRecorder
from controller.systems.registry import SYSTEMS
from controller.teach.cell_state import CellState
from drivers.core.pose import Pose, ToolStep
from tests.controller.recording.test_writer import _run

SCALE = 4


def _decoded_frames(path) -> list[np.ndarray]:
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame)
    capture.release()
    return frames


def _red_marker(frame: np.ndarray) -> tuple[float, float]:
    """Centroid (x, y) of the red centre marker in a replay frame (BGR)."""
    b, g, r = (frame[:, :, i].astype(int) for i in range(3))
    ys, xs = np.nonzero((r > 180) & (g < 110) & (b < 110))
    assert len(xs) > 0, "no centre marker in the frame"
    return float(xs.mean()), float(ys.mean())


def test_replay_writes_one_video_frame_and_one_tile_per_look(tmp_path):
    (result,), _ = _run(tmp_path / "run.mcap")
    looks = read_looks(tmp_path / "run.mcap")
    assert len(looks) == result.iterations + 1
    video = write_video(looks, tmp_path / "run.mp4", scale=SCALE)
    frames = _decoded_frames(video)
    assert len(frames) == len(looks)
    assert frames[0].shape == (144 * SCALE, 192 * SCALE, 3)
    # the scripted estimator sees the part at (96, 72): the marker's centre is there
    x, y = _red_marker(frames[0])
    assert abs(x - (96.5 * SCALE - 0.5)) < 2 and abs(y - (72.5 * SCALE - 0.5)) < 2
    sheet = cv2.imread(str(write_sheet(looks, tmp_path / "run.png", columns=2)))
    assert sheet.shape[1] > 2 * 192 * 2 and sheet.shape[0] > 2 * 144 * 2  # 2 x 2 tiles


def test_replay_command_reports_what_it_wrote(tmp_path, capsys):
    _run(tmp_path / "run.mcap")
    code = main(["replay", str(tmp_path / "run.mcap"), "--out", str(tmp_path / "v.mp4"),
                 "--sheet", str(tmp_path / "s.png")])
    assert code == 0
    out = capsys.readouterr().out
    assert '"looks": 3' in out and (tmp_path / "v.mp4").exists() and (tmp_path / "s.png").exists()


def test_replay_of_a_bad_file_is_a_one_line_error(tmp_path, capsys):
    (tmp_path / "bad.mcap").write_bytes(b"not mcap at all")
    assert main(["replay", str(tmp_path / "bad.mcap"), "--out", str(tmp_path / "v.mp4")]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("finepos: error: ") and "bad.mcap" in err
    with pytest.raises(RecordingError, match="no such recording"):
        read_looks(tmp_path / "missing.mcap")
    assert main(["replay", str(tmp_path / "bad.mcap")]) == 2  # neither --out nor --sheet


@pytest.mark.slow
def test_overlays_fall_on_the_part_on_the_simulated_cell(trained, tmp_path):
    from sim_backend.cell import hand_camera

    cfg = load_config(None)
    with open_devices(cfg, seed=7) as devices:
        fp = FinePositioner(devices, cfg, state_dir=trained)
        model = fp.load_model()
        cell = devices.cell
        projected = []

        class ProjectingCamera:
            """The hand camera, noting where the part's centre projects at every grab."""

            def grab(self):
                frame = devices.camera.grab()
                x, y, _ = cell.object_pose()
                uv, _ = hand_camera.project(np.array([x, y, cell.part.height_mm / 2.0]),
                                            cell.camera_to_world())
                projected.append(uv[0])  # edge coordinates (pixel centres at .5)
                return frame

        fp.move_to(fp.state().nominal_pose.moved_in_tool_frame(ToolStep(-12, 8, 0, -20)))
        with RunRecorder(tmp_path / "sim.mcap") as recorder:
            # one frame a look, so that every grab is a recorded look
            loop_cfg = dataclasses.replace(cfg.controller.loop, settle_frames=1)
            result = PositioningLoop(devices.arm, ProjectingCamera(), loop_cfg,
                                     ground_truth=devices.ground_truth, recorder=recorder,
                                     ).run(SYSTEMS["gabor"].estimator(model))
    assert result.ok
    looks = read_looks(tmp_path / "sim.mcap")
    assert len(looks) == len(projected) >= 2
    frames = _decoded_frames(write_video(looks, tmp_path / "sim.mp4", scale=SCALE))
    assert len(frames) == len(looks)
    for look, frame, (pu, pv) in zip(looks, frames, projected, strict=True):
        u, v = look.overlay.centre_px
        # the recorded centre (pixel-centre coordinates) on the part's projected centre; the
        # cube is about 39 px wide
        assert np.hypot(u + 0.5 - pu, v + 0.5 - pv) < 3.0
        x, y = _red_marker(frame)  # and the drawn marker on it, in the decoded video
        assert np.hypot(x - (pu * SCALE - 0.5), y - (pv * SCALE - 0.5)) < 3.0 * SCALE
        assert look.overlay.roi_px == 50 and len(look.overlay.gabor_px) == 9
        assert look.overlay.taught_px is not None
        assert look.record["error_at_look"] is not None


@pytest.mark.slow
def test_cli_position_grasp_and_evaluate_record(trained, tmp_path, capsys):
    rec = tmp_path / "pos.mcap"
    assert main(["position", "--state-dir", str(trained), "--offset", "10,-6,15", "--grasp",
                 "--log", str(tmp_path / "p.jsonl"), "--record", str(rec)]) == 0
    out = json.loads(capsys.readouterr().out)
    looks = read_looks(rec)
    # every look is recorded; each but a converged look without its step made a move (with
    # --grasp the grasp's first descent move makes that step: "and made by the grasp's ...")
    made = ", and made" in out["reason"]
    assert len(looks) == out["iterations"] + (0 if made else 1) and out["record"] == str(rec)
    with open(rec, "rb") as f:
        topics = [c.topic for _, c, _ in make_reader(f).iter_messages()]
    assert topics.count("/finepos/guard_event") == 1 and "/finepos/wrench" in topics
    rec = tmp_path / "eval.mcap"
    assert main(["evaluate", "--trials", "3", "--record-trials", "2", "--quiet", "--no-grasp",
                 "--model", str(trained / "model-gabor.fpm"), "--record", str(rec)]) == 0
    assert len({look.record["run_id"] for look in read_looks(rec)}) == 2


def test_a_run_that_cannot_start_leaves_no_log_and_names_the_command(tmp_path, capsys):
    state = tmp_path / "state"
    CellState(Pose(300.0, 0.0, 150.0, -90.0, 90.0, 0.0), "cube", 4, 20.0, 30.0, "auto",
              CellState.now()).save(state / "cell.json")
    log, rec = tmp_path / "p.jsonl", tmp_path / "p.mcap"
    assert main(["position", "--state-dir", str(state), "--log", str(log),
                 "--record", str(rec)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == (f"finepos: error: {state / 'model-gabor.fpm'}: no trained gabor model; "
                       "run `finepos train` first")
    assert not log.exists() and not rec.exists()
