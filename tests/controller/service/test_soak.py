"""``finepos bench soak``: its bookkeeping (motion windows, partial files, lost log lines) and,
marked slow, short soaks whose invariants must hold, and one that must catch an unsafe motion."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from controller.service.soak import (
    FAULT_KINDS,
    MotionLedger,
    Soak,
    is_motion,
    lost_log_lines,
    partial_files,
)


def test_motion_lines():
    assert is_motion("do move trans(1,2,3,4,5,6)")
    assert is_motion("DO READY")
    assert is_motion("cal")
    assert is_motion("ex fpdesc")  # a program run (arm.programs)
    assert not is_motion("do set fpd=trans(1,2,3,4,5,6)")
    assert not is_motion("edit fpdesc") and not is_motion("listp fpdesc")
    assert not is_motion("where")
    assert not is_motion("speed 50")
    assert not is_motion("abort")
    assert not is_motion("")


def test_ledger_counts_motion_only_inside_a_window():
    ledger = MotionLedger()
    ledger.on_val("command", "do move trans(1,2,3,4,5,6)")
    ledger.on_val("command", "where")
    assert ledger.motions == 1 and not ledger.unsafe
    ledger.open("position:aborted")
    ledger.on_val("command", "where")  # reading is allowed
    ledger.on_val("command", "do closei")
    assert [u["line"] for u in ledger.unsafe] == ["do closei"]
    ledger.close()
    ledger.on_val("command", "do openi")
    assert len(ledger.unsafe) == 1 and ledger.motions == 3


def test_a_val_fault_opens_a_window_at_once():
    ledger = MotionLedger()
    ledger.on_val("fault", "garbage")
    ledger.on_val("command", "do ready")
    assert ledger.val_faults["garbage"] == 1
    assert ledger.unsafe[0]["after"] == ["val_garbage"]


def test_partial_files_finds_temporary_empty_and_torn_files(tmp_path: Path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "good.json").write_text(json.dumps({"a": 1}))
    (tmp_path / "sub" / "log.jsonl").write_text('{"a": 1}\n{"b": 2}\n')
    assert partial_files([tmp_path, tmp_path / "missing"]) == []
    (tmp_path / ".model.bin.x1.tmp").write_bytes(b"half")
    (tmp_path / "empty.npz").write_bytes(b"")
    (tmp_path / "bad.json").write_text('{"a": ')
    (tmp_path / "sub" / "torn.jsonl").write_text('{"a": 1}\n{"b": ')
    found = {Path(p).name for p in partial_files([tmp_path])}
    assert found == {".model.bin.x1.tmp", "empty.npz", "bad.json", "torn.jsonl"}


def test_lost_log_lines_compares_reported_iterations_with_records(tmp_path: Path):
    log = tmp_path / "iterations.jsonl"
    log.write_text("".join(json.dumps({"run_id": run}) + "\n" for run in ("a", "a", "b")))
    assert lost_log_lines(log, {"a": 2, "b": 1}) == (0, 0)
    assert lost_log_lines(log, {"a": 3, "b": 1, "c": 2}) == (3, 0)
    with open(log, "a", encoding="utf-8") as f:
        f.write('{"run_id": "b"')  # a torn last line
    assert lost_log_lines(log, {"a": 2, "b": 1}) == (0, 1)
    assert lost_log_lines(tmp_path / "none.jsonl", {"a": 2}) == (2, 0)


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="unknown fault kind"):
        Soak(1, True, 0, kinds=("meteor",))
    with pytest.raises(ValueError, match="fault_rate"):
        Soak(1, True, 0, fault_rate=1.5)
    with pytest.raises(ValueError, match="timing"):
        Soak(1, True, 0, timing="fast")


@pytest.mark.slow
@pytest.mark.parametrize("programs", [False, True], ids=["host path", "program path"])
def test_short_soak_with_faults_keeps_its_invariants(programs):
    report = Soak(14, True, seed=3, fault_rate=1.0, programs=programs).run()
    assert report["cycles"] == 14
    assert report["faults_injected"] > 0
    assert report["faults_recovered"] == report["faults_injected"], report["problems"]
    assert report["unsafe_motions"] == 0, report["unsafe"]
    assert report["log_lines_lost"] == 0
    assert report["partial_files"] == 0, report["partial"]
    assert report["fd_growth"] <= 0
    assert report["positioning_runs"] > 0 and report["iterations_reported"] > 0
    assert set(report["faults"]) <= set(FAULT_KINDS)


@pytest.mark.slow
def test_soak_counts_the_motion_of_a_client_that_skips_the_reset():
    """A client that moves again after an abort without ``reset``: the VAL emulator receives
    that motion inside the window, and the soak must count it."""
    report = Soak(5, True, seed=1, fault_rate=1.0, kinds=("abort",),
                  reset_after_abort=False).run()
    assert report["faults"]["abort"]["injected"] > 0
    assert report["unsafe_motions"] > 0
    assert all("aborted" in " ".join(u["after"]) for u in report["unsafe"])
