"""The serial line to the VAL II monitor: send one line, collect its reply within a timeout.

The port is opened with ``serial.serial_for_url``, so a device, a pty, ``socket://``, ``spy://``
and ``loop://`` all work. Bytes still waiting from an earlier exchange are dropped before each
command. Failures come out typed: DeviceTimeoutError (no complete reply in time), ProtocolError
(line noise, missing echo, a reply that never ends) and DeviceFaultError (the link broke).

``interrupt()`` (from another thread: a halt) ends the exchange in flight within one read poll
with ExchangeInterrupted, so a halt never waits behind a move whose reply will not come.
``close()`` interrupts too and waits for the exchange to leave before closing the port, so the
port is never closed under a running exchange.
"""

from __future__ import annotations

import logging
import threading
import time

import serial

from drivers.core.errors import (
    DeviceFaultError,
    DeviceNotConnectedError,
    DeviceTimeoutError,
    ProtocolError,
)
from drivers.val.config import ValConfig
from drivers.val.replies import Reply, parse_reply, reply_complete

logger = logging.getLogger(__name__)

# Longest single blocking read; bounds how late a timeout is noticed, not the latency (a read
# returns as soon as a byte arrives).
_READ_POLL_S = 0.05
# A reply longer than this is line noise or a runaway listing.
_MAX_REPLY_BYTES = 64 * 1024
# close() waits this long for an interrupted exchange to leave before closing anyway.
_CLOSE_WAIT_S = 0.25


class ExchangeInterrupted(ProtocolError):
    """The exchange was ended by ``ValLink.interrupt`` (a halt) before its reply was complete."""


class ValLink:
    """One serial connection to the monitor; ``exchange`` is safe to call from several threads.

    bytes_written / bytes_read count every byte sent and received since construction.
    """

    def __init__(self, config: ValConfig) -> None:
        self.config = config
        self._port: serial.SerialBase | None = None
        self._lock = threading.Lock()
        self._interrupts = 0  # bumped by interrupt(); an exchange started before it ends
        self.bytes_written = 0
        self.bytes_read = 0
        self.last_partial = b""  # what the last exchange that timed out had received

    def open(self) -> None:
        """Open the port (raises DeviceFaultError when it cannot be opened)."""
        cfg = self.config
        try:
            self._port = serial.serial_for_url(
                cfg.port, baudrate=cfg.baudrate, bytesize=cfg.bytesize, parity=cfg.parity,
                stopbits=cfg.stopbits, timeout=_READ_POLL_S, write_timeout=cfg.exchange_timeout_s,
                xonxoff=False, rtscts=False, dsrdtr=False)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceFaultError(f"cannot open VAL port {cfg.port!r}: {exc}") from exc
        logger.info("VAL link open on %s", cfg.port)

    def interrupt(self) -> None:
        """End the exchange now in flight (if any) at its next read poll (thread-safe)."""
        self._interrupts += 1

    def close(self) -> None:
        """Close the port; never raises (the link may already be broken).

        An exchange in flight is interrupted first and the port closed once it has left (within
        one read poll); one stuck in a write longer than _CLOSE_WAIT_S finds its port closed and
        ends with DeviceFaultError.
        """
        self.interrupt()
        locked = self._lock.acquire(timeout=_CLOSE_WAIT_S)
        try:
            port, self._port = self._port, None
            if port is None:
                return
            try:
                port.close()
            except (serial.SerialException, OSError) as exc:
                logger.debug("closing VAL port %s: %s", self.config.port, exc)
        finally:
            if locked:
                self._lock.release()

    def exchange(self, line: str, timeout_s: float, echo: bool) -> Reply:
        """Send ``line`` plus the line ending and return the classified reply.

        Args:
            line: the command or answer, without line ending.
            timeout_s: longest wait for the whole reply.
            echo: whether the reply must start with the echo of ``line``.
        """
        generation = self._interrupts
        with self._lock:
            port = self._port
            if port is None:
                raise DeviceNotConnectedError("VAL link is not open")
            command = line if echo else None
            try:
                port.reset_input_buffer()
                payload = (line + self.config.line_ending).encode("ascii")
                port.write(payload)
                self.bytes_written += len(payload)
                data = self._read_reply(port, command, timeout_s, line, generation)
            except serial.SerialTimeoutException as exc:
                raise DeviceTimeoutError(f"VAL link: sending {line!r} timed out") from exc
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                # TypeError/AttributeError: pyserial's answer to a port closed under a read.
                raise DeviceFaultError(f"VAL link lost during {line!r}: "
                                       f"{type(exc).__name__}: {exc}") from exc
            logger.debug("VAL %r -> %r", line, data)
            return parse_reply(data, command)

    def _read_reply(self, port: serial.SerialBase, command: str | None, timeout_s: float,
                    line: str, generation: int) -> bytes:
        buffer = bytearray()
        deadline = time.monotonic() + timeout_s
        while not reply_complete(bytes(buffer), command):
            if self._interrupts != generation:
                raise ExchangeInterrupted(f"VAL: waiting for the reply to {line!r} was "
                                          "interrupted (halt)")
            if time.monotonic() >= deadline:
                self.last_partial = bytes(buffer)
                raise DeviceTimeoutError(f"VAL: no complete reply to {line!r} within "
                                         f"{timeout_s:g} s (received {bytes(buffer)[-80:]!r})")
            if len(buffer) > _MAX_REPLY_BYTES:
                raise ProtocolError(f"VAL: reply to {line!r} exceeds {_MAX_REPLY_BYTES} bytes "
                                    "without a prompt")
            chunk = port.read(max(1, port.in_waiting))
            self.bytes_read += len(chunk)
            buffer += chunk
        return bytes(buffer)
