"""The service holds the state folder's lock while it runs (issue 51, defect 9): a second service
on the same state folder is refused naming the first one's PID before it writes or binds
anything, a CLI writer is refused too, and the lock is free again once the service stopped."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from controller import cli
from controller.service.config_reload import restart_only_changes
from controller.service.service import Service
from controller.teach.state_lock import StateFolderLocked, locked_state_folder
from tests.controller.service.conftest import device_opener, running_service, service_config
from tests.mocks.fakes import FakeArm, FakeCamera, FakeWrenchSensor


def _opener():
    return device_opener(FakeArm(), FakeCamera(), FakeWrenchSensor())


def test_a_second_service_on_the_same_state_folder_is_refused(tmp_path, short_dir, capsys):
    config = service_config(tmp_path, short_dir)
    other_socket = short_dir / "other.sock"
    second = service_config(tmp_path, short_dir, service={"socket_path": str(other_socket)})
    state = Path(config.controller.paths.state_dir)
    with running_service(config, _opener()) as first:
        with pytest.raises(StateFolderLocked) as refused:
            Service(second, opener=_opener()).run()
        assert refused.value.pid == os.getpid()
        assert f"finepos serve on {first.socket_path}" in str(refused.value)
        assert not other_socket.exists()  # refused before it bound anything
        assert cli.main(["acquire", "--set", "nn1", "--state-dir", str(state)]) == 2
        assert f"in use by PID {os.getpid()}" in capsys.readouterr().err
    with locked_state_folder(state, "after the service"):  # released at its stop
        pass


def test_the_state_folder_cannot_change_in_a_reload(tmp_path, short_dir):
    config = service_config(tmp_path, short_dir)
    moved = service_config(tmp_path, short_dir,
                           controller={"paths": {"state_dir": str(tmp_path / "elsewhere"),
                                                 "log_dir": str(tmp_path / "log")}})
    assert restart_only_changes(config, moved) == ["controller.paths.state_dir"]
