"""Keyboard-driven 3D-mouse input: keys deflect the emulated Magellan's cap, digits click buttons.

Keys (client-side axes, see ``drivers.spacenav.jog`` for what they do to the tool):

    a / d   x  - / +   (cap left / right)        r / f   y  + / -   (cap up / down)
    w / s   z  + / -   (cap away / towards you)  q / e   ry + / -   (twist left / right)
    0 .. 9  click that button                    Esc, Ctrl-C, Ctrl-D   quit

Each key press holds its deflection for ``hold_s``; the terminal's key repeat keeps it held.
"""

from __future__ import annotations

import contextlib
import os
import sys
import termios
import tty
from collections.abc import Iterator

from sim_backend.emulators.magellan.emulator import MagellanEmulator
from sim_backend.emulators.magellan.script import Motion, click

_AXIS_KEYS = {  # key: (axis index, sign)
    "a": (0, -1), "d": (0, 1), "r": (1, 1), "f": (1, -1),
    "w": (2, 1), "s": (2, -1), "q": (4, 1), "e": (4, -1),
}
_QUIT_KEYS = {"\x1b", "\x04"}  # Esc, Ctrl-D (Ctrl-C raises KeyboardInterrupt)


def steps_for_key(key: str, deflection: int, hold_s: float) -> list | None:
    """The script steps one key press means; [] for an unknown key, None to quit."""
    if key in _QUIT_KEYS:
        return None
    if key.isdigit():
        return click(int(key))
    if key in _AXIS_KEYS:
        index, sign = _AXIS_KEYS[key]
        axes = [0] * 6
        axes[index] = sign * deflection
        return [Motion(tuple(axes), hold_s)]
    return []


@contextlib.contextmanager
def raw_terminal(fd: int) -> Iterator[None]:
    """Single key presses without Enter or echo (keys typed before are kept); the terminal is
    restored on exit."""
    saved = termios.tcgetattr(fd)
    try:
        tty.setcbreak(fd, termios.TCSANOW)
        yield
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)


def drive_from_keyboard(mouse: MagellanEmulator, deflection: int = 200,
                        hold_s: float = 0.15) -> None:
    """Read keys from stdin (a terminal) until a quit key; each one drives ``mouse``."""
    fd = sys.stdin.fileno()
    with raw_terminal(fd):
        while True:
            key = os.read(fd, 1).decode("ascii", "replace")
            steps = steps_for_key(key, deflection, hold_s) if key else None
            if steps is None:
                return
            if steps:
                mouse.play(steps, replace=True)
