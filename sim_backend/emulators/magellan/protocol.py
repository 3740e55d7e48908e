"""The Magellan serial mouse's wire format, as spacenavd 1.1 reads it (pure encoding).

- Motion packet: ``d`` + six axes x 4 characters + ``\\r``; each axis is the 16-bit word
  ``value + 0x8000``, most significant nibble first, one character per nibble. spacenavd uses
  only ``char & 0x0F``; the classic Magellan table ``0AB3D56GH9:K<MN?`` is used here.
- Key packet: ``k`` + 3 characters + ``\\r``: the nibbles of buttons 0-3, 4-7 and 8-11 (bit 0
  of the first is button 0).
- spacenavd negates the Magellan's Z and rZ. ``encode_motion`` takes the values a spacenavd
  client should see and negates z and rz on the wire, as a real Magellan reports them.

Probe replies (the daemon's ``\\r@RESET\\r``, ``vQ\\r`` and ``m3\\r``) are in
``sim_backend.emulators.magellan.emulator``.
"""

from __future__ import annotations

from collections.abc import Iterable

NIBBLE_CHARS = b"0AB3D56GH9:K<MN?"
BUTTON_COUNT = 12
AXIS_MIN, AXIS_MAX = -0x8000, 0x7FFF
_WIRE_SIGNS = (1, 1, -1, 1, 1, -1)  # x, y, z, rx, ry, rz: the daemon negates z and rz


def _word(value: int) -> bytes:
    word = value + 0x8000
    return bytes(NIBBLE_CHARS[(word >> shift) & 0xF] for shift in (12, 8, 4, 0))


def encode_motion(axes: Iterable[int]) -> bytes:
    """A ``d`` packet for client-side (x, y, z, rx, ry, rz) values."""
    values = [int(v) for v in axes]
    if len(values) != 6:
        raise ValueError(f"a motion needs 6 axes, got {len(values)}")
    wire = [sign * v for sign, v in zip(_WIRE_SIGNS, values, strict=True)]
    for v in wire:
        if not AXIS_MIN <= v <= AXIS_MAX:
            raise ValueError(f"axis value {v} outside {AXIS_MIN}..{AXIS_MAX}")
    return b"d" + b"".join(_word(v) for v in wire) + b"\r"


def encode_buttons(pressed: Iterable[int]) -> bytes:
    """A ``k`` packet with the given buttons (0..11) down and all others up."""
    mask = 0
    for button in pressed:
        if not 0 <= button < BUTTON_COUNT:
            raise ValueError(f"button {button} outside 0..{BUTTON_COUNT - 1}")
        mask |= 1 << button
    return b"k" + bytes(NIBBLE_CHARS[(mask >> shift) & 0xF] for shift in (0, 4, 8)) + b"\r"
