"""Replay: the video decodes with one frame per look, and the overlays fall on the part."""

import dataclasses
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader

from controller.cli import main
from controller.config import load_config
from controller.devices import open_devices
from controller.fine_positioner import FinePositioner
from controller.loop.positioning import PositioningLoop
from controller.recording.channels import RecordingError
from controller.recording.replay import read_looks, write_sheet, write_video
from controller.recording.writer import RunRecorder
from controller.systems.registry import SYSTEMS
from drivers.core.cell_state import CellState
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
    # the first look waits for the exposure to settle: its extra grabs are at its pose
    assert len(projected) > len(looks) >= 2
    projected = projected[len(projected) - len(looks):]
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


# -- recordings from outside (issue 51, defect 6): bounded, checked, one line each -------------
def _frame(width: int = 32, height: int = 24, fmt: str = ".jpg") -> bytes:
    ok, encoded = cv2.imencode(fmt, np.full((height, width, 3), 90, np.uint8))
    assert ok
    return encoded.tobytes()


def _record(**fields) -> dict:
    return {"run_id": "r", "iteration": 1, "loop_kind": "half", "loops": 0.5, "status": "ok",
            "commanded": None, "error": None, "error_at_look": None,
            "overlay": {"centre_px": [16.0, 12.0], "box_px": [10.0, 6.0, 22.0, 18.0],
                        "roi_px": 8.0, "gabor_px": [[14.0, 10.0]], "taught_px": [16.0, 12.0],
                        "arrow_px": [[16.0, 12.0], [17.0, 13.0]]}, **fields}


def _write_recording(path, looks, image_encoding: str = "json") -> None:
    """A recording of ``looks``: (image message body, iteration record body) pairs, either
    given as raw bytes or as JSON-able values; the images in ``image_encoding``."""
    from mcap.writer import Writer

    from controller.recording.channels import IMAGE_TOPIC, ITERATION_TOPIC

    def data(body) -> bytes:
        return body if isinstance(body, bytes) else json.dumps(body).encode()

    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start()
        channels = {}
        for topic, name, encoding in (
                (IMAGE_TOPIC, "foxglove.CompressedImage", image_encoding),
                (ITERATION_TOPIC, "finepos.IterationRecord", "json")):
            schema_id = writer.register_schema(
                name=name, encoding="jsonschema" if encoding == "json" else encoding,
                data=b'{"type": "object"}')
            channels[topic] = writer.register_channel(topic=topic, message_encoding=encoding,
                                                      schema_id=schema_id)
        for i, (image, record) in enumerate(looks):
            t_ns = (i + 1) * 1_000_000
            for topic, body in ((IMAGE_TOPIC, image), (ITERATION_TOPIC, record)):
                writer.add_message(channels[topic], log_time=t_ns, publish_time=t_ns,
                                   data=data(body))
        writer.finish()


def _image(frame: bytes = None) -> dict:
    import base64

    return {"data": base64.b64encode(frame or _frame()).decode(), "format": "jpeg"}


def _one_line_error(capsys, argv) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("finepos: error: "), err
    assert "internal error" not in err[0]
    return err[0]


def test_a_well_formed_hand_written_recording_replays(tmp_path, capsys):
    _write_recording(tmp_path / "ok.mcap", [(_image(), _record()),
                                            (_image(_frame(fmt=".png")), _record(iteration=2))])
    assert main(["replay", str(tmp_path / "ok.mcap"), "--out", str(tmp_path / "ok.mp4"),
                 "--sheet", str(tmp_path / "ok.png")]) == 0
    assert '"looks": 2' in capsys.readouterr().out
    assert len(_decoded_frames(tmp_path / "ok.mp4")) == 2


@pytest.mark.timeout(30)  # it hung for ever on the FIFO
def test_a_fifo_or_device_as_recording_is_refused_at_once(tmp_path, capsys):
    import os

    os.mkfifo(tmp_path / "pipe.mcap")  # opening it for reading would block without a writer
    for source in (tmp_path / "pipe.mcap", "/dev/zero"):
        err = _one_line_error(capsys, ["replay", str(source), "--out", str(tmp_path / "v.mp4")])
        assert str(source) in err and "not a regular file" in err
    assert not (tmp_path / "v.mp4").exists()


