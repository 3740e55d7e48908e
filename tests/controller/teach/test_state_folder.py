"""The state folder's per-part layout (controller.teach.state_folder), single-part folders of
before it included, and how a command's part is chosen."""

from __future__ import annotations

import pytest

from controller.teach.state_folder import StateFolder
from drivers.core.cell_state import CellState
from drivers.core.errors import ConfigError
from drivers.core.parts import PARTS, declare
from drivers.core.pose import Pose

POSE = Pose(300.0, 0.0, 150.0, -90.0, 90.0, 0.0)


def _teach(folder, kind: str, kappa: int) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    CellState(POSE, kind, kappa, 40.0, 20.0, "test", 1.0).save(folder / "cell.json")


def test_each_part_has_its_own_folder(tmp_path):
    state = StateFolder(tmp_path, "cube")
    assert state.taught() == {}
    assert state.part_dir("nut") == tmp_path / "nut"
    _teach(tmp_path / "nut", "nut", 6)
    _teach(tmp_path / "screw", "screw", 1)
    assert state.taught() == {"nut": tmp_path / "nut", "screw": tmp_path / "screw"}
    assert state.part_dir("cube") == tmp_path / "cube"
    assert state.folders() == [tmp_path, tmp_path / "datasets", tmp_path / "nut",
                               tmp_path / "nut" / "datasets", tmp_path / "screw",
                               tmp_path / "screw" / "datasets"]


def test_the_part_is_the_named_one_else_the_one_taught_else_the_cells(tmp_path):
    state = StateFolder(tmp_path, "cube")
    assert state.resolve(None, "cube") == "cube"  # nothing taught: the cell's
    assert state.resolve("ledge", "cube") == "ledge"
    _teach(tmp_path / "nut", "nut", 6)
    assert state.resolve(None, "cube") == "nut"  # the one taught
    _teach(tmp_path / "ledge", "ledge", 2)
    assert state.resolve("ledge", "cube") == "ledge"
    with pytest.raises(ConfigError) as ambiguous:
        state.resolve(None, "cube")
    message = str(ambiguous.value)
    assert "several parts are taught (nut, ledge)" in message and "--part" in message
    assert "\n" not in message


def test_an_unknown_part_is_refused_listing_the_known_ones_and_where_to_declare(tmp_path):
    with pytest.raises(ConfigError, match=r"unknown part 'bolt' \(known parts: cube, nut, "
                                          r"ledge, screw; declare a new one under parts: in "
                                          r"the cell config"):
        StateFolder(tmp_path, "cube").resolve("bolt", "cube")
    with pytest.raises(ConfigError, match="unknown part"):
        StateFolder(tmp_path, "cube").part_dir("../etc")
    assert StateFolder(tmp_path, "cube").resolve("screw", "cube") == "screw"


def test_a_declared_part_has_a_folder_of_its_own(tmp_path):
    declared = PARTS.with_declared(declare({"pin": {"grasp_width_mm": 6.0}}))
    state = StateFolder(tmp_path, "cube", declared)
    assert state.resolve("pin", "cube") == "pin"
    assert state.part_dir("pin") == tmp_path / "pin"
    _teach(tmp_path / "pin", "pin", 2)
    assert state.taught() == {"pin": tmp_path / "pin"}
    assert StateFolder(tmp_path, "cube").taught() == {}  # a config without it: not known


def test_a_single_part_folder_is_read_as_the_part_it_records(tmp_path):
    _teach(tmp_path, "cube", 4)  # cell.json at the top: written before parts had folders
    state = StateFolder(tmp_path, "nut")
    assert state.single_part() == "cube"
    assert state.taught() == {"cube": tmp_path}
    assert state.part_dir("cube") == tmp_path  # read and re-taught in place
    assert state.resolve(None, "nut") == "cube"
    assert state.part_dir("nut") == tmp_path / "nut"  # another part: a folder of its own
    _teach(tmp_path / "nut", "nut", 6)
    assert state.taught() == {"cube": tmp_path, "nut": tmp_path / "nut"}
    _teach(tmp_path / "cube", "cube", 4)  # once moved (or taught anew) into its own folder
    assert state.part_dir("cube") == tmp_path / "cube"
    assert state.taught()["cube"] == tmp_path / "cube"


def test_a_damaged_single_part_folder_counts_as_the_configured_part(tmp_path):
    (tmp_path / "cell.json").write_text("{not json")
    state = StateFolder(tmp_path, "ledge")
    assert state.taught() == {"ledge": tmp_path}
    assert state.part_dir("ledge") == tmp_path  # its loading error shows where it is used
