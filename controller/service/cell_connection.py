"""The service's devices: opened once, brought back after a fault, probed before a reset.

``open()`` enters ``controller.devices.open_devices`` (or an injected opener with the same
contract: a context manager yielding connected, active ``CellDevices``). ``recover()`` opens
them if that has not succeeded yet, and otherwise reconnects (``Device.reset``) and reactivates
each device that is not active. ``probe()`` asks each device for one reading, which is how a
cause that leaves no FAULT behind (a camera that stopped delivering) is found to be gone.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable

from controller.devices import CellDevices, open_devices
from controller.service.job_arm import PreemptibleArm
from drivers.core.errors import DeviceNotConnectedError
from drivers.interfaces import Device, Lifecycle

DeviceOpener = Callable[..., contextlib.AbstractContextManager[CellDevices]]


class CellConnection:
    """Owns the opened devices; ``arm`` is the preemptible wrapper the jobs use."""

    def __init__(self, config, opener: DeviceOpener = open_devices) -> None:
        self.config = config
        self._opener = opener
        self._stack: contextlib.ExitStack | None = None
        self._devices: CellDevices | None = None
        self.arm: PreemptibleArm | None = None

    @property
    def is_open(self) -> bool:
        """Whether the devices are open (``open`` succeeded, ``close`` not called since)."""
        return self._devices is not None

    def open(self) -> None:
        """Open and activate every configured device (raises what the opener raises)."""
        with contextlib.ExitStack() as stack:
            devices = stack.enter_context(self._opener(self.config))
            self._stack = stack.pop_all()
        self._devices = devices
        self.arm = PreemptibleArm(devices.arm)

    def close(self) -> None:
        """Disconnect everything (reverse order); safe to call twice."""
        stack, self._stack, self._devices = self._stack, None, None
        if stack is not None:
            stack.close()

    def job_devices(self) -> CellDevices:
        """The devices as FinePositioner gets them: the arm wrapped, the rest as opened."""
        devices = self._require()
        assert self.arm is not None
        return CellDevices(self.arm, devices.camera, devices.wrench, devices.cell)

    @property
    def cell(self):
        """The simulated cell, or None on real hardware (and before the devices are open)."""
        return self._devices.cell if self._devices is not None else None

    def named(self) -> list[tuple[str, Device]]:
        """The arm (unwrapped), camera and wrench sensor with their names.

        Raises:
            DeviceNotConnectedError: the devices are not open.
        """
        devices = self._require()
        return [("arm", devices.arm), ("camera", devices.camera), ("wrench", devices.wrench)]

    def not_active(self) -> dict[str, str]:
        """Devices that are not active, with why (their fault reason, else their state)."""
        if self._devices is None:
            return {"devices": "not open"}
        return {name: device.fault_reason or device.state.value
                for name, device in self.named() if device.state is not Lifecycle.ACTIVE}

    def recover(self) -> None:
        """Open the devices, or reconnect and reactivate those not active (raises on failure)."""
        if self._devices is None:
            self.open()
            return
        for _, device in self.named():
            if device.state is Lifecycle.FAULT:
                device.reset()
            elif device.state is Lifecycle.DISCONNECTED:
                device.connect()
            if device.state is Lifecycle.INACTIVE:
                device.activate()

    def probe(self) -> None:
        """One reading from each device (raises the first device error)."""
        devices = self._require()
        assert self.arm is not None
        self.arm.pose()
        devices.camera.grab()
        devices.wrench.read()

    def _require(self) -> CellDevices:
        if self._devices is None:
            raise DeviceNotConnectedError("the devices are not open")
        return self._devices
