"""Config section ``service:``: where the control socket is, who may use it, how faults recover,
and where metrics are served.

Loaded strictly like every other section (``drivers.core.typed_config``). User and group names are
resolved when the service starts (``controller.service.peer``), not at load, so a config can be
checked on a machine without those accounts.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass, field

_POSITIVE = {"min": 0.0, "exclusive_min": True}


def is_loopback(address: str, key: str) -> bool:
    """Whether the IP address ``address`` (config key ``key``) is a loopback address.

    Raises:
        ValueError: ``address`` is not an IP address (the message names ``key``).
    """
    try:
        return ipaddress.ip_address(address).is_loopback
    except ValueError as exc:
        raise ValueError(f"{key}: expected an IP address, got {address!r}") from exc


@dataclass(frozen=True)
class TcpConfig:
    """The optional TCP listener (``service.tcp``): off unless configured.

    host: must be a loopback address (127.0.0.1 or ::1); port: 1..65535;
    token_file: a file holding the shared token (at least 16 characters, the first line is used);
    it must not be readable by group or others. Every TCP connection must first send
    ``{"cmd": "auth", "args": {"token": ...}}``.
    """

    port: int = field(metadata={"min": 1, "max": 65535})
    token_file: str
    host: str = "127.0.0.1"

    def __post_init__(self) -> None:
        if not is_loopback(self.host, "host"):
            raise ValueError(f"host: the TCP listener must be bound to loopback, got {self.host!r}")
        if not self.token_file.strip():
            raise ValueError("token_file: must name the token file")


LIVE_PORT = 8765  # Foxglove's default for a WebSocket connection


@dataclass(frozen=True)
class LiveConfig:
    """The live view (``service.live``): the cell's channels over the Foxglove WebSocket
    protocol (``controller.recording.live``), for Foxglove to connect to.

    port: 1..65535 (8765, Foxglove's default); address: the address it binds to (an IP address;
    127.0.0.1 by default); any other than loopback needs ``service.tcp`` (its token_file), and
    every connection then sends that token (``Authorization: Bearer <token>`` or
    ``?token=<token>`` in the URL).
    """

    port: int = field(default=LIVE_PORT, metadata={"min": 1, "max": 65535})
    address: str = "127.0.0.1"

    def __post_init__(self) -> None:
        is_loopback(self.address, "address")


@dataclass(frozen=True)
class ServiceConfig:
    """Config section ``service``: the long-running controller (``finepos serve``).

    socket_path: the UNIX control socket (``--socket`` overrides it); created with mode 0660;
    socket_group: group owning the socket (name or number; None: the service's own group);
    allowed_users / allowed_groups: peers (checked with SO_PEERCRED) allowed besides the
    service's own user; names or numeric ids; a peer is allowed when its uid is listed or its
    primary or a supplementary group is;
    max_request_bytes: longest request line; max_clients: connections served at once;
    request_rate_hz / request_burst: each connection's answers are paced to this rate after a
    burst of this many (``controller.service.pacing``; ``abort`` is never paced; 0 Hz: off);
    idle_timeout_s: a connection that sends no request for this long is closed (``stream``
    connections excepted); request_timeout_s: a request line must be complete this long after
    its first byte (a byte-a-second peer is closed);
    max_clients_per_uid: connections served at once per peer uid (TCP peers count as one);
    max_waiting: authorised peers over either limit still connect, up to this many, and may
    send one ``abort`` or ``status`` within request_timeout_s (answered by the accept thread,
    so idle connections can never lock out an abort); anything else gets too_many_clients;
    idle_poll_s: while idle, read the arm's pose this often to notice a lost link (0: never);
    reconnect_initial_s / reconnect_max_s: backoff between reconnection attempts after a fault
    (doubling from the first to the second);
    stall_timeout_s: one arm command running longer than this withholds the systemd watchdog
    ping, so systemd restarts a hung service (keep it above the arm's own move timeout);
    stop_timeout_s: the whole shutdown (halt, the aborted job, the clients, the ports) ends
    within this, whatever the devices and clients do;
    abort_wait_s: ``abort`` waits this long for the arm to acknowledge the halt before answering
    (a halt still unanswered then is reported in the answer and later as a ``halt`` event);
    tcp: the optional loopback TCP listener (None: no network listener);
    record_dir: record every positioning job as ``<job>.mcap`` in this folder
    (``controller.recording``; None: no recordings);
    live: the live view for Foxglove (hand camera, overlays, tool pose, wrench, iteration
    records; ``LiveConfig``; None: off);
    metrics_port: serve Prometheus metrics (text format) over HTTP at this port
    (``controller.service.metrics``; None: off);
    metrics_address: the address the metrics port binds to (an IP address; 127.0.0.1 by
    default); any other than loopback needs ``service.tcp`` (its token_file), and every scrape
    then sends ``Authorization: Bearer <token>`` with that token;
    self_check_at_start: at start, move to the taught pose and run the self-check
    (``finepos check``); when it fires the service starts in fault (code ``self_check``) and
    refuses motion until a reset (off by default: it moves the arm at start).
    """

    socket_path: str = "/run/finepos/finepos.sock"
    socket_group: int | str | None = None
    allowed_users: tuple[int | str, ...] = ()
    allowed_groups: tuple[int | str, ...] = ()
    max_request_bytes: int = field(default=16384, metadata={"min": 512, "max": 1 << 20})
    max_clients: int = field(default=32, metadata={"min": 1, "max": 1024})
    request_rate_hz: float = field(default=20.0, metadata={"min": 0.0, "max": 1e6})
    request_burst: int = field(default=5, metadata={"min": 1, "max": 10000})
    idle_timeout_s: float = field(default=60.0, metadata={**_POSITIVE, "max": 86400.0})
    request_timeout_s: float = field(default=5.0, metadata={**_POSITIVE, "max": 3600.0})
    max_clients_per_uid: int = field(default=8, metadata={"min": 1, "max": 1024})
    max_waiting: int = field(default=256, metadata={"min": 1, "max": 4096})
    idle_poll_s: float = field(default=2.0, metadata={"min": 0.0})
    reconnect_initial_s: float = field(default=0.5, metadata=_POSITIVE)
    reconnect_max_s: float = field(default=30.0, metadata=_POSITIVE)
    stall_timeout_s: float = field(default=180.0, metadata=_POSITIVE)
    stop_timeout_s: float = field(default=2.0, metadata={**_POSITIVE, "max": 600.0})
    abort_wait_s: float = field(default=0.05, metadata={**_POSITIVE, "max": 10.0})
    tcp: TcpConfig | None = None
    record_dir: str | None = None
    live: LiveConfig | None = None
    metrics_port: int | None = field(default=None, metadata={"min": 1, "max": 65535})
    metrics_address: str = "127.0.0.1"
    self_check_at_start: bool = False

    def __post_init__(self) -> None:
        if not self.socket_path.strip():
            raise ValueError("socket_path: must name the control socket")
        if not is_loopback(self.metrics_address, "metrics_address") and self.tcp is None:
            raise ValueError(f"metrics_address: {self.metrics_address} is not loopback: that "
                             "needs service.tcp.token_file (scrapes send its token)")
        if self.live is not None and not is_loopback(self.live.address, "live.address") \
                and self.tcp is None:
            raise ValueError(f"live.address: {self.live.address} is not loopback: that needs "
                             "service.tcp.token_file (live clients send its token)")
        if self.reconnect_max_s < self.reconnect_initial_s:
            raise ValueError("reconnect_max_s must be at least reconnect_initial_s, got "
                             f"{self.reconnect_max_s} / {self.reconnect_initial_s}")
