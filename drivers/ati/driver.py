"""ATI F/T controller driver: a WrenchSensor over the controller's ASCII serial protocol.

Start-up synchronises with the controller: drain stale bytes until the line is quiet, send a
bare ``\\r`` (which also ends a stream a previous client left running) and expect nothing but
the prompt back, up to three times; then send ``config.startup_commands`` (``CD A``,
``CD R``). ``read()`` sends ``QR`` and parses one record; ``bias()`` sends ``SB`` (the
controller keeps the bias); ``prepare_contact_guard`` sends ``SB``, the monitor condition and
the mean's lines from a thread of its own.

Every exchange waits at most ``config.timeout_s``. A timeout (DeviceTimeoutError), bytes off
protocol (ProtocolError), a lost link or a nonzero status word (AtiStatusError, a
DeviceFaultError) put the sensor into FAULT; it refuses readings until ``reset()`` reconnects.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import TypeVar

import serial

from drivers.ati.config import AtiConfig
from drivers.ati.protocol import (
    PROMPT,
    AtiStatusError,
    Record,
    check_silent_reply,
    parse_query_reply,
)
from drivers.core.errors import (
    DeviceFaultError,
    DeviceNotConnectedError,
    DeviceTimeoutError,
    FineposError,
    ProtocolError,
)
from drivers.interfaces import GuardSetup, MonitorCondition, Wrench, WrenchSensor

logger = logging.getLogger(__name__)

_SYNC_ATTEMPTS = 3
T = TypeVar("T")


class AtiWrenchSensor(WrenchSensor):
    """An ATI F/T controller on a serial line (device path, pty, ``socket://``, ``spy://``)."""

    def __init__(self, config: AtiConfig) -> None:
        super().__init__()
        self.config = config
        self._serial: serial.SerialBase | None = None

    # -- lifecycle ------------------------------------------------------------------------
    def _open(self) -> None:
        cfg = self.config
        try:
            self._serial = serial.serial_for_url(cfg.port, baudrate=cfg.baud,
                                                 timeout=cfg.timeout_s,
                                                 write_timeout=cfg.timeout_s)
        except (serial.SerialException, ValueError) as exc:
            raise DeviceNotConnectedError(f"ATI F/T: cannot open {cfg.port}: {exc}") from exc
        try:
            self._synchronise()
            for command in cfg.startup_commands:
                self._command(command)
        except FineposError:
            self._close()
            raise
        logger.info("ATI F/T controller ready on %s", cfg.port)

    def _synchronise(self) -> None:
        error: FineposError | None = None
        for _ in range(_SYNC_ATTEMPTS):
            self._drain()
            try:
                self._command("")
                return
            except (DeviceTimeoutError, ProtocolError) as exc:
                logger.debug("ATI F/T: resynchronising after %s", exc)
                error = exc
        assert error is not None
        raise error

    def _drain(self) -> None:
        """Discard input until none arrived for ``sync_quiet_s`` (at most ``timeout_s``)."""
        ser = self._serial
        assert ser is not None
        cfg = self.config
        ser.reset_input_buffer()
        deadline_s = time.monotonic() + cfg.timeout_s
        ser.timeout = cfg.sync_quiet_s
        try:
            while time.monotonic() < deadline_s and ser.read(cfg.max_reply_bytes):
                pass
        except (serial.SerialException, OSError) as exc:
            raise DeviceFaultError(f"ATI F/T: serial link lost: {exc}") from exc
        finally:
            ser.timeout = cfg.timeout_s

    def _close(self) -> None:
        if self._serial is None:
            return
        try:
            self._serial.close()
        except (serial.SerialException, OSError) as exc:
            logger.debug("ATI F/T: closing %s: %s", self.config.port, exc)
        self._serial = None

    # -- readings -------------------------------------------------------------------------
    def _read(self) -> Wrench:
        record = self._guarded(self._query)
        cfg = self.config
        c = record.counts
        return Wrench(c[0] / cfg.counts_per_force, c[1] / cfg.counts_per_force,
                      c[2] / cfg.counts_per_force, c[3] / cfg.counts_per_torque,
                      c[4] / cfg.counts_per_torque, c[5] / cfg.counts_per_torque)

    def _read_mean(self, samples: int) -> Wrench:
        """The controller's own moving average of the last ``samples`` samples: set it, one
        ``QR``, set back the start-up average."""
        cfg = self.config
        if samples == 1:
            return self._read()
        self._guarded(self._command, cfg.average_command.format(samples=samples))
        try:
            return self._read()
        finally:
            if self.is_connected:
                self._guarded(self._command, cfg.average_command.format(
                    samples=self._startup_average()))

    def _startup_average(self) -> int:
        for command in self.config.startup_commands:
            words = command.split()
            if len(words) == 2 and words[0].upper() == "SA" and words[1].isdigit():
                return int(words[1])
        return 0

    def _bias(self) -> None:
        self._guarded(self._command, "SB")

    def _prepare_contact_guard(self, condition: MonitorCondition,
                               samples: int | None) -> GuardSetup:
        """``SB``, the monitor condition and the mean (``SA n``, ``QR``, ``SA``) in a thread of
        their own: the sensor's serial line is its own, so they run while the caller sends the
        arm its lines. Each exchange keeps its ``timeout_s``."""
        return GuardSetup(lambda: self._contact_guard_steps(condition, samples),
                          background=True)

    def _set_monitor_condition(self, condition: MonitorCondition | None) -> None:
        """``monitor_command`` with the threshold in counts (``monitor_clear`` for None)."""
        cfg = self.config
        if condition is None:
            self._guarded(self._command, cfg.monitor_clear)
            return
        scale = cfg.counts_per_force if condition.axis.endswith("_n") else cfg.counts_per_torque
        line = cfg.monitor_command.format(axis=condition.axis.split("_")[0].upper(),
                                          op="GT" if condition.op == ">" else "LT",
                                          counts=round(condition.limit * scale),
                                          output=cfg.monitor_output)
        self._guarded(self._command, line)

    def _query(self) -> Record:
        record = parse_query_reply("QR", self._exchange("QR"))
        if record.status != 0:
            raise AtiStatusError(record.status)
        return record

    def _command(self, command: str) -> None:
        check_silent_reply(command, self._exchange(command))

    def _guarded(self, fn: Callable[..., T], *args: str) -> T:
        """Run one exchange; on any device error enter FAULT and re-raise it."""
        try:
            return fn(*args)
        except (DeviceTimeoutError, ProtocolError, DeviceFaultError) as exc:
            self.mark_fault(str(exc))
            raise

    def _exchange(self, command: str) -> bytes:
        """Send ``command\\r``; return the reply up to and including the prompt."""
        assert self._serial is not None
        limit = self.config.max_reply_bytes
        try:
            self._serial.write(command.encode("ascii") + b"\r")
            reply = self._serial.read_until(PROMPT, limit)
        except serial.SerialTimeoutException as exc:
            raise DeviceTimeoutError(f"ATI F/T: sending {command!r} timed out") from exc
        except (serial.SerialException, OSError) as exc:
            raise DeviceFaultError(f"ATI F/T: serial link lost during {command!r}: {exc}") \
                from exc
        if reply.endswith(PROMPT):
            return reply
        if len(reply) >= limit:
            raise ProtocolError(f"ATI F/T: no prompt in {limit} bytes after {command!r}: "
                                f"{reply[:80]!r}...")
        raise DeviceTimeoutError(f"ATI F/T: no prompt within {self.config.timeout_s} s after "
                                 f"{command!r} (got {reply!r})")
