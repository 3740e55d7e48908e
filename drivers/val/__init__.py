"""PUMA 260 with a VAL II controller over RS-232: config, reply and ``where`` parsers, arm driver.

Modules: ``config`` (ValConfig, ValCommands), ``replies`` (reply classification), ``where``
(pose table parser), ``link`` (serial exchanges with timeouts), ``arm`` (ValArm).
"""

from drivers.val.arm import ValArm
from drivers.val.config import ValCommands, ValConfig
from drivers.val.where import WhereReading

__all__ = ["ValArm", "ValCommands", "ValConfig", "WhereReading"]
