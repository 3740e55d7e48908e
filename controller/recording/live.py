"""Live view: the cell's channels served over the Foxglove WebSocket protocol, for Foxglove.

``LiveServer`` is a look recorder (the positioning loop's ``recorder`` hook, like
``RunRecorder``) whose sink is the Foxglove SDK's WebSocket server instead of a file: the hand
camera, its overlay, the tool pose, each iteration's record, the wrench readings and the grasp's
end, on the channels of ``controller.recording.channels``, stamped with the cell's clock. ``Tee``
hands each look to several recorders (a recording and the live view).

The server binds to 127.0.0.1 unless told otherwise (``service.live``); bound elsewhere, a client
must send the TCP control token (``controller.recording.live_gate``). Messages
go to each client through a queue of its own of ``BACKLOG_MESSAGES``, drained by the SDK's
threads; a client that stops reading loses the oldest messages, never holds up the loop. A
message no client subscribed to is not built (a frame nobody watches is not encoded).
"""

from __future__ import annotations

import ipaddress
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import foxglove
from foxglove import Context

from controller.loop.record import IterationRecord
from controller.recording.channels import CellChannels, RecordingError, RecordingSensor
from controller.recording.live_gate import TokenGate
from controller.systems.estimator import TranslationEstimate
from drivers.core.pose import Pose
from drivers.interfaces import Frame, Wrench, WrenchSensor

logger = logging.getLogger(__name__)

# Messages queued per client: a look is about 4 messages, so a client may lag by some 250 looks
# before it loses any; a queue holds at most one frame per message (a few kB each).
BACKLOG_MESSAGES = 1024


class LiveServer:
    """The Foxglove WebSocket server of the cell's channels; use as a context manager.

    Args:
        port: the TCP port (0: any free one; ``port`` then says which).
        address: the IP address to bind. Off loopback the SDK's server listens on a private
            loopback port behind a ``TokenGate`` on ``address`` that admits only clients
            sending ``token``.
        token: the token a client off loopback must send (``service.tcp.token_file``).
        name: the server's name, as Foxglove shows it.

    Raises:
        RecordingError: the port cannot be bound (in use, or not allowed), or ``address`` is
            not loopback and there is no token.
    """

    def __init__(self, port: int, address: str = "127.0.0.1",
                 token: str | None = None, name: str = "finepos") -> None:
        try:
            gated = not ipaddress.ip_address(address).is_loopback
        except ValueError:
            raise RecordingError(f"live view: expected an IP address, got {address!r}") from None
        self.address = address
        if gated and not token:
            raise RecordingError(f"live view on {address}: not loopback, so it needs the "
                                 "TCP control token (service.tcp.token_file)")
        self._context = Context()  # held for the server's life
        self._channels = CellChannels(self._context)
        self._lock = threading.Lock()
        self._gate: TokenGate | None = None
        self.looks = 0
        try:
            self._server = foxglove.start_server(
                name=name, host="127.0.0.1" if gated else address, port=0 if gated else port,
                context=self._context, message_backlog_size=BACKLOG_MESSAGES)
        except Exception as exc:  # the SDK raises RuntimeError for a bind error
            self._channels.close()
            text = " ".join(str(exc).split())
            raise RecordingError(f"live view on {address}:{port}: cannot listen ({text})"
                                 ) from None
        if gated:
            try:
                self._gate = TokenGate(address, port, self._server.port, token).start()
            except OSError as exc:
                self._channels.close()
                self._server.stop()
                raise RecordingError(f"live view on {address}:{port}: cannot listen "
                                     f"({exc.strerror or exc})") from None
        self._closed = False
        logger.info("live view (Foxglove WebSocket) on %s%s", self.url,
                    " (token required)" if gated else "")

    @property
    def port(self) -> int:
        """The port clients connect to."""
        return self._gate.port if self._gate is not None else self._server.port

    @property
    def url(self) -> str:
        """The address Foxglove opens (``Open connection``, Foxglove WebSocket)."""
        host = f"[{self.address}]" if ":" in self.address else self.address
        return f"ws://{host}:{self.port}"

    def subscribed(self) -> set[str]:
        """The topics some client is subscribed to now."""
        return self._channels.subscribed()

    def close(self) -> None:
        """Stop the server (clients are disconnected); later calls do nothing."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        if self._gate is not None:
            self._gate.close()
        self._channels.close()
        self._server.stop()

    def __enter__(self) -> LiveServer:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # -- the recorder hooks ----------------------------------------------------------------
    def look(self, record: IterationRecord, frame: Frame, estimate: TranslationEstimate,
             estimator: Any = None,
             error_at_look: tuple[float, float, float] | None = None) -> None:
        """Send one look of the positioning loop to the subscribed clients."""
        if self._closed:
            return
        self._channels.look(record, frame, estimate, estimator, error_at_look)
        self.looks += 1

    def pose(self, pose: Pose, t_s: float | None = None) -> None:
        """Send the tool pose at ``t_s`` (default: now, monotonic)."""
        if not self._closed:
            self._channels.pose(pose, time.monotonic() if t_s is None else t_s)

    def wrench(self, wrench: Wrench, t_s: float | None = None) -> None:
        """Send one wrist reading at ``t_s`` (default: now, monotonic)."""
        if not self._closed:
            self._channels.wrench(wrench, time.monotonic() if t_s is None else t_s)

    def grasp_event(self, result: Any, t_s: float | None = None) -> None:
        """Send how a grasp ended."""
        if not self._closed:
            self._channels.grasp_event(result, time.monotonic() if t_s is None else t_s)

    def recording_sensor(self, sensor: WrenchSensor,
                         clock: Callable[[], float] | None = None) -> WrenchSensor:
        """``sensor`` with every ``read()`` also sent, stamped by ``clock`` (cell seconds)."""
        return RecordingSensor(sensor, self, clock)


class Tee:
    """Hands every look, reading and grasp event to each of ``recorders``."""

    def __init__(self, *recorders: Any) -> None:
        self.recorders = [r for r in recorders if r is not None]

    def look(self, record: IterationRecord, frame: Frame, estimate: TranslationEstimate,
             estimator: Any = None,
             error_at_look: tuple[float, float, float] | None = None) -> None:
        """Pass the look to every recorder."""
        for r in self.recorders:
            r.look(record, frame, estimate, estimator, error_at_look)

    def recording_sensor(self, sensor: WrenchSensor, clock: Any = None) -> WrenchSensor:
        """``sensor`` wrapped by every recorder in turn."""
        for r in self.recorders:
            sensor = r.recording_sensor(sensor, clock)
        return sensor

    def grasp_event(self, result: Any, t_s: float | None = None) -> None:
        """Pass the grasp's end to every recorder."""
        for r in self.recorders:
            r.grasp_event(result, t_s)
