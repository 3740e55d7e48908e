"""The root config: sections, device backends by type, errors naming the key path."""

import pytest

from controller.config import (
    config_from_mapping,
    load_config,
    recipe_of,
    with_part,
    with_recipe,
)
from controller.devices import with_device
from controller.recipe import Recipe, recipe_from_mapping
from controller.simulated import UnreadScene
from drivers.core.errors import ConfigError


def test_defaults_are_the_simulated_cell():
    cfg = load_config(None)
    assert (cfg.arm.type, cfg.camera.type, cfg.wrench.type) == ("sim", "sim", "sim")
    assert cfg.controller.loop.r_fine_mm == 4.0
    acquisition = cfg.controller.acquisition
    assert acquisition.nn1.a_mm == 25.0 and acquisition.nn2.a_mm == 5.0
    assert cfg.perception.gabor.n_filters == 36


def test_backend_options_are_checked_by_type():
    cfg = config_from_mapping({"arm": {"type": "val", "port": "loop://"},
                               "wrench": {"type": "ati", "port": "loop://"},
                               "camera": {"type": "opencv", "source": "http://127.0.0.1:1/x"}})
    assert cfg.arm.type == "val" and cfg.arm.options.port == "loop://"
    assert cfg.wrench.options.counts_per_force == 20.0


@pytest.mark.parametrize("data,message", [
    ({"robot": {}}, "robot: unknown section"),
    ({"arm": {"type": "kuka"}}, "arm.type: must be one of sim | val"),
    ({"arm": {"type": "sim", "repeatability_mm": -1}}, "arm.repeatability_mm: must be >= 0"),
    ({"arm": {"type": "val", "baudrate": 9600}}, "arm"),
    ({"scene": {"lighting": {"preset": "disco"}}}, "scene.lighting.preset: must be one of"),
    ({"controller": {"loop": {"max_loops": "four"}}},
     "controller.loop.max_loops: expected a number"),
    ({"controller": {"grasp": {"guards": [{"quantity": "fz_n", "op": "=", "limit": 1,
                                           "action": "stop"}]}}},
     "controller.grasp.guards[0].op: must be one of"),
    ({"safety": {"on_violation": "ignore"}}, "safety.on_violation: must be one of reject | clip"),
])
def test_bad_configs_name_the_key(data, message):
    with pytest.raises(ConfigError) as info:
        config_from_mapping(data)
    assert message in str(info.value)


@pytest.mark.parametrize("data,message", [
    ({"perception": {"gabor": {"lambda_px": 0}}}, "perception.gabor.lambda_px: must be > 0"),
    ({"loop": {"r_fine_mm": "four"}}, "loop.r_fine_mm: expected a number"),
    ({"loop": {"max_loops": 3}}, "loop.max_loops: a cell key, not a recipe key: set "
                                 "controller.loop.max_loops in the cell config"),
    ({"controller": {}}, "controller: unknown recipe section (allowed: perception, loop"),
    ({"loop": {"settle_frames": 4, "settle_max_frames": 2}}, "settle_max_frames: 2 is below"),
])
def test_bad_recipes_name_the_key(data, message):
    with pytest.raises(ConfigError) as info:
        recipe_from_mapping(data, "recipe.yaml")
    assert str(info.value).startswith("recipe.yaml: ") and message in str(info.value)


@pytest.mark.parametrize("data,message", [
    ({"perception": {"gabor": {"sigma_px": 10}}},
     "perception.gabor: a recipe key, kept in the model file: set it in a recipe file given "
     "to `finepos train --recipe FILE` (as perception.gabor)"),
    ({"perception": None}, "perception: a recipe key"),
    ({"controller": {"loop": {"max_loops": 3, "settle_frames": 5}}},
     "controller.loop.settle_frames: a recipe key, kept in the model file: set it in a recipe "
     "file given to `finepos train --recipe FILE` (as loop.settle_frames)"),
])
def test_a_cell_config_that_sets_a_recipe_key_names_its_home(data, message):
    with pytest.raises(ConfigError) as info:
        config_from_mapping(data)
    assert str(info.value) == message or str(info.value).startswith(message)
    assert "\n" not in str(info.value)


def test_a_recipe_runs_its_perception_and_loop_keys_and_keeps_the_cells():
    cell = config_from_mapping({"controller": {"loop": {"max_loops": 3.5}}})
    recipe = recipe_from_mapping({"perception": {"edge_coverage": "grey"},
                                  "loop": {"settle_frames": 5}})
    run = with_recipe(cell, recipe)
    assert run.perception.edge_coverage == "grey" and run.controller.loop.settle_frames == 5
    assert run.controller.loop.max_loops == 3.5  # the cell's key
    assert recipe_of(run) == Recipe(recipe.perception, run.controller.loop)
    stored = recipe_of(run).to_mapping()
    assert "max_loops" not in stored["loop"] and stored["loop"]["settle_frames"] == 5
    assert recipe_from_mapping(stored) == recipe_from_mapping(
        {"perception": {"edge_coverage": "grey"}, "loop": {"settle_frames": 5}})


def test_file_errors_name_the_file(tmp_path):
    f = tmp_path / "cell.yaml"
    f.write_text("scene:\n  clutter: {count: 99}\n")
    with pytest.raises(ConfigError, match=r"cell.yaml: scene.clutter.count: must be <= 8"):
        load_config(f)


REAL_DEVICES = {"arm": {"type": "val", "port": "loop://"},
                "wrench": {"type": "ati", "port": "loop://"},
                "camera": {"type": "opencv", "source": 0}}


