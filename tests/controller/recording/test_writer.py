"""Run recordings: a recorded loop run opens in the mcap reader as the issue names it."""

import json
import struct

import pytest
from mcap.reader import make_reader

from controller.loop.iteration_log import IterationLog
from controller.loop.positioning import LoopConfig, PositioningLoop
from controller.loop.record import IterationRecord
from controller.recording import protobuf
from controller.recording.channels import RecordingError
from controller.recording.overlay import Overlay, overlay_of
from controller.recording.writer import RunRecorder
from controller.systems.estimator import TranslationEstimate
from drivers.core.pose import ToolStep
from drivers.interfaces import Wrench
from tests.controller.loop.loop_fixtures import NOMINAL, TruthEstimator, truth_error
from tests.mocks.fakes import FakeArm, FakeCamera, FakeWrenchSensor

EXPECTED_SCHEMAS = {
    "/hand_camera/image": "foxglove.CompressedImage",
    "/hand_camera/annotations": "foxglove.ImageAnnotations",
    "/tf": "foxglove.FrameTransform",
    "/finepos/iteration": "finepos.IterationRecord",
    "/finepos/guard_event": "finepos.GuardEvent",
    "/finepos/wrench": "finepos.WrenchReading",
}


def _devices(offset: ToolStep):
    arm = FakeArm(start=NOMINAL.moved_in_tool_frame(offset))
    arm.connect()
    arm.activate()
    cam = FakeCamera()
    cam.connect()
    return arm, cam


START = ToolStep(12.0, -8.0, 0.0, 20.0)


def _run(path):
    """One recorded run from START with the scripted estimator: (result,), recorder."""
    with RunRecorder(path) as recorder:
        arm, cam = _devices(START)
        loop = PositioningLoop(arm, cam, LoopConfig(), None, lambda: truth_error(arm),
                               recorder=recorder)
        result = loop.run(TruthEstimator(arm))
    return (result,), recorder


