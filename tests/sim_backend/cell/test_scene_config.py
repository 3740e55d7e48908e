"""The scene section and the simulated arm's options: defaults, loading, clear errors."""

from __future__ import annotations

import dataclasses

import pytest

from drivers.core.errors import ConfigError
from drivers.core.parts import PARTS
from drivers.core.typed_config import from_mapping
from sim_backend.cell.lighting import PRESETS, kelvin_rgb, resolve_light
from sim_backend.cell.scene_config import (
    LightingConfig,
    SceneConfig,
    SimArmConfig,
    load_parts,
    load_scene,
)

ISSUE_EXAMPLE = """
scene:
  object: {kind: cube, color: [1.0, 0.85, 0.1]}
  table: {color: [0.5, 0.5, 0.5], texture: none}
  lighting: {preset: good}
  occluder: {enabled: false, coverage: 0.0}
  camera: {noise_std: 2.0}
  clutter: {count: 0}
"""


def test_defaults_are_the_issue_example(tmp_path):
    path = tmp_path / "finepos.yaml"
    path.write_text(ISSUE_EXAMPLE)
    scene = SceneConfig()
    assert load_scene(path) == dataclasses.replace(
        scene, object=dataclasses.replace(scene.object, color=(1.0, 0.85, 0.1)))
    # unset, the cell paints the part in its own colour: the cube's is the example's
    assert scene.object.kind == "cube" and scene.object.color is None
    assert PARTS["cube"].color == (1.0, 0.85, 0.1)
    assert scene.table.texture == "none" and scene.lighting.preset == "good"
    assert scene.camera.noise_std == 2.0 and scene.clutter.count == 0


def test_load_scene_ignores_other_sections_and_missing_scene(tmp_path):
    path = tmp_path / "finepos.yaml"
    path.write_text("arm: {type: sim}\nperception: {whatever: 1}\n")
    assert load_scene(path) == SceneConfig()
    path.write_text("scene:\n  lighting: {preset: poor}\n  clutter: {count: 3}\n")
    scene = load_scene(path)
    assert scene.lighting.preset == "poor" and scene.clutter.count == 3


@pytest.mark.parametrize("data, message", [
    ({"object": {"size": 3}}, "scene.object.size: unknown key"),
    ({"object": {"color": [1, 0]}}, "scene.object.color: expected 3 values"),
    ({"object": {"color": [1, 0, 2]}}, "scene.object.color: must be <= 1.0"),
    ({"table": {"texture": "marble"}}, "scene.table.texture: must be one of none | wood"),
    ({"lighting": {"preset": "bright"}}, "scene.lighting.preset: must be one of good"),
    ({"lighting": {"ambient": -1}}, "scene.lighting.ambient: must be >= 0.0"),
    ({"lighting": {"shadows": "yes"}}, "scene.lighting.shadows: expected true or false"),
    ({"lighting": {"direction": [0, 0, -1]}}, "scene.lighting: direction: "),
    ({"occluder": {"coverage": 1.5}}, "scene.occluder.coverage: must be <= 0.9"),
    ({"camera": {"noise_std": "loud"}}, "scene.camera.noise_std: expected a number"),
    ({"clutter": {"count": 2.5}}, "scene.clutter.count: expected a whole number"),
    ({"clutter": {"count": 20}}, "scene.clutter.count: must be <= 8"),
    ({"lights": {}}, "scene.lights: unknown key"),
    ({"lighting": {"lamps": [{"direction": [1, 0, -1]}]}}, "scene.lighting.lamps[0]: "),
    ({"lighting": {"lamps": [{"diffuse": 3}]}}, "scene.lighting.lamps[0].diffuse: must be"),
    ({"lighting": {"lamps": [{}] * 5}}, "scene.lighting: lamps: at most 4"),
])
def test_bad_scene_values_fail_with_the_key_path(data, message):
    with pytest.raises(ConfigError) as err:
        from_mapping(SceneConfig, data, "scene")
    assert str(err.value).startswith(message), str(err.value)


def test_load_scene_names_the_file(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("scene:\n  camera: {noise_std: -3}\n")
    with pytest.raises(ConfigError, match=r"bad.yaml: scene.camera.noise_std: must be >= 0"):
        load_scene(path)


def test_load_parts_adds_the_files_declared_parts_with_meshes_from_its_folder(tmp_path):
    path = tmp_path / "cell" / "finepos.yaml"
    path.parent.mkdir()
    path.write_text("parts:\n  pin: {mesh: meshes/pin.stl, grasp_width_mm: 6}\n")
    catalogue = load_parts(path)
    assert list(catalogue) == [*PARTS, "pin"]
    assert catalogue["pin"].mesh_file == str(tmp_path / "cell" / "meshes" / "pin.stl")
    path.write_text("parts:\n  pin: {grasp_width_mm: 6, jaw_opening_mm: 41}\n")
    with pytest.raises(ConfigError, match=r"finepos.yaml: parts.pin.jaw_opening_mm: 41 mm is "
                                          r"over the gripper's 40 mm opening$"):
        load_parts(path)


def test_sim_arm_config():
    assert SimArmConfig().repeatability_mm == 0.02 and SimArmConfig().repeatability_deg == 0.02
    with pytest.raises(ConfigError, match=r"^arm.contact_stiffness_n_per_mm: must be > 0"):
        from_mapping(SimArmConfig, {"contact_stiffness_n_per_mm": 0}, "arm")
    with pytest.raises(ConfigError, match=r"^arm.speed: unknown key"):
        from_mapping(SimArmConfig, {"speed": 3}, "arm")


def test_explicit_light_values_override_the_preset():
    light = resolve_light(LightingConfig(preset="side", ambient=0.9, direction=(0, 0, 2)))
    assert light.ambient == 0.9 and light.direction == (0.0, 0.0, 1.0)
    assert light.diffuse == PRESETS["side"].diffuse
    assert not resolve_light(LightingConfig(shadows=False)).casts_shadows
    assert resolve_light(LightingConfig(preset="poor")).shadow_strength > 0.9


def test_further_lamps_resolve_to_lights_of_their_own():
    config = from_mapping(SceneConfig, {"lighting": {"preset": "poor", "lamps": [
        {"direction": [0, 2, 2], "diffuse": 0.4, "color": [1, 0.9, 0.8],
         "shadow_strength": 0.7}]}}, "scene")
    light = resolve_light(config.lighting)
    (lamp,) = light.lamps
    assert lamp.ambient == 0.0 and lamp.specular == 0.0 and lamp.diffuse == 0.4
    assert lamp.direction == pytest.approx((0.0, 2 ** -0.5, 2 ** -0.5))
    assert lamp.shadow_strength == 0.7 and light.ambient == PRESETS["poor"].ambient
    no_shadows = resolve_light(type(config.lighting)(lamps=config.lighting.lamps,
                                                     shadows=False))
    assert no_shadows.lamps[0].shadow_strength == 0.0


def test_colour_temperature_runs_from_warm_to_daylight():
    warm, day = kelvin_rgb(2700), kelvin_rgb(6500)
    assert warm[0] == 1.0 and warm[0] > warm[1] > warm[2] > 0.2
    assert min(day) > 0.95
    assert kelvin_rgb(4000)[2] > warm[2]
