"""Configuration of the ATI F/T controller driver (config section ``wrench: {type: ati, ...}``)."""

from __future__ import annotations

from dataclasses import dataclass, field

_POSITIVE = {"min": 0.0, "exclusive_min": True}


@dataclass(frozen=True)
class AtiConfig:
    """How to reach and scale an ATI F/T controller on a serial line.

    port: anything ``serial.serial_for_url`` opens (``/dev/ttyS0``, ``/dev/pts/3``,
    ``socket://host:port``, ``spy:///dev/ttyS0``); baud: line speed (9600 on older boxes);
    counts_per_force: counts per newton and counts_per_torque: counts per N*m (from the sensor's
    calibration sheet); timeout_s: longest wait for one reply (prompt included);
sync_quiet_s: at start-up, stale bytes are drained until the line is quiet this long;
    startup_commands: sent in order after the prompt was found, each answered by the prompt
    (``CD A`` ASCII output, ``CD R`` resolved forces; add e.g. ``SA 4`` for averaging);
    max_reply_bytes: a reply longer than this without a prompt is a protocol error;
    average_command: sets the controller's moving average over the last ``samples`` samples
    (``SA n``, confirmed); ``read_mean`` sends it, one ``QR``, and sets back the average of
    the start-up commands (an ``SA n`` among them, else none);
    monitor_output: the discrete output the monitor condition switches (wired to the VAL
    input ``arm.program_input``); monitor_command: sets the condition (fields ``axis``
    ``FX``..``TZ``, ``op`` ``LT``/``GT`` (``>`` is the prompt), ``counts`` the threshold in
    counts, ``output``);
    monitor_clear: clears it. The controller evaluates monitor conditions itself (ATI manual
    9620-05-CTL); their serial syntax has no public source: these defaults are the emulator's.
    """

    port: str
    baud: int = field(default=9600, metadata=_POSITIVE)
    counts_per_force: float = field(default=20.0, metadata=_POSITIVE)
    counts_per_torque: float = field(default=333.33, metadata=_POSITIVE)
    timeout_s: float = field(default=0.5, metadata=_POSITIVE)
    sync_quiet_s: float = field(default=0.05, metadata=_POSITIVE)
    startup_commands: tuple[str, ...] = ("CD A", "CD R")
    max_reply_bytes: int = field(default=512, metadata={"min": 64})
    average_command: str = "SA {samples}"
    monitor_output: int = field(default=1, metadata={"min": 1, "max": 16})
    monitor_command: str = "MC {axis} {op} {counts} {output}"
    monitor_clear: str = "MC"

    def __post_init__(self) -> None:
        for i, command in enumerate(self.startup_commands):
            if not (command.isascii() and command.isprintable()):
                raise ValueError(f"startup_commands[{i}]: must be printable ASCII without line "
                                 f"breaks, got {command!r}")
