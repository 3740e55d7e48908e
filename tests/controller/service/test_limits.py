"""Connection limits and timeouts: idle and slow peers are disconnected, each uid has its own
limit, and peers over the limits can still send ``abort`` and ``status``, so 200 idle or
byte-a-second connections never lock out an abort."""

from __future__ import annotations

import socket
import threading
import time

import pytest

from controller.service.client import ServiceClient, ServiceError
from controller.service.listeners import read_token
from drivers.core.errors import ConfigError
from tests.controller.service.conftest import (
    EVENT_TIMEOUT_S,
    client_for,
    device_opener,
    free_port,
    running_service,
    service_config,
    token_file,
)
from tests.mocks.fakes import FakeArm, FakeCamera, FakeWrenchSensor


@pytest.fixture
def fakes():
    return FakeArm(), FakeCamera(), FakeWrenchSensor()


def raw_peer(service) -> socket.socket:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.connect(str(service.socket_path))  # blocking: waits for room in the backlog
    sock.settimeout(EVENT_TIMEOUT_S)
    return sock


def closed_by_service(sock: socket.socket) -> bool:
    """Wait (up to EVENT_TIMEOUT_S) for the service to close the connection."""
    try:
        return sock.recv(4096) == b""
    except ConnectionResetError:
        return True


def test_an_idle_peer_is_disconnected(tmp_path, short_dir, fakes):
    config = service_config(tmp_path, short_dir, service={"idle_timeout_s": 0.2})
    with running_service(config, device_opener(*fakes)) as service, raw_peer(service) as idle:
        idle.sendall(b'{"cmd": "status"}\n')
        assert b'"ok":true' in idle.recv(65536)
        assert closed_by_service(idle)


def test_a_byte_a_second_peer_is_disconnected(tmp_path, short_dir, fakes):
    config = service_config(tmp_path, short_dir, service={"request_timeout_s": 0.3,
                                                          "idle_timeout_s": 60.0})
    with running_service(config, device_opener(*fakes)) as service, raw_peer(service) as slow:
        stop = threading.Event()

        def trickle() -> None:
            for byte in b'{"cmd": "status"}':
                if stop.wait(0.1):
                    return
                try:
                    slow.send(bytes([byte]))
                except OSError:
                    return

        thread = threading.Thread(target=trickle)
        thread.start()
        try:
            assert closed_by_service(slow)
        finally:
            stop.set()
            thread.join()


def test_a_stream_is_not_idle_timed_out(tmp_path, short_dir, fakes):
    config = service_config(tmp_path, short_dir, service={"idle_timeout_s": 0.1})
    with running_service(config, device_opener(*fakes)) as service, \
            client_for(service) as listener:
        events = listener.events(timeout_s=EVENT_TIMEOUT_S)
        time.sleep(0.5)
        with client_for(service) as other:
            other.call("abort")
        service.stop()
        assert [e for e in events][-1]["event"] == "end"


def test_each_uid_has_its_own_limit(tmp_path, short_dir, fakes):
    config = service_config(tmp_path, short_dir, service={"max_clients_per_uid": 2,
                                                          "max_clients": 10})
    with running_service(config, device_opener(*fakes)) as service, \
            client_for(service) as first, client_for(service) as second, \
            client_for(service) as third:
        assert first.call("status") and second.call("status")
        with pytest.raises(ServiceError) as refused:
            third.call("reset")
        assert refused.value.code == "too_many_clients"
        assert "max_clients_per_uid" in refused.value.message


@pytest.mark.parametrize(("key", "value"), [("request_timeout_s", 0), ("idle_timeout_s", -1),
                                            ("max_clients_per_uid", 0), ("max_waiting", 0),
                                            ("request_rate_hz", -1.0), ("request_burst", 0)])
def test_limit_keys_are_strict(tmp_path, short_dir, key, value):
    with pytest.raises(ConfigError, match=f"service.{key}"):
        service_config(tmp_path, short_dir, service={key: value})


@pytest.mark.parametrize("kind", ["idle", "byte_a_second"])
def test_abort_gets_through_200_idle_or_slow_peers(tmp_path, short_dir, fakes, kind):
    config = service_config(tmp_path, short_dir, service={"request_timeout_s": 30.0})
    with running_service(config, device_opener(*fakes)) as service:
        peers = [raw_peer(service) for _ in range(200)]
        stop = threading.Event()

        def trickle() -> None:
            while not stop.wait(1.0):
                for peer in peers:
                    try:
                        peer.send(b" ")
                    except OSError:
                        pass

        thread = threading.Thread(target=trickle)
        if kind == "byte_a_second":
            for peer in peers:
                peer.send(b"{")
            thread.start()
        try:
            time.sleep(0.3)  # let the accept thread take them all in
            with ServiceClient(service.socket_path, timeout_s=EVENT_TIMEOUT_S) as operator:
                t0 = time.perf_counter()
                answer = operator.call("abort")
                elapsed_s = time.perf_counter() - t0
            assert answer["halted"] is True and fakes[0].halts >= 1
            assert elapsed_s < 1.0, f"abort took {elapsed_s:.3f} s"  # generous; bench: ~ms
        finally:
            stop.set()
            if thread.is_alive():
                thread.join()
            for peer in peers:
                peer.close()


def test_abort_is_obeyed_with_every_waiting_place_taken(tmp_path, short_dir, fakes):
    config = service_config(tmp_path, short_dir, service={
        "max_clients_per_uid": 2, "max_waiting": 4, "request_timeout_s": 30.0})
    with running_service(config, device_opener(*fakes)) as service:
        # the accept thread takes peers in the order they connected: all of these are in
        # (2 served, 4 waiting, 3 more pushing out the oldest) before the operator is
        peers = [raw_peer(service) for _ in range(9)]
        try:
            for _ in range(3):
                with client_for(service) as operator:
                    assert operator.call("abort")["halted"] is True
                peers.append(raw_peer(service))  # the flood goes on between the aborts
        finally:
            for peer in peers:
                peer.close()


def test_unauthenticated_tcp_peers_cannot_lock_out_the_token_holder(tmp_path, short_dir, fakes):
    tokens, port = token_file(tmp_path), free_port()
    config = service_config(tmp_path, short_dir, service={
        "tcp": {"port": port, "token_file": str(tokens)}})
    with running_service(config, device_opener(*fakes)):
        silent = [socket.create_connection(("127.0.0.1", port)) for _ in range(2 * 4)]
        try:
            for _ in range(10):
                silent.append(socket.create_connection(("127.0.0.1", port)))
                with ServiceClient(tcp=("127.0.0.1", port), token=read_token(tokens),
                                   timeout_s=EVENT_TIMEOUT_S) as operator:
                    assert operator.call("abort")["halted"] is True
        finally:
            for sock in silent:
                sock.close()
