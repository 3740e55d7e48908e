"""PyBullet's start-up banner lands on neither stdout nor stderr (finepos prints JSON and
one-line errors there)."""

from __future__ import annotations

import subprocess
import sys


def test_import_prints_no_banner():
    done = subprocess.run(
        [sys.executable, "-c", "from sim_backend.cell.pybullet_quiet import p; print('ok')"],
        capture_output=True, text=True, timeout=60, check=True)
    assert done.stdout == "ok\n"
    assert "pybullet build time" not in done.stderr


def test_help_output_has_no_banner():
    done = subprocess.run([sys.executable, "-m", "controller.cli", "sim", "snapshot", "--help"],
                          capture_output=True, text=True, timeout=60, check=True)
    assert done.stdout.startswith("usage: finepos sim snapshot")
    assert "pybullet build time" not in done.stdout + done.stderr
