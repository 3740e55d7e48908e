"""The recipe lives in the model file: training writes it, a run reads its loop keys back."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from calibration_free.bundle import ModelBundle
from calibration_free.synthetic import SyntheticCell, render
from controller.cli import main
from controller.config import load_config
from controller.fine_positioner import FinePositioner
from controller.recipe import DEFAULT_RECIPE, recipe_from_mapping, recipe_of_model
from controller.systems.gabor import GaborSystem
from drivers.core.errors import ConfigError


@pytest.fixture
def state(trained, tmp_path):
    folder = tmp_path / "state"
    shutil.copytree(trained, folder)
    return folder


def stored_recipe(state) -> dict:
    return ModelBundle.load(state / "model-gabor.fpm").training["recipe"]


@pytest.mark.slow  # trains three times
def test_train_writes_the_recipe_into_the_model_and_a_run_reads_it_back(state, tmp_path,
                                                                       capsys):
    recipe = tmp_path / "recipe.yaml"
    recipe.write_text("perception:\n  edge_coverage: grey\nloop:\n  settle_frames: 5\n"
                      "  look_around_deg: null\n")
    assert main(["train", "--state-dir", str(state), "--recipe", str(recipe)]) == 0
    assert json.loads(capsys.readouterr().out)["recipe"] == str(recipe)
    stored = stored_recipe(state)
    assert stored["perception"]["edge_coverage"] == "grey"
    assert stored["loop"]["settle_frames"] == 5 and stored["loop"]["look_around_deg"] is None
    cell = load_config(None)
    fp = FinePositioner(None, cell, state_dir=state)
    fp.load_model()
    loop = fp.loop_config()
    assert loop.settle_frames == 5 and loop.look_around_deg is None
    assert loop.max_loops == cell.controller.loop.max_loops  # the cell's key stays the cell's
    assert fp._model.model.front.edge_gamma == 0.0  # grey edges, as trained

    # training again without --recipe keeps the model file's recipe
    assert main(["train", "--state-dir", str(state)]) == 0
    assert json.loads(capsys.readouterr().out)["recipe"] == "kept"
    assert stored_recipe(state) == stored
    # an empty recipe file is the default recipe
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    assert main(["train", "--state-dir", str(state), "--recipe", str(empty)]) == 0
    assert stored_recipe(state) == DEFAULT_RECIPE.to_mapping()


def test_a_model_file_without_a_recipe_runs_with_the_defaults(state):
    bundle = ModelBundle.load(state / "model-gabor.fpm")
    old = bundle.training.copy()
    old.pop("recipe", None)
    assert recipe_of_model(type("M", (), {"training": old})()) == DEFAULT_RECIPE
    cell = load_config(None)
    fp = FinePositioner(None, cell, state_dir=state)
    assert fp.loop_config() == cell.controller.loop  # no model in use yet


def test_a_bad_recipe_file_is_one_line_naming_the_file_and_key(state, tmp_path, capsys):
    recipe = tmp_path / "recipe.yaml"
    recipe.write_text("loop:\n  max_loops: 3\n")
    before = (state / "model-gabor.fpm").read_bytes()
    assert main(["train", "--state-dir", str(state), "--recipe", str(recipe)]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].endswith(f"{recipe}: loop.max_loops: a cell key, not a recipe key: set "
                            "controller.loop.max_loops in the cell config"), err
    assert (state / "model-gabor.fpm").read_bytes() == before


def test_a_damaged_stored_recipe_is_named():
    model = type("M", (), {"training": {"recipe": {"perception": {"seed": "x"}}}})()
    with pytest.raises(ConfigError, match="model recipe: perception.seed"):
        recipe_of_model(model)


OLD_MODEL = Path(__file__).parent / "data" / "model-gabor-without-recipe.fpm"


def test_a_model_file_written_before_recipes_loads_and_runs_with_the_defaults():
    """A Gabor model file written before the recipe existed (a synthetic cube, trained by
    the code of 4fd3f9e) loads, reads the recipe's defaults, and reads zero at the taught
    pose."""
    model = GaborSystem.load(OLD_MODEL)
    assert "recipe" not in model.model.training
    assert recipe_of_model(model.model) == DEFAULT_RECIPE
    cell = load_config(None)
    fp = FinePositioner(None, cell, state_dir=OLD_MODEL.parent)
    assert fp.loop_config(model) == cell.controller.loop
    estimator = GaborSystem.estimator(model)
    image = render(SyntheticCell(), np.zeros(3), np.random.default_rng(1))
    tr = estimator.estimate_translation(image)
    assert tr.status == "ok" and abs(tr.dx_mm) < 0.3 and abs(tr.dy_mm) < 0.3


@pytest.mark.parametrize("stages", [["axis"], ["ends", "outline"]])
def test_a_recipe_naming_the_long_axis_stages_without_the_axis_is_refused(stages):
    with pytest.raises(ConfigError, match=r"^r: perception: stages: .* needs the long axis"):
        recipe_from_mapping({"perception": {"axis": False, "stages": stages}}, "r")


def test_the_default_recipe_names_no_stages():
    assert DEFAULT_RECIPE.perception.stages is None
    assert recipe_from_mapping({"perception": {"stages": ["outline"]}}).perception.stages \
        == ("outline",)
