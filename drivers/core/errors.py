"""Typed errors raised by every device implementation (real drivers, simulator, fakes)."""


class FineposError(Exception):
    """Base of every error finepos raises on purpose."""


class ConfigError(FineposError, ValueError):
    """A configuration value is unknown, of the wrong type or out of range.

    The message starts with the full key path, e.g. ``scene.object.kind: ...``.
    """


class DeviceNotConnectedError(FineposError):
    """The device was used before ``connect()`` or after ``disconnect()``."""


class MotionRejectedError(FineposError):
    """A motion command was refused before anything moved.

    Attributes:
        reason: human-readable cause (safety limit, inactive lifecycle, unreachable pose, ...).
    """

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


class DeviceTimeoutError(FineposError):
    """A device did not answer within its timeout."""


class ProtocolError(FineposError):
    """A device sent bytes that do not follow its protocol."""


class DeviceFaultError(FineposError):
    """The device is in a fault state; it refuses motion until reset/reconnected.

    Attributes:
        message: the controller's own message where it sent one.
    """

    def __init__(self, message: str):
        super().__init__(message)
        self.message = message
