"""ATI F/T controller (wrist force-torque sensor) over its ASCII serial protocol."""

from drivers.ati.config import AtiConfig
from drivers.ati.driver import AtiWrenchSensor
from drivers.ati.protocol import AtiStatusError

__all__ = ["AtiConfig", "AtiStatusError", "AtiWrenchSensor"]
