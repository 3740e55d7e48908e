"""The root config: sections, device backends by type, errors naming the key path."""

import pytest

from controller.config import config_from_mapping, load_config, with_part
from controller.devices import with_device
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
    ({"controller": {"loop": {"r_fine_mm": "four"}}},
     "controller.loop.r_fine_mm: expected a number"),
    ({"controller": {"grasp": {"guards": [{"quantity": "fz_n", "op": "=", "limit": 1,
                                           "action": "stop"}]}}},
     "controller.grasp.guards[0].op: must be one of"),
    ({"safety": {"on_violation": "ignore"}}, "safety.on_violation: must be one of reject | clip"),
    ({"perception": {"gabor": {"lambda_px": 0}}}, "perception.gabor.lambda_px: must be > 0"),
])
def test_bad_configs_name_the_key(data, message):
    with pytest.raises(ConfigError) as info:
        config_from_mapping(data)
    assert message in str(info.value)


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
