"""One simulated cell behind the real devices' wire protocols: VAL arm, ATI sensor, MJPEG camera.

For hardware-in-the-loop runs on one machine: ``CellEmulators(cell, ...)`` serves the cell's
arm as the VAL II monitor (a pty, or TCP on 127.0.0.1), optionally its wrist sensor as an ATI
F/T controller (a second pty, or TCP) and its hand camera as an MJPEG stream over HTTP on
127.0.0.1. The real drivers (``drivers.val``, ``drivers.ati``, ``drivers.camera``) connect to
``val_url``, ``ati_url`` and ``stream_url``; whatever moves through the VAL monitor is what the
sensor feels and the camera sees.

The emulators serve from their own threads and PyBullet is not thread-safe, so the cell they
share is wrapped in a ``SerialisedCell``: every call into it holds one lock. A caller that uses
the cell directly (placing the part, reading the ground truth) must go through ``cell`` (the
wrapped one) too. The simulated arm behind the monitor has no safety limits: the VAL driver
applies them, as on the real cell.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import threading
from typing import Any, Self

from drivers.camera.mjpeg_server import MjpegServer
from drivers.core.lifecycle import Lifecycle
from drivers.core.timing import TimingConfig
from sim_backend.cell.sim_cell import SimCell
from sim_backend.cell.timing import CellTiming, cell_timing
from sim_backend.devices import SimArm, SimCamera, SimWrenchSensor
from sim_backend.emulators.ati.emulator import AtiEmulator
from sim_backend.emulators.val.server import ValEmulator, ValFaults
from sim_backend.emulators.val.sim_arm import SIM_KINEMATICS

logger = logging.getLogger(__name__)

DEFAULT_FPS = 30.0
# What the camera driver waits past a frame's request, beyond the stream's own frame period,
# exposure and latency: the emulator renders, encodes and the driver decodes on the same
# machine as the loop. With the driver's default 0.05 s on a loaded two-core machine, a look
# right after a 14 mm move read the frame from before it (the loop stepped twice as far and
# the grasp met the part 3 mm off its centre).
STREAM_MARGIN_S = 0.15
# The wire from the ATI controller's discrete output to the VAL controller's input line, as
# the drivers' defaults name them (arm.program_input, wrench.monitor_output).
VAL_INPUT_SIGNAL = 1001
ATI_OUTPUT = 1


class SerialisedCell:
    """A SimCell shared by several threads: every attribute read and method call on it holds
    ``lock``, so an arm move, a render and a wrench reading never interleave."""

    def __init__(self, cell: SimCell) -> None:
        self._cell = cell
        self.lock = threading.RLock()

    def __getattr__(self, name: str) -> Any:
        with self.lock:
            value = getattr(self._cell, name)
        if not callable(value):
            return value

        @functools.wraps(value)
        def locked(*args, **kwargs):
            with self.lock:
                return value(*args, **kwargs)

        return locked


class CellEmulators(Lifecycle):
    """Serves ``cell`` over the VAL emulator and, when asked, the ATI emulator and an MJPEG
    stream. Use as a context manager; the caller owns ``cell`` (close it after this).

    Args:
        cell: the simulated cell to serve.
        val_tcp_port: serve VAL on 127.0.0.1:PORT (0: any free) instead of a pty.
        ati: also serve the wrist sensor as an ATI F/T controller.
        ati_tcp_port: serve it on 127.0.0.1:PORT (0: any free) instead of a pty.
        mjpeg_port: also serve the hand camera on http://127.0.0.1:PORT (0: any free port).
        fps: frame rate of the stream.
        boot_questions / faults: the VAL emulator's start-up questions and fault knobs.
        counts_per_force / counts_per_torque: the emulated ATI controller's calibration (the
            driver's config must use the same).
        timing: realistic timing (``--timing realistic``): the VAL and ATI lines are paced at
            ``val_baud`` / ``ati_baud``, a move really takes its motion time (``do move``
            answers after it), the hand its hand time, the camera streams at
            ``camera.frame_rate_hz`` with exposure, latency and motion blur (fps is then
            ignored). None: ideal, everything as fast as it goes.
    """

    def __init__(self, cell: SimCell, *, val_tcp_port: int | None = None, ati: bool = False,
                 ati_tcp_port: int | None = None, mjpeg_port: int | None = None,
                 fps: float = DEFAULT_FPS, boot_questions: bool = False,
                 faults: ValFaults | None = None, counts_per_force: float = 20.0,
                 counts_per_torque: float = 333.33, timing: TimingConfig | None = None) -> None:
        self.cell = SerialisedCell(cell)
        self.timing_config = timing
        self.timing: CellTiming | None = (None if timing is None
                                          else cell_timing("realistic", timing, wall=True))
        if timing is not None:
            fps = timing.camera.frame_rate_hz
        self._val_tcp_port = val_tcp_port
        self._ati = ati or ati_tcp_port is not None
        self._ati_tcp_port = ati_tcp_port
        self._mjpeg_port = mjpeg_port
        self._fps = fps
        self._boot_questions = boot_questions
        self._faults = faults
        self._counts = (counts_per_force, counts_per_torque)
        self._stack = contextlib.ExitStack()
        self.val: ValEmulator | None = None
        self.ati: AtiEmulator | None = None
        self.mjpeg: MjpegServer | None = None

    @property
    def val_url(self) -> str:
        """The VAL driver's ``port`` (``/dev/pts/N`` or ``socket://127.0.0.1:N``)."""
        if self.val is None:
            raise RuntimeError("CellEmulators is not started")
        return self.val.url

    @property
    def ati_url(self) -> str | None:
        """The ATI driver's ``port``, or None when the sensor is not served."""
        return self.ati.url if self.ati is not None else None

    @property
    def stream_url(self) -> str | None:
        """The camera driver's ``source`` (``http://127.0.0.1:N/stream.mjpg``), or None."""
        return self.mjpeg.stream_url if self.mjpeg is not None else None

    def device_sections(self) -> dict[str, dict]:
        """Config sections (``arm``, and ``wrench`` and ``camera`` where served) that point the
        real drivers at these emulators.

        The VAL driver keeps its own gripper defaults, as on a real controller (VAL reports no
        finger width): the grasp's check must rest on the wrist sensor, as on the real cell.
        """
        sections: dict[str, dict] = {"arm": {"type": "val", "port": self.val_url}}
        if self.ati_url is not None:
            sections["wrench"] = {"type": "ati", "port": self.ati_url}
        if self.stream_url is not None:
            sections["camera"] = {"type": "opencv", "source": self.stream_url,
                                  "settle_s": round(self.stream_settle_s(), 3)}
        return sections

    def stream_settle_s(self) -> float:
        """The camera driver's ``settle_s`` for this stream: after a move, the frame being
        rendered may have started before it ended (one frame period), and a frame is exposed
        and delivered ``latency_frames`` periods later (realistic timing), plus
        STREAM_MARGIN_S for rendering, encoding and decoding on this machine."""
        settle_s = 1.0 / self._fps + STREAM_MARGIN_S
        if self.timing_config is not None:
            settle_s += self.timing_config.camera.delivery_s
        return settle_s

    def start(self) -> Self:
        """Connect the simulated devices and start every emulator asked for."""
        stack = self._stack
        try:
            timing, config = self.timing, self.timing_config
            if timing is not None:
                stack.callback(timing.clock.interrupt)  # first out: no sleep holds a close
            arm = stack.enter_context(SimArm(self.cell, None, timing))
            self.val = stack.enter_context(ValEmulator(
                arm, tcp_port=self._val_tcp_port, boot_questions=self._boot_questions,
                kinematics=SIM_KINEMATICS, faults=self._faults,
                baud=config.val_baud if config else None,
                on_line=timing.begin_command if timing else None))
            if self._ati:
                sensor = stack.enter_context(SimWrenchSensor(self.cell, timing))
                self.ati = stack.enter_context(AtiEmulator(
                    sensor, *self._counts, tcp_port=self._ati_tcp_port,
                    baud=config.ati_baud if config else None))
                controller = self.ati.controller
                self.val.monitor.set_input(VAL_INPUT_SIGNAL,
                                           lambda: controller.output_high(ATI_OUTPUT))
            if self._mjpeg_port is not None:
                camera = stack.enter_context(SimCamera(self.cell, timing))
                self.mjpeg = stack.enter_context(MjpegServer(camera, port=self._mjpeg_port,
                                                             fps=self._fps))
        except BaseException:
            self.close()
            raise
        logger.info("cell emulators: VAL %s, ATI %s, camera %s", self.val_url, self.ati_url,
                    self.stream_url)
        return self

    def close(self) -> None:
        """Stop every emulator, in reverse order of starting (idempotent)."""
        self._stack.close()
        self.val = self.ati = self.mjpeg = None
