"""Device backends by configuration: one explicit registry per device kind.

``arm: {type: sim}`` or ``arm: {type: val, port: /dev/ttyS0, ...}``: ``type`` picks the
backend, the other keys are that backend's options, checked strictly at load. ``open_devices``
builds the configured arm, camera and wrench sensor (sharing one simulated cell where any of
them is simulated) and closes everything it opened, in reverse order. The ``sim`` backends and
the simulated cell come through ``controller.simulated``, which loads the simulator only when a
config names one.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from controller import simulated
from drivers.ati.config import AtiConfig
from drivers.camera.config import OpenCvCameraConfig
from drivers.core.errors import ConfigError
from drivers.core.typed_config import from_mapping, to_mapping
from drivers.interfaces import Arm, Camera, WrenchSensor
from drivers.val.config import ValConfig


@dataclass(frozen=True)
class DeviceSection:
    """A device backend chosen by ``type`` with that backend's typed options."""

    type: str
    options: Any


@dataclass(frozen=True)
class NoOptions:
    """A backend without options of its own."""


@dataclass(frozen=True)
class Backend:
    """One backend of a device kind: its options' type and how to build the device.

    options: the options' dataclass, or a function returning it (the simulated arm's, so the
    simulator's types load only when a config names that backend; see ``options_type``).
    """

    options: type | Callable[[], type]
    build: Callable[[Any, Any], Any]  # (options, DeviceContext) -> device

    @property
    def options_type(self) -> type:
        """The options' dataclass."""
        return self.options if isinstance(self.options, type) else self.options()


class DeviceContext:
    """What builders share: the root config, and the simulated cell once one is needed."""

    def __init__(self, config, seed: int = 0) -> None:
        self.config = config
        self.seed = seed
        self._cell = None
        self._timing = None
        self._stack = contextlib.ExitStack()

    @property
    def cell(self):
        """The simulated work cell (created on first use)."""
        if self._cell is None:
            self._cell = self._stack.enter_context(simulated.build_cell(self.config, self.seed))
        return self._cell

    @property
    def timing(self):
        """The simulated cell's timing (``sim_backend.cell.timing.CellTiming``: a virtual clock
        when ``scene.timing`` is realistic), or None when ideal. Shared by the simulated
        devices."""
        if self._timing is None:
            self._timing = simulated.cell_timing(self.config)
        return self._timing

    def clock(self) -> float:
        """Cell seconds: the virtual cell clock when the cell is simulated with realistic
        timing, else wall time (``time.monotonic``)."""
        timing = self._timing
        return timing.clock.now() if timing is not None else time.monotonic()

    @property
    def has_cell(self) -> bool:
        """Whether a simulated cell was built."""
        return self._cell is not None

    def close(self) -> None:
        """Close the simulated cell, if one was built."""
        self._stack.close()


def _val_arm(options, ctx: DeviceContext) -> Arm:
    from drivers.val import ValArm

    return ValArm(options, ctx.config.safety)


def _opencv_camera(options, ctx: DeviceContext) -> Camera:
    from drivers.camera import OpenCvCamera

    return OpenCvCamera(options)


def _ati_wrench(options, ctx: DeviceContext) -> WrenchSensor:
    from drivers.ati import AtiWrenchSensor

    return AtiWrenchSensor(options)


ARM_BACKENDS: dict[str, Backend] = {
    "sim": Backend(simulated.arm_options, simulated.build_arm),
    "val": Backend(ValConfig, _val_arm),
}
CAMERA_BACKENDS: dict[str, Backend] = {
    "sim": Backend(NoOptions, simulated.build_camera),
    "opencv": Backend(OpenCvCameraConfig, _opencv_camera),
}
WRENCH_BACKENDS: dict[str, Backend] = {
    "sim": Backend(NoOptions, simulated.build_wrench),
    "ati": Backend(AtiConfig, _ati_wrench),
}
REGISTRIES = {"arm": ARM_BACKENDS, "camera": CAMERA_BACKENDS, "wrench": WRENCH_BACKENDS}


def parse_device_section(kind: str, data: Any):
    """Validate ``{type: ..., <options>}`` for device ``kind`` (default: ``type: sim``).

    Raises:
        ConfigError: an unknown ``type``, or options that backend does not take (naming the
            key).
    """
    registry = REGISTRIES[kind]
    data = {"type": "sim"} if data is None else data
    if not isinstance(data, dict):
        raise ConfigError(f"{kind}: expected a mapping with a 'type' key, got {data!r}")
    options = dict(data)
    backend_type = options.pop("type", "sim")
    if backend_type not in registry:
        raise ConfigError(f"{kind}.type: must be one of {' | '.join(registry)}, "
                          f"got {backend_type!r}")
    backend = registry[backend_type]
    return DeviceSection(backend_type, from_mapping(backend.options_type, options, kind))


def with_device(config, kind: str, backend_type: str, **options):
    """``config`` with device ``kind`` (arm, camera, wrench) on ``backend_type``.

    ``options`` override that backend's options; the options already configured are kept when
    the backend stays the same. The result is validated as strictly as a config file
    (ConfigError naming the key); a simulated device has the ``scene`` section read.
    """
    section = getattr(config, kind)
    data = to_mapping(section.options) if section.type == backend_type else {}
    data.update(options)
    replaced = parse_device_section(kind, {"type": backend_type, **data})
    config = dataclasses.replace(config, **{kind: replaced})
    return simulated.with_scene_read(config) if backend_type == "sim" else config


@dataclass
class CellDevices:
    """The opened devices, and the simulated cell when the config uses one (else None).

    clock: cell seconds now (the simulated cell's virtual clock when its timing is realistic,
    else wall time); timing: the simulated cell's ``CellTiming`` (None: ideal or no cell).
    """

    arm: Arm
    camera: Camera
    wrench: WrenchSensor
    cell: Any
    clock: Callable[[], float] = time.monotonic
    timing: Any = None

    def ground_truth(self):
        """The gripper's error against the part's grasp pose, where the backend knows it."""
        return self.cell.ground_truth_error() if self.cell is not None else None


@contextlib.contextmanager
def open_devices(config, seed: int = 0, activate: bool = True):
    """Build, connect (and activate) the configured devices; close them all on exit."""
    ctx = DeviceContext(config, seed)
    with contextlib.ExitStack() as stack:
        stack.callback(ctx.close)
        built = []
        for kind in ("arm", "camera", "wrench"):
            section = getattr(config, kind)
            device = REGISTRIES[kind][section.type].build(section.options, ctx)
            stack.callback(device.disconnect)
            device.connect()
            if activate:
                device.activate()
            built.append(device)
        yield CellDevices(*built, cell=ctx._cell, clock=ctx.clock, timing=ctx._timing)
