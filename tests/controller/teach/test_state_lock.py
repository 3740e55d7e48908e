"""The state folder's lock (controller.teach.state_lock): one writer at a time, the holder's PID
in the refusal, released on every way out; and the CLI's writers taking it (issue 51)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from controller import cli
from controller.teach.state_lock import (
    LOCK_NAME,
    StateFolderLocked,
    StateLockError,
    locked_state_folder,
)

HOLD = r"""
import sys
from controller.teach.state_lock import locked_state_folder

with locked_state_folder(sys.argv[1], "finepos test-holder"):
    print("held", flush=True)
    sys.stdin.readline()
"""


def test_a_second_writer_is_refused_naming_the_holder(tmp_path):
    state = tmp_path / "state"
    with locked_state_folder(state, "finepos serve on /run/fp.sock") as path:
        assert path == state / LOCK_NAME
        with pytest.raises(StateFolderLocked) as refused, locked_state_folder(state, "other"):
            pass
    assert refused.value.pid == os.getpid()
    message = str(refused.value)
    assert f"PID {os.getpid()} (finepos serve on /run/fp.sock)" in message
    assert str(state) in message and "\n" not in message


def test_the_lock_is_released_on_every_way_out(tmp_path):
    with pytest.raises(RuntimeError), locked_state_folder(tmp_path, "a"):
        raise RuntimeError("a failing command")
    with pytest.raises(KeyboardInterrupt), locked_state_folder(tmp_path, "b"):
        raise KeyboardInterrupt
    with locked_state_folder(tmp_path, "c"):
        pass  # free again after both


def test_another_process_holding_it_is_named_by_its_pid(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(tmp_path)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(StateFolderLocked) as refused, locked_state_folder(tmp_path, "x"):
            pass
        assert refused.value.pid == holder.pid
        assert f"PID {holder.pid} (finepos test-holder)" in str(refused.value)
    finally:
        holder.communicate("\n", timeout=10)
    with locked_state_folder(tmp_path, "after"):  # the holder's exit released it
        pass


def test_a_lock_file_planted_as_a_symlink_or_fifo_is_refused(tmp_path):
    target = tmp_path / "precious"
    target.write_text("keep\n")
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / LOCK_NAME).symlink_to(target)
    with pytest.raises(StateLockError, match="symlink"), locked_state_folder(tmp_path / "a", "x"):
        pass
    assert target.read_text() == "keep\n"
    (tmp_path / "b").mkdir()
    os.mkfifo(tmp_path / "b" / LOCK_NAME)
    with pytest.raises(StateLockError, match="not a regular file"), \
            locked_state_folder(tmp_path / "b", "x"):
        pass


@pytest.mark.parametrize("argv", [["teach", "--auto"], ["acquire", "--set", "nn1"], ["train"],
                                  ["rezero"], ["position"], ["grasp"]])
def test_cli_writers_are_refused_while_the_folder_is_held(tmp_path, capsys, argv):
    with locked_state_folder(tmp_path, "finepos serve on /run/fp.sock"):
        status = cli.main([*argv, "--state-dir", str(tmp_path)])
    assert status == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("finepos: error: ")
    assert f"in use by PID {os.getpid()} (finepos serve on /run/fp.sock)" in err[0]


def test_a_cli_writer_releases_the_folder_when_it_fails(tmp_path, capsys):
    assert cli.main(["train", "--state-dir", str(tmp_path)]) == 2  # nothing taught
    assert "in use" not in capsys.readouterr().err
    with locked_state_folder(tmp_path, "next"):
        pass


def test_only_teach_creates_a_missing_state_folder(tmp_path, capsys):
    missing = tmp_path / "typo"
    assert cli.main(["train", "--state-dir", str(missing)]) == 2  # nothing taught there
    assert not missing.exists()
    with locked_state_folder(missing, "x", create=False) as path:
        assert path is None
    with locked_state_folder(missing, "x") as path:
        assert path == missing / LOCK_NAME
