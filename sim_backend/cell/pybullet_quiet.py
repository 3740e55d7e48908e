"""PyBullet, imported without its start-up banner.

PyBullet's C extension writes "pybullet build time: ..." straight to a file descriptor when
first imported; finepos commands print JSON on stdout and one-line errors on stderr, so the
banner must land on neither. Every module imports PyBullet as
``from sim_backend.cell.pybullet_quiet import p``.
"""

from __future__ import annotations

import os
import sys


def _import_quietly():
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        import pybullet
    finally:
        for fd, copy in zip((1, 2), saved, strict=True):
            os.dup2(copy, fd)
            os.close(copy)
        os.close(devnull)
    return pybullet


p = _import_quietly()