def _messages(path):
    """The summary and (topic, log time, message) of every message: JSON messages decoded,
    protobuf ones as their bytes."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        out = [(channel.topic, message.log_time,
                json.loads(message.data) if channel.message_encoding == "json" else message.data)
               for _, channel, message in reader.iter_messages(log_time_order=False)]
    return summary, out


def _first_circle_position(annotations: bytes) -> tuple[float, float]:
    """(x, y) of the first circle of a protobuf ``foxglove.ImageAnnotations``."""
    circle = next(v for n, _, v in protobuf.fields(annotations) if n == 1)  # circles
    position = next(v for n, _, v in protobuf.fields(circle) if n == 2)
    xy = {n: struct.unpack("<d", v.to_bytes(8, "little"))[0]
          for n, _, v in protobuf.fields(position)}
    return xy[1], xy[2]


def test_a_recorded_three_look_run_opens_with_every_schema_named(tmp_path):
    path = tmp_path / "run.mcap"
    (result,), recorder = _run(path)
    assert result.outcome == "converged" and result.iterations == 2  # half, full, check
    looks = result.iterations + 1
    assert recorder.looks == looks
    summary, messages = _messages(path)
    names = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    # a channel is written with its first message: this run has no grasp
    assert names == {t: n for t, n in EXPECTED_SCHEMAS.items()
                     if t not in ("/finepos/guard_event", "/finepos/wrench")}
    encodings = {c.topic: (summary.schemas[c.schema_id].encoding, c.message_encoding)
                 for c in summary.channels.values()}
    assert encodings == {topic: ("protobuf", "protobuf") if name.startswith("foxglove.")
                         else ("jsonschema", "json") for topic, name in names.items()}
    topics = [t for t, _, _ in messages]
    assert topics.count("/hand_camera/image") == looks
    assert topics.count("/hand_camera/annotations") == looks
    assert topics.count("/finepos/iteration") == looks
    assert topics.count("/tf") == result.iterations  # one pose after each move
    times = [t for _, t, _ in messages]
    assert times == sorted(times)  # written in order, as the file stores them
    records = [m for t, _, m in messages if t == "/finepos/iteration"]
    assert [r["loop_kind"] for r in records] == ["half", "full", "check"]
    assert records[0]["error_at_look"]["x_mm"] == pytest.approx(12.0)
    image = next(m for t, _, m in messages if t == "/hand_camera/image")
    data, image_format = protobuf.compressed_image(image)
    assert image_format == "jpeg" and data.startswith(b"\xff\xd8")
    frame_id = next(v for n, _, v in protobuf.fields(image) if n == protobuf.IMAGE_FRAME_ID)
    assert frame_id == b"hand_camera"
    notes = next(m for t, _, m in messages if t == "/hand_camera/annotations")
    assert _first_circle_position(notes) == (96.5, 72.5)  # edge coordinates


def test_the_json_lines_log_is_the_same_with_and_without_a_recording(tmp_path):
    def logged(name, record):
        arm, cam = _devices(START)
        with IterationLog(tmp_path / name) as log:
            recorder = RunRecorder(tmp_path / "r.mcap") if record else None
            PositioningLoop(arm, cam, LoopConfig(), log, lambda: truth_error(arm),
                            recorder=recorder).run(TruthEstimator(arm), run_id="same")
            if recorder:
                recorder.close()
        lines = (tmp_path / name).read_text().splitlines()
        return [{k: v for k, v in json.loads(line).items() if k not in ("time", "timings_ms")}
                for line in lines]

    assert logged("a.jsonl", False) == logged("b.jsonl", True)


def test_max_runs_keeps_the_first_runs_and_their_readings_only(tmp_path):
    path = tmp_path / "runs.mcap"
    sensor = FakeWrenchSensor()
    sensor.connect()
    run_ids = []
    with RunRecorder(path, max_runs=2) as recorder:
        wrapped = recorder.recording_sensor(sensor)
        for _ in range(3):
            arm, cam = _devices(START)
            loop = PositioningLoop(arm, cam, LoopConfig(), recorder=recorder)
            run_ids.append(loop.run(TruthEstimator(arm)).run_id)
            wrapped.read()  # the run's grasp reading
    _, messages = _messages(path)
    runs = {m["run_id"] for t, _, m in messages if t == "/finepos/iteration"}
    assert runs == set(run_ids[:2])
    assert [t for t, _, _ in messages].count("/finepos/wrench") == 2


def test_recording_sensor_records_every_reading(tmp_path):
    sensor = FakeWrenchSensor(lambda: Wrench(0.0, 0.0, -2.5, 0.0, 0.0, 0.0))
    sensor.connect()
    with RunRecorder(tmp_path / "w.mcap") as rec:
        wrapped = rec.recording_sensor(sensor)
        readings = [wrapped.read().fz_n for _ in range(3)]
    _, messages = _messages(tmp_path / "w.mcap")
    assert [m["fz_n"] for t, _, m in messages if t == "/finepos/wrench"] == readings


def test_overlay_without_a_bundle_has_centre_and_box_only():
    record = IterationRecord(0.0, "r", "x", 1, 50.0, 40.0, "ok",
                             commanded=ToolStep(1.0, 0.0, 0.0, 0.0))
    est = TranslationEstimate("ok", 2.0, 0.0, 50.0, 40.0, record={"area_px": 400.0})
    o = overlay_of(record, est)
    assert o.centre_px == (50.0, 40.0) and o.box_px == (40.0, 30.0, 60.0, 50.0)
    assert o.roi_px is None and o.gabor_px == () and o.arrow_px is None
    assert Overlay.from_dict(o.as_dict()) == o
    lost = overlay_of(record, TranslationEstimate("no_object"))
    assert lost.centre_px is None and lost.box_px is None


def test_bad_recording_arguments_are_one_line_errors(tmp_path):
    with pytest.raises(RecordingError, match="image format"):
        RunRecorder(tmp_path / "x.mcap", image_format="gif")
    (tmp_path / "file").write_text("")
    with pytest.raises(RecordingError, match="x.mcap"):
        RunRecorder(tmp_path / "file" / "x.mcap")


def test_a_planted_link_is_replaced_not_followed(tmp_path):
    target = tmp_path / "precious.txt"
    target.write_text("keep me")
    path = tmp_path / "rec" / "job-00001-position.mcap"
    path.parent.mkdir()
    path.symlink_to(target)
    _run(path)
    assert target.read_text() == "keep me"
    assert not path.is_symlink() and _messages(path)[0] is not None
    assert [p.name for p in path.parent.iterdir()] == [path.name]  # no temporary file left


def test_a_failed_write_leaves_no_partial_file_and_close_says_so(tmp_path, monkeypatch):
    path = tmp_path / "rec.mcap"
    path.write_bytes(b"the previous run's recording")
    with pytest.raises(RecordingError, match=r"rec\.mcap not written: No space left"):
        with RunRecorder(path) as recorder:
            arm, cam = _devices(START)

            def full(data):
                raise OSError(28, "No space left on device")

            monkeypatch.setattr(recorder._file, "write", full)
            loop = PositioningLoop(arm, cam, LoopConfig(), None, lambda: truth_error(arm),
                                   recorder=recorder)
            assert loop.run(TruthEstimator(arm)) is not None  # the run itself goes on
    assert path.read_bytes() == b"the previous run's recording"
    assert [p.name for p in tmp_path.iterdir()] == ["rec.mcap"]
