"""The arm the VAL emulator serves by default: the simulated cell's PUMA 260.

The cell's world frame is the robot's base frame and its tool centre point lies
``robot_model.TOOL_LENGTH_MM`` beyond the flange, so ``SIM_KINEMATICS`` gives the emulator the
same joint angles the simulated arm uses. The arm has no safety limits of its own: the VAL
driver talking to the emulator applies them, as on the real cell.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

from drivers.interfaces import Arm
from sim_backend.cell.robot_model import TOOL_LENGTH_MM
from sim_backend.emulators.val.kinematics import Puma260

SIM_KINEMATICS = Puma260(tool_length_mm=TOOL_LENGTH_MM)


@contextlib.contextmanager
def simulated_arm(scene_path: str | None = None, seed: int = 0) -> Iterator[Arm]:
    """A connected, active SimArm in a new SimCell (scene from the config file at
    ``scene_path``, else the default scene); closed on exit."""
    from sim_backend.cell.scene_config import load_cell
    from sim_backend.cell.sim_cell import SimCell
    from sim_backend.devices import SimArm

    scene, parts = load_cell(scene_path)
    with SimCell(scene, seed=seed, parts=parts) as cell, SimArm(cell, None) as arm:
        yield arm
