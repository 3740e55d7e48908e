"""Hardware in the loop on one machine: the real drivers against emulators of one simulated cell.

``open_hil_devices(config, seed)`` is ``controller.devices.open_devices`` with the wire in
between: it builds the SimCell that ``open_devices`` would build (same scene, simulated-arm
options and seed), serves it in this process (``sim_backend.emulators.cell.CellEmulators``:
the VAL II monitor on a pty, the ATI F/T controller on a second pty, the hand camera as an MJPEG
stream on 127.0.0.1, each from its own thread), and opens the real drivers on them: ``ValArm``
(``drivers.val``), ``AtiWrenchSensor`` (``drivers.ati``) and ``OpenCvCamera`` (``drivers.camera``,
through OpenCV's FFmpeg HTTP reader). Every arm, camera and wrench exchange of the controller
goes over those links. Only what a real cell does not offer is taken from the cell directly:
placing the part and the ground truth (``CellDevices.cell``, serialised with the emulators'
threads), which is what ``finepos evaluate --hil`` needs.

The driver options not given by the emulators (timeouts, command templates, calibration) come
from ``config`` when it already names that backend, else they are the drivers' defaults. VAL
reports no finger width, so the VAL driver's nominal closed width is set to the simulated part's
(the grasp's grip check then passes when the jaws close; the evaluation counts a grasp only when
the cell really holds the part).
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Iterator

from controller.devices import CellDevices, open_devices, with_device
from sim_backend.cell.scene_config import SimArmConfig
from sim_backend.emulators.cell import DEFAULT_FPS, CellEmulators


@contextlib.contextmanager
def open_hil_devices(config, seed: int = 0, activate: bool = True,
                     fps: float = DEFAULT_FPS) -> Iterator[CellDevices]:
    """Serve a new simulated cell over its emulators and open the real drivers on them.

    Yields CellDevices whose arm, camera and wrench are the real drivers and whose ``cell`` is
    the served cell (serialised). With ``scene.timing: realistic`` the emulators take the
    ``timing`` section's durations for real (paced lines, moves that last), and the devices'
    clock is wall time. Everything is closed on exit: drivers, emulators, cell.
    """
    from sim_backend.cell.sim_cell import SimCell  # PyBullet only when a cell is built

    arm_options = config.arm.options if config.arm.type == "sim" else SimArmConfig()
    with contextlib.ExitStack() as stack:
        cell = stack.enter_context(SimCell(config.scene, arm_options, seed=seed,
                                                   parts=config.parts))
        emulators = stack.enter_context(
            CellEmulators(cell, ati=True, mjpeg_port=0, fps=fps,
                          timing=config.timing if config.scene.timing == "realistic" else None))
        hil_config = hil_device_config(config, emulators)
        devices = stack.enter_context(open_devices(hil_config, seed=seed, activate=activate))
        yield dataclasses.replace(devices, cell=emulators.cell)


def hil_device_config(config, emulators: CellEmulators):
    """``config`` with the arm, wrench and camera pointed at ``emulators``."""
    for kind, section in emulators.device_sections().items():
        options = dict(section)
        config = with_device(config, kind, options.pop("type"), **options)
    return config
