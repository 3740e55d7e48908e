"""The command interpreter of the emulated ATI F/T controller (no I/O: lines in, bytes out).

Backed by any ``drivers.interfaces.WrenchSensor``: a record reports the sensor's reading as
counts (N * counts_per_force, N*m * counts_per_torque, rounded) minus the controller's own bias.
The backing sensor's bias is never touched.

Commands (case-insensitive, one per ``\\r``-ended line; each answered by the echo, its output
and the prompt ``>``):

- ``CD A`` / ``CD B``: ASCII / binary records; ``CD R`` resolved forces, ``CD D`` / ``CD H``
  raw gauges in decimal / hex.
- ``QR``: one record. ``QS``: a stream of records until the client sends ``\\r``.
- ``SB`` bias (pushes the current load; at most 3 kept), ``SU`` drops the last bias, ``SZ``
  clears all.
- ``SA n``: each record is the moving average of the last n samples (0 or 1: no averaging):
  the backing sensor's ``read_mean(n)`` (the simulated one waits only for the samples not yet
  taken since the arm came to rest).
- ``CL 0|1``: lines end ``\\r`` / ``\\r\\n``. ``CV h``: hex mask of the components sent.

Where the wire format is not confirmed by the hardware notes this emulator chooses one and says
so: ``CV`` bit i selects component i of (Fx, Fy, Fz, Tx, Ty, Tz); gauges are the unbiased counts
(an identity calibration matrix) and ``CD H`` prints each as 4 hex digits (16-bit two's
complement); a binary record is the status word and the selected values as big-endian 16-bit
integers; an unknown command, a bad argument or a failing backing sensor is answered by one
line ``Error: ...``.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drivers.core.errors import FineposError
from drivers.interfaces import WrenchSensor

PROMPT = b">"
ALL_AXES_MASK = 0x3F
BIAS_LEVELS = 3


@dataclass
class OutputMode:
    """What ``CD``, ``CL`` and ``CV`` have set."""

    ascii: bool = True
    data: str = "resolved"  # "resolved" | "gauge_dec" | "gauge_hex"
    linefeed: bool = True
    mask: int = ALL_AXES_MASK


class AtiController:
    """State and replies of one ATI F/T controller; ``status_word()`` gives each record's."""

    def __init__(self, sensor: WrenchSensor, counts_per_force: float = 20.0,
                 counts_per_torque: float = 333.33, echo: bool = True,
                 status_word: Callable[[], int] = lambda: 0) -> None:
        self.sensor = sensor
        self.scale = np.array([counts_per_force] * 3 + [counts_per_torque] * 3)
        self.echo = echo
        self.status_word = status_word
        self.mode = OutputMode()
        self.average_n = 0
        self.biases: list[np.ndarray] = []
        self.streaming = False
        self.conditions: dict[int, tuple[int, str, int]] = {}  # output -> (axis, op, counts)

    @property
    def eol(self) -> bytes:
        return b"\r\n" if self.mode.linefeed else b"\r"

    # -- commands -------------------------------------------------------------------------
    def execute(self, line: str) -> bytes:
        """Reply to one command line (without its ``\\r``): echo, output, prompt.

        ``QS`` answers with the echo only and sets ``streaming``; the caller then sends
        ``record()`` until the client sends ``\\r`` and ends with ``stop_stream()``.
        """
        out = (line.encode("ascii", "replace") + self.eol) if self.echo else b""
        words = line.strip().upper().split()
        if not words:
            return out + PROMPT
        try:
            body = self._dispatch(words[0], words[1:])
        except (ValueError, FineposError) as exc:
            self.streaming = False
            body = f"Error: {exc}".encode("ascii", "replace") + self.eol
        if self.streaming:
            return out + body
        return out + body + PROMPT

    def stop_stream(self) -> bytes:
        self.streaming = False
        return self.eol + PROMPT

    def _dispatch(self, name: str, args: list[str]) -> bytes:
        if name == "QR":
            return self.record()
        if name == "QS":
            self.streaming = True
            return b""
        if name == "CD":
            self._set_data_mode(args)
        elif name == "CL":
            self.mode.linefeed = _flag(args)
        elif name == "CV":
            self.mode.mask = _one_int(args, base=16) & ALL_AXES_MASK
        elif name == "SA":
            self.average_n = _one_int(args, base=10)
        elif name == "SB":
            self.biases = (self.biases + [self._resolved_counts()])[-BIAS_LEVELS:]
        elif name == "SU":
            self.biases = self.biases[:-1]
        elif name == "SZ":
            self.biases = []
        elif name == "MC":
            self._set_condition(args)
        else:
            raise ValueError(f"unknown command {name}")
        return b""

    def _set_condition(self, args: list[str]) -> None:
        if not args:
            self.conditions = {}
            return
        axes = ("FX", "FY", "FZ", "TX", "TY", "TZ")
        if len(args) != 4 or args[0] not in axes or args[1] not in ("LT", "GT"):
            raise ValueError("MC needs axis (FX..TZ), LT or GT, counts, output")
        try:
            counts, output = int(args[2]), int(args[3])
        except ValueError:
            raise ValueError(f"bad number in {' '.join(args)}") from None
        if not 1 <= output <= 4:
            raise ValueError(f"no output {output}")
        self.conditions[output] = (axes.index(args[0]), args[1], counts)

    def output_high(self, output: int) -> bool:
        """Whether discrete ``output`` is high: its monitor condition holds on a fresh biased
        reading (no condition: low). A failing sensor leaves it low."""
        condition = self.conditions.get(output)
        if condition is None:
            return False
        axis, op, counts = condition
        try:
            raw = self._resolved_counts(1)
        except FineposError:
            return False
        if self.biases:
            raw = raw - self.biases[-1]
        value = int(raw[axis])
        return value < counts if op == "LT" else value > counts

    def _set_data_mode(self, args: list[str]) -> None:
        if len(args) != 1 or args[0] not in ("A", "B", "R", "D", "H"):
            raise ValueError("CD needs one of A, B, R, D, H")
        if args[0] in ("A", "B"):
            self.mode.ascii = args[0] == "A"
        else:
            self.mode.data = {"R": "resolved", "D": "gauge_dec", "H": "gauge_hex"}[args[0]]

    # -- records --------------------------------------------------------------------------
    def record(self) -> bytes:
        """One record in the current output mode (ASCII records end with the line ending)."""
        raw = self._resolved_counts()
        if self.mode.data == "resolved" and self.biases:
            raw = raw - self.biases[-1]
        values = [int(v) for i, v in enumerate(raw) if self.mode.mask >> i & 1]
        status = self.status_word()
        if not self.mode.ascii:
            clipped = [max(-32768, min(32767, v)) for v in values]
            return struct.pack(f">H{len(clipped)}h", status & 0xFFFF, *clipped)
        if self.mode.data == "gauge_hex":
            fields = [f"{v & 0xFFFF:04X}" for v in values]
        else:
            fields = [f"{v:6d}" for v in values]
        return (",".join([f"{status}"] + fields)).encode("ascii") + self.eol

    def _resolved_counts(self, samples: int | None = None) -> np.ndarray:
        """Current load in counts (the mean of ``samples`` readings, by default
        ``average_n``), unbiased."""
        n = max(1, self.average_n if samples is None else samples)
        if n == 1:
            mean = list(self.sensor.read().as_dict().values())
        else:  # the moving average of the samples the controller has been taking
            mean = list(self.sensor.read_mean(n).as_dict().values())
        return np.rint(np.array(mean) * self.scale).astype(np.int64)


def _one_int(args: list[str], base: int) -> int:
    if len(args) != 1:
        raise ValueError("expected one argument")
    try:
        value = int(args[0], base)
    except ValueError:
        raise ValueError(f"bad number {args[0]}") from None
    if value < 0:
        raise ValueError(f"negative number {args[0]}")
    return value


def _flag(args: list[str]) -> bool:
    value = _one_int(args, base=10)
    if value not in (0, 1):
        raise ValueError("expected 0 or 1")
    return bool(value)
