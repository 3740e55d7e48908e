"""The spacenavd client: v0 event decoding, socket path resolution, reads against a fake daemon."""

from __future__ import annotations

import socket
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.core.errors import DeviceNotConnectedError, ProtocolError
from drivers.spacenav import ButtonEvent, MotionEvent, SpacenavClient, resolve_socket_path
from drivers.spacenav.events import EVENT_BYTES, decode_event

TIMEOUT_S = 5.0


def packet(*words: int) -> bytes:
    return struct.pack("=8i", *words, *([0] * (8 - len(words))))


def test_decodes_motion_and_buttons():
    assert decode_event(packet(0, 1, -2, 3, -4, 5, -6, 16)) == MotionEvent(1, -2, 3, -4, 5, -6, 16)
    assert decode_event(packet(1, 5)) == ButtonEvent(5, True)
    assert decode_event(packet(2, 5)) == ButtonEvent(5, False)


@pytest.mark.parametrize("bad", [packet(3), packet(1, -1), b"\0" * 31, b"\0" * 33])
def test_bad_packets_are_protocol_errors(bad):
    with pytest.raises(ProtocolError):
        decode_event(bad)


@given(st.binary(min_size=0, max_size=40))
def test_decoder_gives_an_event_or_a_protocol_error(data):
    try:
        event = decode_event(data)
    except ProtocolError:
        return
    assert isinstance(event, MotionEvent | ButtonEvent)


def test_socket_path_precedence(monkeypatch):
    monkeypatch.delenv("SPNAV_SOCKET", raising=False)
    assert resolve_socket_path() == "/var/run/spnav.sock"
    monkeypatch.setenv("SPNAV_SOCKET", "/tmp/from-env.sock")
    assert resolve_socket_path() == "/tmp/from-env.sock"
    assert resolve_socket_path("/tmp/configured.sock") == "/tmp/configured.sock"


@pytest.fixture
def fake_daemon(tmp_path):
    """A listening AF_UNIX socket standing in for spacenavd; yields (path, accept)."""
    path = str(tmp_path / "spnav.sock")
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as server:
        server.bind(path)
        server.listen(1)
        server.settimeout(TIMEOUT_S)
        yield path, server


def test_reads_events_split_across_writes(fake_daemon):
    path, server = fake_daemon
    with SpacenavClient(path) as client:
        conn, _ = server.accept()
        with conn:
            data = packet(0, 10, 0, 0, 0, 0, 0, 8) + packet(1, 0)
            conn.sendall(data[:5])
            conn.sendall(data[5:40])
            conn.sendall(data[40:])
            assert client.next_event(TIMEOUT_S) == MotionEvent(10, 0, 0, 0, 0, 0, 8)
            assert client.next_event(TIMEOUT_S) == ButtonEvent(0, True)
            assert client.next_event(0.01) is None  # nothing more: times out


def test_partial_packet_is_kept_across_a_timeout(fake_daemon):
    path, server = fake_daemon
    with SpacenavClient(path) as client:
        conn, _ = server.accept()
        with conn:
            data = packet(2, 3)
            conn.sendall(data[:EVENT_BYTES - 1])
            assert client.next_event(0.01) is None
            conn.sendall(data[EVENT_BYTES - 1:])
            assert client.next_event(TIMEOUT_S) == ButtonEvent(3, False)


def test_daemon_hanging_up_disconnects(fake_daemon):
    path, server = fake_daemon
    client = SpacenavClient(path)
    client.connect()
    conn, _ = server.accept()
    conn.close()
    with pytest.raises(DeviceNotConnectedError, match="closed the connection"):
        client.next_event(TIMEOUT_S)
    assert not client.is_connected
    with pytest.raises(DeviceNotConnectedError, match="not connected"):
        client.next_event(0.01)


def test_missing_daemon_is_not_connected(tmp_path):
    with pytest.raises(DeviceNotConnectedError, match="is spacenavd running"):
        SpacenavClient(str(tmp_path / "none.sock")).connect()