def test_a_real_cell_leaves_the_scene_to_the_simulator():
    cfg = config_from_mapping({**REAL_DEVICES, "scene": {"lighting": {"preset": "disco"}}})
    assert cfg.scene == UnreadScene({"lighting": {"preset": "disco"}})
    assert with_part(cfg, "nut").controller.part == "nut"
    # a device made simulated reads the scene, with the same error as at load
    with pytest.raises(ConfigError, match="scene.lighting.preset: must be one of"):
        with_device(cfg, "camera", "sim")


def test_a_device_made_simulated_reads_the_scene():
    cfg = config_from_mapping({**REAL_DEVICES, "scene": {"lighting": {"preset": "poor"}}})
    assert with_device(cfg, "camera", "sim").scene.lighting.preset == "poor"


def test_a_partial_nn2_grid_keeps_nn2s_defaults():
    config = config_from_mapping({"controller": {"acquisition": {"nn2": {"shape": [3, 3, 3]}}}},
                                 "<test>")
    nn2 = config.controller.acquisition.nn2
    assert (nn2.a_mm, nn2.staggered, nn2.shape) == (5.0, True, (3, 3, 3))
    assert config.controller.acquisition.nn1.a_mm == 25.0


BRACKET = {"mesh": "parts/bracket.obj", "grasp_width_mm": 12.0, "grip_below_top_mm": 8.0,
           "jaw_opening_mm": 16.0, "mass_g": 20.0, "material": "wood",
           "color": [0.8, 0.3, 0.2], "kappa": 2}


def test_a_declared_part_joins_the_built_in_ones_with_its_mesh_beside_the_file(tmp_path):
    path = tmp_path / "cell" / "finepos.yaml"
    path.parent.mkdir()
    path.write_text("parts:\n  bracket: {mesh: parts/bracket.obj, grasp_width_mm: 12.0,\n"
                    "            jaw_opening_mm: 16.0, kappa: 2}\n"
                    "controller: {part: bracket}\nscene: {object: {kind: bracket}}\n")
    cfg = load_config(path)
    assert list(cfg.parts) == ["cube", "nut", "ledge", "screw", "bracket"]
    bracket = cfg.parts["bracket"]
    assert bracket.mesh_file == str(tmp_path / "cell" / "parts" / "bracket.obj")
    assert (bracket.kappa, bracket.grasp_width_mm, bracket.jaw_opening_mm) == (2, 12.0, 16.0)
    assert cfg.controller.part == "bracket" and cfg.scene.object.kind == "bracket"
    assert with_part(cfg, "nut").scene.object.kind == "nut"
    assert load_config(None).parts == config_from_mapping({}).parts  # the built-in four


def test_a_declaration_gives_the_issue_examples_fields_and_defaults_the_rest():
    part = config_from_mapping({"parts": {"bracket": BRACKET}}).parts["bracket"]
    assert (part.grip_below_top_mm, part.mass_g, part.material, part.color) == \
        (8.0, 20.0, "wood", (0.8, 0.3, 0.2))
    pin = config_from_mapping({"parts": {"pin": {"grasp_width_mm": 6.0}}}).parts["pin"]
    assert pin.kappa is None and pin.jaw_opening_mm == 9.0 and pin.mesh_file is None


@pytest.mark.parametrize("declared,message", [
    ({"jaw_opening_mm": 45.0}, "parts.bracket.jaw_opening_mm: 45 mm is over the gripper's "
                               "40 mm opening"),
    ({"grasp_width_mm": 16.0}, "parts.bracket.grasp_width_mm: 16 mm is not below the jaw "
                               "opening, 16 mm"),
    ({"grasp_width_mm": 39.0, "jaw_opening_mm": None},
     "parts.bracket.jaw_opening_mm: 42 mm is over the gripper's 40 mm opening"),
    ({"kappa": 0}, "parts.bracket.kappa: must be >= 1"),
    ({"material": "glass"}, "parts.bracket.material: must be one of wood | plastic | metal"),
    ({"colour": [1, 0, 0]}, "parts.bracket.colour: unknown key"),
])
def test_a_bad_declaration_names_the_value_and_the_limit(declared, message):
    with pytest.raises(ConfigError) as info:
        config_from_mapping({"parts": {"bracket": {**BRACKET, **declared}}})
    assert str(info.value) == message or str(info.value).startswith(message)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("parts,message", [
    ({"cube": {"grasp_width_mm": 10.0}}, "parts.cube: the name of a built-in part"),
    ({"all": {"grasp_width_mm": 10.0}}, "parts.all: a part's name is"),
    ({"Big Part": {"grasp_width_mm": 10.0}}, "parts.Big Part: a part's name is"),
    ({"pin": {"mesh": "pin.stl"}}, "parts.pin.grasp_width_mm: required"),
    ({"pin": "small"}, "parts.pin: expected a mapping"),
    (["pin"], "parts: expected a mapping of part names to parts"),
])
def test_bad_part_names_and_entries_are_refused(parts, message):
    with pytest.raises(ConfigError, match="^" + message.replace("(", r"\(")):
        config_from_mapping({"parts": parts})


def test_an_unknown_part_lists_the_known_ones_and_where_to_declare():
    with pytest.raises(ConfigError) as info:
        config_from_mapping({"controller": {"part": "bolt"}})
    assert str(info.value) == (
        "controller.part: unknown part 'bolt' (known parts: cube, nut, ledge, screw; declare "
        "a new one under parts: in the cell config, docs/quickstart.md#adding-a-part)")
    with pytest.raises(ConfigError, match=r"^scene.object.kind: unknown part 'sphere'"):
        config_from_mapping({"scene": {"object": {"kind": "sphere"}}})
    with pytest.raises(ConfigError, match=r"^unknown part 'bolt' \(known parts: cube, nut, "
                                          r"ledge, screw, pin;"):
        with_part(config_from_mapping({"parts": {"pin": {"grasp_width_mm": 6.0}}}), "bolt")
