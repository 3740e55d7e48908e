"""spacenavd's client protocol v0: one event is 8 native-order int32 (pure decoding).

Word 0 is the type: 0 motion (then x, y, z, rx, ry, rz, period in ms), 1 button press,
2 button release (then the button number). A client that never sends anything gets v0 events.
The daemon sends a motion event only when the device's values change; its ``period_ms`` is the
time since the previous motion event, i.e. how long the previous deflection was held.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from drivers.core.errors import ProtocolError

EVENT = struct.Struct("=8i")
EVENT_BYTES = EVENT.size  # 32
_MOTION, _PRESS, _RELEASE = 0, 1, 2


@dataclass(frozen=True)
class MotionEvent:
    """Deflection of the cap (device counts) as spacenavd reports it, and the period in ms."""

    x: int
    y: int
    z: int
    rx: int
    ry: int
    rz: int
    period_ms: int

    @property
    def axes(self) -> tuple[int, int, int, int, int, int]:
        """(x, y, z, rx, ry, rz)."""
        return (self.x, self.y, self.z, self.rx, self.ry, self.rz)

    def axis(self, name: str) -> int:
        """One axis by name: ``x``, ``y``, ``z``, ``rx``, ``ry`` or ``rz``."""
        return {"x": self.x, "y": self.y, "z": self.z,
                "rx": self.rx, "ry": self.ry, "rz": self.rz}[name]


@dataclass(frozen=True)
class ButtonEvent:
    """A button (numbered from 0) went down (``pressed``) or up."""

    button: int
    pressed: bool


SpnavEvent = MotionEvent | ButtonEvent


def decode_event(packet: bytes) -> SpnavEvent:
    """Decode one 32-byte packet; ProtocolError for a wrong size or an unknown type."""
    if len(packet) != EVENT_BYTES:
        raise ProtocolError(f"spacenavd event must be {EVENT_BYTES} bytes, got {len(packet)}")
    words = EVENT.unpack(packet)
    kind = words[0]
    if kind == _MOTION:
        return MotionEvent(*words[1:8])
    if kind in (_PRESS, _RELEASE):
        if words[1] < 0:
            raise ProtocolError(f"spacenavd button event with button number {words[1]}")
        return ButtonEvent(words[1], kind == _PRESS)
    raise ProtocolError(f"unknown spacenavd event type {kind} in {words}")
