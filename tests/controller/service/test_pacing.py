"""Per-connection pacing (token bucket) and the status snapshot."""

from __future__ import annotations

import json

import pytest

from controller.service.pacing import RequestPacer
from controller.service.protocol import EncodedResult, ok_line
from controller.service.snapshot import StatusSnapshot


def test_pacer_allows_a_burst_then_spaces_answers_at_the_rate():
    pacer = RequestPacer(rate_hz=10.0, burst=3)
    t0 = pacer._at_s
    assert [pacer.delay_s(t0) for _ in range(3)] == [0.0, 0.0, 0.0]
    assert pacer.delay_s(t0) == pytest.approx(0.1)
    assert pacer.delay_s(t0) == pytest.approx(0.2)
    # after a quiet second the bucket is full again, never fuller than the burst
    assert [pacer.delay_s(t0 + 10.0) for _ in range(3)] == [0.0, 0.0, 0.0]
    assert pacer.delay_s(t0 + 10.0) == pytest.approx(0.1)


def test_pacer_at_zero_hz_never_delays():
    pacer = RequestPacer(rate_hz=0.0, burst=1)
    assert all(pacer.delay_s() == 0.0 for _ in range(1000))


def test_ok_line_splices_an_encoded_result():
    line = ok_line("a", EncodedResult(b'{"state":"idle","n":[1,2]}'))
    assert line.endswith(b"\n")
    assert json.loads(line) == {"id": "a", "ok": True, "result": {"state": "idle", "n": [1, 2]}}
    assert json.loads(ok_line(None, {"x": 1})) == {"id": None, "ok": True, "result": {"x": 1}}


def test_status_snapshot_rebuilds_only_when_an_input_changes():
    inputs = {"record": {"i": 1}, "state": ("idle", 1.0, "ready")}
    built = []

    def build():
        built.append(dict(inputs))
        return {"state": inputs["state"][0], "record": inputs["record"]}

    snapshot = StatusSnapshot(build, lambda: (inputs["state"], inputs["record"]), max_age_s=1e9)
    first = snapshot.get()
    assert snapshot.get() is first and snapshot.builds == 1
    inputs["state"] = ("idle", 1.0, "ready")  # an equal tuple of plain values: no rebuild
    assert snapshot.get() is first and snapshot.builds == 1
    inputs["record"] = {"i": 2}  # a new object (even if it were equal): rebuilt
    assert json.loads(snapshot.get())["record"] == {"i": 2} and snapshot.builds == 2
    inputs["state"] = ("positioning", 2.0, "job 1")
    assert json.loads(snapshot.get())["state"] == "positioning" and snapshot.builds == 3


def test_status_snapshot_expires():
    snapshot = StatusSnapshot(lambda: {"x": 1}, lambda: (), max_age_s=0.0)
    snapshot.get()
    snapshot.get()
    assert snapshot.builds == 2
