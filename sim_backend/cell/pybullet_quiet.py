"""PyBullet, imported without its start-up banner, and a guard for its other chatter.

PyBullet's C extension writes "pybullet build time: ..." straight to a file descriptor when
first imported, and its convex decomposition (``p.vhacd``) writes its progress there too;
finepos commands print JSON on stdout and one-line errors on stderr, so neither may land on
them. Every module imports PyBullet as ``from sim_backend.cell.pybullet_quiet import p`` and
calls what chatters inside ``silenced()``.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
from collections.abc import Iterator


def _flush_c_streams() -> None:
    """Flush the C library's buffered streams (what C code printed lands where fd 1 and 2
    point now, not after they are restored)."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None).fflush(None)


@contextlib.contextmanager
def silenced() -> Iterator[None]:
    """File descriptors 1 and 2 sent to the null device while the block runs."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        _flush_c_streams()
        for fd, copy in zip((1, 2), saved, strict=True):
            os.dup2(copy, fd)
            os.close(copy)
        os.close(devnull)


def _import_quietly():
    with silenced():
        import pybullet
    return pybullet


p = _import_quietly()