def _claiming(width: int, height: int) -> bytes:
    """A small JPEG whose frame header claims ``width`` x ``height`` pixels."""
    data = bytearray(_frame())
    sof = data.index(b"\xff\xc0")
    data[sof + 5:sof + 9] = height.to_bytes(2, "big") + width.to_bytes(2, "big")
    return bytes(data)


def test_frame_sizes_are_read_from_the_header_before_decoding(tmp_path, capsys, monkeypatch):
    decoded = []
    real = cv2.imdecode
    monkeypatch.setattr(cv2, "imdecode", lambda *a: decoded.append(1) or real(*a))
    _write_recording(tmp_path / "huge.mcap", [(_image(_claiming(20000, 20000)), _record())])
    err = _one_line_error(capsys, ["replay", str(tmp_path / "huge.mcap"),
                                   "--out", str(tmp_path / "v.mp4")])
    assert "huge.mcap" in err and "20000x20000" in err and "4096x4096" in err
    assert decoded == []  # refused before OpenCV allocated anything
    _write_recording(tmp_path / "mixed.mcap", [(_image(), _record()),
                                               (_image(_frame(64, 48)), _record())])
    err = _one_line_error(capsys, ["replay", str(tmp_path / "mixed.mcap"),
                                   "--sheet", str(tmp_path / "s.png")])
    assert "a 64x48 frame in a recording of 32x24 frames" in err


BAD_SHAPES = {
    "record is a list": (_image(), [1, 2], "expected an iteration record"),
    "centre is text": (_image(), _record(overlay={"centre_px": "abc"}), "overlay.centre_px"),
    "centre at 1e308": (_image(), _record(overlay={"centre_px": [1e308, 0.0]}),
                        "overlay.centre_px"),
    "arrow of NaN": (_image(), b'{"overlay": {"arrow_px": [[NaN, 1], [2, 3]]}}',
                     "overlay.arrow_px"),
    "box of three": (_image(), _record(overlay={"box_px": [1, 2, 3]}), "overlay.box_px"),
    "loops 10**400": (_image(), _record(loops=10 ** 400), "loops"),
    "loops null": (_image(), _record(loops=None), "loops"),
    "step of text": (_image(), _record(commanded={"dx_mm": "x", "dy_mm": 0, "dphi_deg": 0}),
                     "commanded.dx_mm"),
    "error without phi": (_image(), _record(error={"x_mm": 1, "y_mm": 2}), "error.phi_deg"),
    "run id a list": (_image(), _record(run_id=[1]), "run_id"),
    "image is a list": ([1], _record(), "base64 string"),
    "data not base64": ({"data": "!!!", "format": "jpeg"}, _record(), "not base64"),
    "frame not an image": (_image(b"GIF89a" + b"\0" * 40), _record(), "neither JPEG nor PNG"),
    "JPEG without header": (_image(b"\xff\xd8\xff\xd9" + b"\0" * 20), _record(),
                            "no frame header"),
    "image JSON broken": (b'{"data": ', _record(), "not a readable finepos recording"),
    "nesting 100000 deep": (_image(), b"[" * 100_000 + b"]" * 100_000,
                            "not a readable finepos recording"),
}


PROTOBUF_IMAGE = b"\x12\x05\xff\xd8abc\x1a\x04jpeg"  # data (field 2), format (field 3)
BAD_PROTOBUF = {
    "data past the end": (b"\x12\x7f\xff\xd8", "claims 127 bytes"),
    "endless varint": (b"\x12" + b"\xff" * 12, "varint"),
    "wire type 7": (b"\x17abc", "unknown wire type 7"),
    "no frame": (b"\x1a\x04jpeg", "neither JPEG nor PNG"),
    "a frame without header": (PROTOBUF_IMAGE, "no frame header"),
}


@pytest.mark.parametrize("case", BAD_PROTOBUF)
def test_a_damaged_protobuf_image_is_one_line_naming_file_and_fault(tmp_path, capsys, case):
    image, expected = BAD_PROTOBUF[case]
    _write_recording(tmp_path / "bad.mcap", [(image, _record())], image_encoding="protobuf")
    err = _one_line_error(capsys, ["replay", str(tmp_path / "bad.mcap"),
                                   "--out", str(tmp_path / "v.mp4")])
    assert "bad.mcap" in err and expected in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.mcap"]


