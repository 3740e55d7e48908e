"""``--part NAME`` on the workflow and evaluation commands: the parser, how the part and its
state folder are chosen, and the commands on the simulated cell."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from calibration_free.dataset import Dataset
from controller import cli
from controller.commands.common import part_setup
from controller.config import config_from_mapping, load_config
from drivers.core.cell_state import CellState
from drivers.core.errors import ConfigError
from drivers.core.pose import Pose

PART_COMMANDS = ("teach", "acquire", "train", "position", "grasp", "evaluate", "table1", "demo")
CTL_JOB_COMMANDS = ("teach", "acquire", "train", "rezero", "position", "grasp")
POSE = Pose(300.0, 0.0, 150.0, -90.0, 90.0, 0.0)


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices


@pytest.mark.parametrize("command", PART_COMMANDS)
def test_every_part_command_takes_part_and_refuses_an_unknown_one(command, tmp_path, capsys):
    parser = _subparsers(cli.build_parser())[command]
    option = next(a for a in parser._actions if "--part" in a.option_strings)
    assert option.type("nut") == "nut"
    required = {"acquire": ["--set", "nn1"], "table1": ["--out", str(tmp_path / "t")]}.get(
        command, [])
    with pytest.raises(SystemExit) as exited:
        cli.build_parser().parse_args([command, *required, "--part", "../etc"])
    assert exited.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert "not a part's name: '../etc' (built-in parts: cube, nut, ledge, screw; declare" in last
    state = [] if command == "table1" else ["--state-dir", str(tmp_path)]
    assert cli.main([command, *required, *state, "--part", "bolt"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].endswith("unknown part 'bolt' (known parts: cube, nut, ledge, screw; declare "
                            "a new one under parts: in the cell config, "
                            "docs/quickstart.md#adding-a-part)")


@pytest.mark.parametrize("command", CTL_JOB_COMMANDS)
def test_every_ctl_job_command_takes_part(command):
    args = cli.build_parser().parse_args(["ctl", command, "--part", "ledge"]
                                         + (["--set", "nn1"] if command == "acquire" else []))
    assert args.part == "ledge"
    args = cli.build_parser().parse_args(["ctl", command, "--part", "bracket"]
                                         + (["--set", "nn1"] if command == "acquire" else []))
    assert args.part == "bracket"  # a declared part: the service checks it against its config


def test_only_evaluate_takes_all():
    assert cli.build_parser().parse_args(["evaluate", "--part", "all"]).part == "all"
    with pytest.raises(SystemExit):
        cli.build_parser().parse_args(["position", "--part", "all"])


def test_a_declared_part_is_taken_wherever_a_built_in_one_is(tmp_path):
    config = config_from_mapping({"parts": {"pin": {"grasp_width_mm": 6.0, "kappa": 2}}})
    part_config, folder = part_setup(_args(tmp_path, "pin"), config)
    assert folder == tmp_path / "pin"
    assert part_config.controller.part == "pin" and part_config.scene.object.kind == "pin"
    with pytest.raises(ConfigError, match=r"unknown part 'pin' \(known parts: cube, nut, "
                                          r"ledge, screw; declare"):
        part_setup(_args(tmp_path, "pin"), load_config(None))


def _args(tmp_path, part=None):
    return argparse.Namespace(state_dir=str(tmp_path), part=part)


def _teach(folder, kind: str, kappa: int) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    CellState(POSE, kind, kappa, 40.0, 20.0, "test", 1.0).save(folder / "cell.json")


def test_part_setup_puts_the_part_on_the_simulated_table_and_picks_its_folder(tmp_path):
    config = load_config(None)
    part_config, folder = part_setup(_args(tmp_path, "screw"), config)
    assert folder == tmp_path / "screw"
    assert part_config.controller.part == "screw" and part_config.scene.object.kind == "screw"
    assert part_config.scene.object.x_mm == config.scene.object.x_mm  # placement kept
    # Without --part and nothing taught: the simulated table's part.
    assert part_setup(_args(tmp_path), config)[1] == tmp_path / "cube"
    _teach(tmp_path / "ledge", "ledge", 2)
    assert part_setup(_args(tmp_path), config)[0].scene.object.kind == "ledge"  # the one taught
    assert part_setup(_args(tmp_path), config, teach=True)[1] == tmp_path / "cube"  # the cell's
    _teach(tmp_path / "nut", "nut", 6)
    with pytest.raises(ConfigError, match="several parts are taught"):
        part_setup(_args(tmp_path), config)


def test_on_a_real_cell_the_default_part_is_the_configured_one(tmp_path):
    config = config_from_mapping({"arm": {"type": "val", "port": "loop://"},
                                  "camera": {"type": "opencv", "source": "0"},
                                  "wrench": {"type": "ati", "port": "loop://"},
                                  "controller": {"part": "nut"}})
    part_config, folder = part_setup(_args(tmp_path), config, teach=True)
    assert folder == tmp_path / "nut" and part_config.controller.part == "nut"


def test_a_single_part_state_folder_still_works_from_the_command_line(tmp_path, capsys):
    _teach(tmp_path, "cube", 4)  # the layout before parts had folders: cell.json at the top
    assert cli.main(["train", "--state-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert str(tmp_path / "datasets" / "nn1.npz") in err  # read where that layout keeps it
    assert cli.main(["train", "--state-dir", str(tmp_path), "--part", "nut"]) == 2
    assert "no cell state yet" in capsys.readouterr().err  # the nut is not taught


def test_evaluate_options_that_do_not_go_with_part_all(capsys):
    assert cli.main(["evaluate", "--part", "all", "--model", "m.fpm"]) == 2
    assert "--model: not with --part all" in capsys.readouterr().err
    assert cli.main(["evaluate", "--workers", "2"]) == 2
    assert "--workers: only with --part all" in capsys.readouterr().err


def test_teach_and_acquire_each_part_on_the_simulated_cell(tmp_path, capsys):
    state = tmp_path / "state"
    config = tmp_path / "small.yaml"
    config.write_text("controller: {acquisition: {test_count: 2}}\n")
    common = ["--config", str(config), "--state-dir", str(state)]
    assert cli.main(["teach", "--auto", "--part", "nut", *common]) == 0
    taught = json.loads(capsys.readouterr().out)
    assert taught["part"] == "nut" and taught["kappa"] == 6  # the nut was on the table
    assert taught["state_file"] == str(state / "nut" / "cell.json")
    assert cli.main(["acquire", "--set", "test", *common]) == 0  # the one part taught
    acquired = json.loads(capsys.readouterr().out)
    assert acquired["part"] == "nut"
    data = Dataset.load(state / "nut" / "datasets" / "test.npz")
    assert data.metadata["object_kind"] == "nut" and len(data) == 2
    assert cli.main(["teach", "--auto", *common]) == 0  # the scene's part, the cube
    assert json.loads(capsys.readouterr().out)["state_file"] == str(state / "cube" / "cell.json")
    assert cli.main(["acquire", "--set", "test", *common]) == 2
    assert "several parts are taught (cube, nut); name one with --part" in \
        capsys.readouterr().err
    assert cli.main(["acquire", "--set", "test", "--part", "cube", *common]) == 0
    cube = Dataset.load(state / "cube" / "datasets" / "test.npz")
    assert cube.metadata["object_kind"] == "cube"
    assert not np.array_equal(cube.images[0], data.images[0])
