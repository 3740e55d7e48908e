"""The product's one door into the simulator, opened only when the config names a simulated device.

Here the root config's ``scene`` section is read into ``sim_backend.cell.scene_config.SceneConfig``
and the simulated arm's options (``arm: {type: sim, ...}``) are typed; here the simulated cell, its
clock and the simulated devices are built (``controller.devices`` registers them as the ``sim``
backends). Every import of ``sim_backend`` sits inside a function, and those functions run only for
a simulated device, so a real cell loads no simulator code. ``tests/test_layout.py`` follows only
this module's module-level imports; ``tests/test_product_path.py`` checks a real cell's run.

On a config without a simulated device the ``scene`` section stays as the file wrote it
(``UnreadScene``): the emulators of ``finepos sim ...`` read it from the file themselves.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class UnreadScene:
    """The ``scene`` section as the file wrote it (None: absent), on a config whose devices are
    all real; ``read_scene`` reads it once a simulated device is configured."""

    data: Any = None


def read_scene(data: Any):
    """The ``scene`` section ``data`` read into a ``SceneConfig``.

    Raises:
        ConfigError: naming the key's full path (``scene.lighting.preset: ...``).
    """
    from drivers.core.typed_config import from_mapping
    from sim_backend.cell.scene_config import SceneConfig

    return from_mapping(SceneConfig, data, "scene")


def scene_section(data: Any, simulated: bool):
    """The root config's ``scene``: read (``SceneConfig``) when a device is ``simulated``, else
    kept unread (``UnreadScene``)."""
    return read_scene(data) if simulated else UnreadScene(data)


def with_scene_read(config):
    """``config`` with its ``scene`` read, when it is still unread (a device just became
    simulated)."""
    if isinstance(config.scene, UnreadScene):
        return dataclasses.replace(config, scene=read_scene(config.scene.data))
    return config


def arm_options() -> type:
    """The simulated arm's options (``SimArmConfig``)."""
    from sim_backend.cell.scene_config import SimArmConfig

    return SimArmConfig


def build_cell(config, seed: int):
    """The simulated work cell of ``config`` (a context manager): its scene, and the simulated
    arm's options (the defaults when the arm is real)."""
    from sim_backend.cell.scene_config import SimArmConfig
    from sim_backend.cell.sim_cell import SimCell

    arm_opts = config.arm.options if config.arm.type == "sim" else SimArmConfig()
    return SimCell(config.scene, arm_opts, seed=seed, parts=config.parts)


def cell_timing(config):
    """The simulated cell's timing (``sim_backend.cell.timing.CellTiming``, a virtual clock),
    or None when ``scene.timing`` is ideal."""
    if config.scene.timing == "ideal":
        return None
    from sim_backend.cell.timing import cell_timing as timing

    return timing(config.scene.timing, config.timing)


def build_arm(options, ctx):
    """The simulated arm on ``ctx``'s cell (``controller.devices.DeviceContext``)."""
    from sim_backend.devices import SimArm

    return SimArm(ctx.cell, ctx.config.safety, ctx.timing)


def build_camera(options, ctx):
    """The simulated hand camera on ``ctx``'s cell."""
    from sim_backend.devices import SimCamera

    return SimCamera(ctx.cell, ctx.timing)


def build_wrench(options, ctx):
    """The simulated wrist force-torque sensor on ``ctx``'s cell."""
    from sim_backend.devices import SimWrenchSensor

    return SimWrenchSensor(ctx.cell, ctx.timing)
