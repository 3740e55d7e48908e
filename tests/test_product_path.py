"""The real-cell path at run time: on a real cell's config, the cell commands load neither the
simulator nor the lab.

``tests/test_layout.py`` proves it from the source; this runs it in a fresh interpreter, as
``finepos COMMAND`` does: each cell command's parser is built and its help printed, a config
naming the real devices is loaded (its ``scene`` section stays unread) and the service's and
the positioner's modules are imported. PyBullet is not loaded either.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from controller.cli import CELL_COMMAND_MODULES
from tests.test_layout import LAB, REAL_CELL_PATH, ROOT

REAL_CELL_CONFIG = """\
arm: {type: val, port: "loop://"}
camera: {type: opencv, source: 0}
wrench: {type: ati, port: "loop://"}
scene: {lighting: {preset: poor}}
"""

SCRIPT = """
import contextlib, io, json, sys
from controller.cli import CELL_COMMAND_MODULES, main

LAB = tuple(json.loads(sys.argv[2]))

def lab_loaded():
    return sorted(m for m in sys.modules if m == "pybullet" or any(
        m == lab or m.startswith(lab + ".") for lab in LAB))

found = {}
for command in CELL_COMMAND_MODULES:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
        main([command, "--help"])
    found[command] = {"usage": out.getvalue().split("\\n")[0], "lab": lab_loaded()}

from controller.config import load_config
from controller.fine_positioner import FinePositioner
from controller.service.service import Service

config = load_config(sys.argv[1])
found["config"] = {"scene": type(config.scene).__name__, "lab": lab_loaded()}
print(json.dumps(found))
"""


def test_the_import_graph_test_starts_from_every_cell_command():
    assert set(CELL_COMMAND_MODULES.values()) <= set(REAL_CELL_PATH)


@pytest.mark.slow
def test_a_real_cell_loads_neither_the_simulator_nor_the_lab(tmp_path):
    config = tmp_path / "cell.yaml"
    config.write_text(REAL_CELL_CONFIG)
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(config), json.dumps(LAB)],
                          cwd=ROOT, capture_output=True, text=True, timeout=120, check=True)
    found = json.loads(done.stdout)
    for command in CELL_COMMAND_MODULES:
        assert found[command]["usage"].startswith(f"usage: finepos {command}")
        assert found[command]["lab"] == [], f"finepos {command}"
    assert found["config"] == {"scene": "UnreadScene", "lab": []}