@pytest.mark.parametrize("case", BAD_SHAPES)
def test_a_recording_of_the_wrong_shape_is_one_line_naming_file_and_fault(tmp_path, capsys,
                                                                          case):
    image, record, expected = BAD_SHAPES[case]
    _write_recording(tmp_path / "bad.mcap", [(image, record)])
    err = _one_line_error(capsys, ["replay", str(tmp_path / "bad.mcap"),
                                   "--out", str(tmp_path / "v.mp4"),
                                   "--sheet", str(tmp_path / "s.png")])
    assert str(tmp_path / "bad.mcap") in err and expected in err, err
    assert len(err) < 700
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.mcap"]


def test_an_output_in_a_missing_folder_is_refused_and_no_folder_made(tmp_path, capsys):
    _write_recording(tmp_path / "ok.mcap", [(_image(), _record())])
    for option in ("--out", "--sheet"):
        err = _one_line_error(capsys, ["replay", str(tmp_path / "ok.mcap"), option,
                                       str(tmp_path / "missing" / "x.mp4")])
        assert "no such folder" in err and str(tmp_path / "missing") in err
        assert not (tmp_path / "missing").exists()


_VIDEO_WRITER = cv2.VideoWriter


class _DiskFullWriter:
    """cv2.VideoWriter as it behaves on a full disk: it stops writing without a word."""

    def __init__(self, path, *args) -> None:
        self._real = _VIDEO_WRITER(path, *args)
        self._frames = 0

    def isOpened(self):  # noqa: N802 (OpenCV's name)
        return self._real.isOpened()

    def write(self, frame) -> None:
        self._frames += 1
        if self._frames == 1:
            self._real.write(frame)

    def release(self) -> None:
        self._real.release()


def test_a_video_that_could_not_be_written_fails_and_leaves_no_file(tmp_path, capsys,
                                                                    monkeypatch):
    from controller.recording import replay

    _write_recording(tmp_path / "ok.mcap", [(_image(), _record(iteration=i)) for i in range(3)])
    (tmp_path / "out").mkdir()
    monkeypatch.setattr(replay.cv2, "VideoWriter", _DiskFullWriter)
    err = _one_line_error(capsys, ["replay", str(tmp_path / "ok.mcap"),
                                   "--out", str(tmp_path / "out" / "v.mp4")])
    assert "v.mp4" in err and "1 of 3 frames" in err
    assert list((tmp_path / "out").iterdir()) == []  # neither the video nor a temporary file


@pytest.fixture
def tiny_disk(tmp_path):
    """A 64 KB tmpfs (root only; skipped otherwise), unmounted afterwards."""
    import os
    import subprocess

    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    folder = tmp_path / "tiny"
    folder.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(folder)],
                      check=False, capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    try:
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)


def test_replay_onto_a_full_disk_exits_non_zero_and_leaves_no_file(tmp_path, tiny_disk, capsys):
    rng = np.random.default_rng(0)
    noisy = [cv2.imencode(".jpg", rng.integers(0, 255, (144, 192, 3), np.uint8))[1].tobytes()
             for _ in range(12)]  # noise compresses badly: the video outgrows 64 KB
    _write_recording(tmp_path / "ok.mcap", [(_image(f), _record()) for f in noisy])
    for option, name in (("--out", "v.mp4"), ("--sheet", "s.png")):
        assert main(["replay", str(tmp_path / "ok.mcap"), option, str(tiny_disk / name)]) != 0
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and name in err[0] and "internal error" not in err[0], err
        assert list(tiny_disk.iterdir()) == []


# -- recordings in the JSON Schema layout (channels with message encoding json) ----------------
JSON_LAYOUT = Path(__file__).parent / "data" / "jsonschema-recording.mcap"


def test_a_recording_in_the_json_schema_layout_replays(tmp_path, capsys):
    """data/jsonschema-recording.mcap: the three-look run of test_writer's ``_run`` (FakeCamera,
    scripted estimator), written with JSON-encoded channels and JSON Schema schemas."""
    looks = read_looks(JSON_LAYOUT)
    assert [look.record["loop_kind"] for look in looks] == ["half", "full", "check"]
    assert looks[0].image.shape == (144, 192, 3)
    assert looks[0].overlay.centre_px == pytest.approx((96.0, 72.0))
    assert main(["replay", str(JSON_LAYOUT), "--out", str(tmp_path / "old.mp4")]) == 0
    assert '"looks": 3' in capsys.readouterr().out
    assert len(_decoded_frames(tmp_path / "old.mp4")) == 3
