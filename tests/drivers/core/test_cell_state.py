"""The cell state file under damage (issue 15): NaN, infinite, huge or wrongly typed values and
files that are not regular files give one StateError line naming the file, never a traceback."""

from __future__ import annotations

import json
import os

import pytest

from drivers.core.cell_state import CellState, StateError
from drivers.core.pose import Pose

GOOD = CellState(Pose(300.0, 0.0, 150.0, -90.0, 90.0, 0.0), "cube", 4, 5.0, 30.0, "test", 1.0)


def _damaged(tmp_path, text: str):
    path = tmp_path / "cell.json"
    path.write_text(text)
    with pytest.raises(StateError) as refused:
        CellState.load(path)
    message = str(refused.value)
    assert message.startswith(str(path)) and "\n" not in message
    return message


def _with(tmp_path, **changes) -> str:
    GOOD.save(tmp_path / "cell.json")
    data = json.loads((tmp_path / "cell.json").read_text())
    for key, value in changes.items():
        if key.startswith("pose_"):
            data["nominal_pose"][key[5:]] = value
        else:
            data[key] = value
    return json.dumps(data)


@pytest.mark.parametrize("value", ["NaN", "Infinity", "-Infinity", "1e999", "1e308", "-1e308"])
def test_non_finite_or_huge_pose_values_are_refused(tmp_path, value):
    text = _with(tmp_path, pose_x_mm=0.5).replace('"x_mm": 0.5', f'"x_mm": {value}')
    message = _damaged(tmp_path, text)
    assert "x_mm" in message or "not a number" in message


@pytest.mark.parametrize("changes", [
    {"nominal_pose": "300,0,150"}, {"nominal_pose": [1, 2, 3, 4, 5, 6]},
    {"nominal_pose": {"x_mm": 1}}, {"pose_z_mm": "150"}, {"pose_o_deg": True},
    {"kappa": 0}, {"kappa": 2.5}, {"kappa": 10**30}, {"grasp_depth_mm": -1},
    {"object_width_mm": 1e300}, {"object_kind": 7}, {"taught_at": None},
], ids=str)
def test_wrong_types_and_ranges_are_refused(tmp_path, changes):
    _damaged(tmp_path, _with(tmp_path, **changes))


def test_missing_key_not_utf8_and_a_fifo(tmp_path):
    data = json.loads(_with(tmp_path))
    del data["kappa"]
    assert "'kappa' is missing" in _damaged(tmp_path, json.dumps(data))
    path = tmp_path / "cell.json"
    path.write_bytes(b'{"version": 1, \xff}')
    with pytest.raises(StateError, match="unreadable"):
        CellState.load(path)
    path.unlink()
    os.mkfifo(path)
    with pytest.raises(StateError, match="FIFO"):
        CellState.load(path)


def test_a_good_file_still_loads(tmp_path):
    GOOD.save(tmp_path / "cell.json")
    assert CellState.load(tmp_path / "cell.json") == GOOD


def test_a_file_written_before_kappa_was_found_from_images_loads_unchanged(tmp_path):
    GOOD.save(tmp_path / "cell.json")
    data = json.loads((tmp_path / "cell.json").read_text())
    del data["kappa_found"]  # as written before the field existed
    (tmp_path / "cell.json").write_text(json.dumps(data))
    assert CellState.load(tmp_path / "cell.json") == GOOD


def test_the_kappa_found_round_trips_and_must_be_an_object(tmp_path):
    found = {"kappa": 4, "sure": True, "confidence": 0.98, "scores_px": [1.2, 0.02],
             "repeat_px": 0.01, "reason": "the view repeats every 90 deg"}
    state = CellState(GOOD.nominal_pose, "cross", 4, 5.0, 30.0, "auto", 1.0, found)
    state.save(tmp_path / "cell.json")
    assert CellState.load(tmp_path / "cell.json").kappa_found == found
    assert "kappa_found: expected an object" in _damaged(tmp_path, _with(tmp_path,
                                                                         kappa_found=4))
