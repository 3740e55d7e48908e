"""PyBullet, imported with its start-up banner sent to stderr.

PyBullet's C extension prints "pybullet build time: ..." to file descriptor 1 when first
imported; finepos commands print JSON on stdout, so the banner must not land there. Every
module imports PyBullet as ``from sim_backend.cell.pybullet_quiet import p``.
"""

from __future__ import annotations

import os
import sys


def _import_quietly():
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        import pybullet
    finally:
        os.dup2(saved, 1)
        os.close(saved)
    return pybullet


p = _import_quietly()
