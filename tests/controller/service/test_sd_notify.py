"""The sd_notify client: datagrams to $NOTIFY_SOCKET (also abstract), the watchdog interval, and
never blocking on a receiver that stopped reading."""

from __future__ import annotations

import os
import socket
import uuid

import pytest

from controller.service.sd_notify import Notifier
from controller.service.watchdog import WatchdogPinger


def test_messages_arrive_as_datagrams(notify_socket):
    notifier = Notifier({"NOTIFY_SOCKET": str(notify_socket.path)})
    notifier.ready("idle: devices open")
    notifier.watchdog()
    notifier.status("fault: line one\nline two")
    notifier.stopping("stopping")
    notifier.close()
    received = [notify_socket.wait_for(lambda _: True) for _ in range(4)]
    assert received == ["READY=1\nSTATUS=idle: devices open", "WATCHDOG=1",
                        "STATUS=fault: line one line two", "STOPPING=1\nSTATUS=stopping"]


def test_abstract_namespace_address():
    name = f"finepos-test-{uuid.uuid4().hex}"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as receiver:
        receiver.bind("\0" + name)
        notifier = Notifier({"NOTIFY_SOCKET": "@" + name})
        notifier.watchdog()
        notifier.close()
        assert receiver.recv(100) == b"WATCHDOG=1"


def test_without_systemd_nothing_is_sent_and_nothing_fails():
    notifier = Notifier({})
    notifier.ready("idle")
    assert notifier.watchdog_interval_s is None
    notifier.close()


@pytest.mark.parametrize(("environ", "interval_s"), [
    ({"WATCHDOG_USEC": "30000000"}, 15.0),
    ({"WATCHDOG_USEC": "30000000", "WATCHDOG_PID": str(os.getpid())}, 15.0),
    ({"WATCHDOG_USEC": "30000000", "WATCHDOG_PID": "1"}, None),
    ({"WATCHDOG_USEC": "0"}, None),
    ({"WATCHDOG_USEC": "soon"}, None),
    ({}, None),
])
def test_watchdog_interval_is_half_the_timeout_when_meant_for_us(environ, interval_s):
    assert Notifier(environ).watchdog_interval_s == interval_s


def test_a_receiver_that_stopped_reading_does_not_block(notify_socket):
    notifier = Notifier({"NOTIFY_SOCKET": str(notify_socket.path)})
    for _ in range(5000):  # far beyond any datagram queue
        notifier.watchdog()
    notifier.close()


class RecordingNotifier(Notifier):
    def __init__(self) -> None:
        super().__init__({"WATCHDOG_USEC": "2000000"})
        self.sent: list[str] = []

    def notify(self, *fields: str) -> None:
        self.sent.append("\n".join(fields))


def test_pings_are_due_every_interval_and_withheld_while_an_arm_command_hangs():
    notifier = RecordingNotifier()
    pinger = WatchdogPinger(notifier)
    for now_s, busy_s in ((0.0, 0.0), (0.5, 0.0), (1.0, 0.0), (1.5, 9.0), (2.5, 12.0),
                          (3.0, 0.0)):
        pinger.tick(now_s, busy_s, stall_timeout_s=5.0)
    assert notifier.sent == ["WATCHDOG=1", "WATCHDOG=1",
                             "STATUS=an arm command has been running for 9.0 s; watchdog "
                             "withheld", "WATCHDOG=1"]
