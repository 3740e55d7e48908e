"""Who may use the control socket: mode 0660 with the configured group, and the peer's
credentials (SO_PEERCRED, SO_PEERGROUPS) checked against the allowed users and groups."""

from __future__ import annotations

import contextlib
import errno
import json
import os
import socket
import stat

import pytest

from controller.service.peer import PeerCredentials, PeerPolicy
from tests.controller.service.conftest import (
    EVENT_TIMEOUT_S,
    client_for,
    device_opener,
    running_service,
    service_config,
)
from tests.mocks.fakes import FakeArm, FakeCamera, FakeWrenchSensor

SOCKET_GID = 4242  # need not exist in /etc/group: the kernel only compares numbers
OTHER_GID = 4243
NOBODY_UID = 65534

root_only = pytest.mark.skipif(os.geteuid() != 0,
                               reason="connecting as another user needs root (setuid/setgid)")


def test_policy_allows_listed_users_and_group_members_and_no_one_else():
    policy = PeerPolicy.from_config([1001, "0"], [SOCKET_GID])
    assert policy.refusal(PeerCredentials(1, os.geteuid(), 5, ())) is None
    assert policy.refusal(PeerCredentials(1, 1001, 5, ())) is None
    assert policy.refusal(PeerCredentials(1, 0, 5, ())) is None
    assert policy.refusal(PeerCredentials(1, 2000, SOCKET_GID, ())) is None
    assert policy.refusal(PeerCredentials(1, 2000, 5, (7, SOCKET_GID))) is None
    assert policy.refusal(PeerCredentials(9, 2000, 5, (7,))) == \
        "uid 2000 (pid 9) is not an allowed user or group member"


def _status_request(path: str) -> bytes:
    """Send ``status`` and return the answer line, or which errno stopped us."""
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
            sock.settimeout(EVENT_TIMEOUT_S)
            sock.connect(path)
            with contextlib.suppress(BrokenPipeError):  # refused: the answer is waiting
                sock.sendall(b'{"cmd": "status"}\n')
            reply = b""
            while not reply.endswith(b"\n"):
                chunk = sock.recv(65536)
                if not chunk:
                    break
                reply += chunk
            return reply
    except OSError as exc:
        return f"errno {errno.errorcode.get(exc.errno, exc.errno)}".encode()


def connect_as(path: str, uid: int, gid: int, groups: list[int]) -> str:
    """Send ``status`` from a forked child running as uid/gid/groups; what it got back."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: system calls only, then _exit
        try:
            os.close(read_fd)
            os.setgroups(groups)
            os.setgid(gid)
            os.setuid(uid)
            os.write(write_fd, _status_request(path))
        except BaseException as exc:  # reported to the parent through the pipe
            os.write(write_fd, f"child failed: {exc!r}".encode())
        finally:
            os._exit(0)
    os.close(write_fd)
    with os.fdopen(read_fd, "rb") as pipe:
        answer = pipe.read().decode()
    assert os.waitpid(pid, 0)[1] == 0
    return answer


@pytest.fixture
def shared_service(tmp_path, short_dir):
    """A service whose socket folder other users may traverse; only its own user is listed,
    plus members of OTHER_GID."""
    short_dir.chmod(0o711)
    config = service_config(tmp_path, short_dir, service={
        "socket_group": SOCKET_GID, "allowed_groups": [OTHER_GID]})
    with running_service(config, device_opener(FakeArm(), FakeCamera(),
                                               FakeWrenchSensor())) as service:
        yield service


@root_only
def test_socket_is_0660_with_the_configured_group(shared_service):
    info = os.stat(shared_service.socket_path)
    assert stat.S_ISSOCK(info.st_mode) and stat.S_IMODE(info.st_mode) == 0o660
    assert info.st_gid == SOCKET_GID
    with client_for(shared_service) as client:
        assert client.call("status")["state"] == "idle"


@root_only
def test_a_peer_with_the_wrong_uid_is_refused(shared_service):
    answer = json.loads(connect_as(str(shared_service.socket_path), NOBODY_UID, SOCKET_GID, []))
    assert answer["ok"] is False and answer["error"]["code"] == "unauthorized"
    assert answer["error"]["message"].startswith(f"uid {NOBODY_UID} ")
    with client_for(shared_service) as client:
        assert client.call("status")["state"] == "idle"


@root_only
def test_a_peer_outside_the_socket_group_cannot_even_connect(shared_service):
    assert connect_as(str(shared_service.socket_path), NOBODY_UID, NOBODY_UID, []) == \
        "errno EACCES"


@root_only
def test_a_member_of_an_allowed_group_is_served(shared_service):
    answer = json.loads(connect_as(str(shared_service.socket_path), NOBODY_UID, SOCKET_GID,
                                   [OTHER_GID]))
    assert answer["ok"] is True and answer["result"]["state"] == "idle"
