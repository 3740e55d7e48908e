"""``finepos sim snapshot`` and ``finepos bench sim``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import pytest

from controller.cli import main
from drivers.core.pose import ToolStep
from sim_backend import bench
from sim_backend.cell.scene_config import SceneConfig
from sim_backend.snapshot import parse_offset


def test_snapshot_writes_the_hand_camera_image(tmp_path):
    config = tmp_path / "finepos.yaml"
    config.write_text("scene:\n  lighting: {preset: side}\n  camera: {noise_std: 0}\n")
    out = tmp_path / "hand.png"
    assert main(["sim", "snapshot", "--config", str(config), "--out", str(out),
                 "--offset", "10,-5,20"]) == 0
    image = cv2.imread(str(out))
    assert image.shape == (144, 192, 3)


def test_snapshot_reports_a_bad_config_with_its_key_path(tmp_path, capsys):
    config = tmp_path / "bad.yaml"
    config.write_text("scene:\n  object: {kind: sphere}\n")
    assert main(["sim", "snapshot", "--config", str(config), "--out",
                 str(tmp_path / "x.png")]) == 2
    assert "bad.yaml: scene.object.kind: unknown part 'sphere' (known parts: cube, nut, " \
           "ledge, screw; declare" in capsys.readouterr().err


def test_snapshot_shows_a_part_declared_in_the_config(tmp_path, capsys):
    example = Path(__file__).resolve().parents[2] / "deploy" / "parts" / "example.yaml"
    out = tmp_path / "bracket.png"
    assert main(["sim", "snapshot", "--config", str(example), "--part", "bracket", "--out",
                 str(out)]) == 0
    assert cv2.imread(str(out)).shape == (144, 192, 3)
    assert main(["sim", "snapshot", "--part", "bracket", "--out", str(out)]) == 2
    assert "--part: unknown part 'bracket'" in capsys.readouterr().err


@pytest.mark.parametrize("text, message", [
    ("10,-5", "three numbers"),
    ("a,b,c", "as numbers"),
    ("1,nan,0", "finite"),
    ("70,0,0", "beyond the 60 mm"),
    ("0,0,400", "DPHI must be within"),
])
def test_bad_offsets_are_explained(text, message):
    with pytest.raises(ValueError, match=message):
        parse_offset(text)


def test_offset_parses_into_a_tool_step():
    assert parse_offset(" 10, -5 ,20") == ToolStep(10.0, -5.0, 0.0, 20.0)


def test_bench_measures_the_three_medians(tmp_path):
    results = bench.measure(SceneConfig(), repeats=10)
    for key in ("render_ms", "move_ms", "look_and_move_ms"):
        assert results[key]["median"] > 0 and results[key]["p90"] >= results[key]["median"]
    realistic = results["realistic_look_and_move"]  # cell seconds next to wall time
    assert realistic["cell_ms"] > 0.0 and realistic["wall_ms"] > 0.0
    # the move's line, its echo and the prompt (a move starts from the pose the last one
    # reached: no `where`), at 9600 baud
    assert realistic["wire_ms"] > 100.0 and realistic["motion_ms"] > 0.0
    assert realistic["cell_ms"] == pytest.approx(
        realistic["wire_ms"] + realistic["motion_ms"] + realistic["camera_ms"], rel=0.05)
    out = tmp_path / "bench.json"
    assert main(["bench", "sim", "--repeats", "10", "--json", str(out)]) == 0
    written = json.loads(out.read_text())
    assert {"cpu", "render_ms", "move_ms", "look_and_move_ms", "meets_target"} <= set(written)


def test_every_subcommands_help_starts_with_its_example():
    from controller.cli import build_parser

    parser = build_parser()
    groups = [parser]
    seen = 0
    while groups:
        group = groups.pop()
        for action in group._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    if any(isinstance(a, argparse._SubParsersAction) for a in sub._actions):
                        groups.append(sub)
                    else:
                        seen += 1
                        assert (sub.description or "").startswith("Example: finepos "), name
    assert seen >= 20
