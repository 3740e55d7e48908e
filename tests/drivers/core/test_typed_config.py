"""Strict config loading: unknown keys, wrong types and ranges fail with the key's path."""

from dataclasses import dataclass, field
from typing import Literal

import pytest

from drivers.core.errors import ConfigError
from drivers.core.typed_config import from_mapping, load_yaml_file, to_mapping
from drivers.safety import SafetyLimits


@dataclass(frozen=True)
class Inner:
    kind: Literal["cube", "nut"] = "cube"
    color: tuple[float, float, float] = field(default=(1.0, 0.85, 0.1),
                                              metadata={"min": 0.0, "max": 1.0})


@dataclass(frozen=True)
class Outer:
    inner: Inner = Inner()
    count: int = field(default=0, metadata={"min": 0})
    name: str | None = None
    enabled: bool = False


@pytest.mark.parametrize("data,message", [
    ({"inner": {"kind": "sphere"}}, "scene.inner.kind: must be one of cube | nut"),
    ({"inner": {"colour": [1, 1, 1]}}, "scene.inner.colour: unknown key"),
    ({"inner": {"color": [1, 1]}}, "scene.inner.color: expected 3 values"),
    ({"inner": {"color": [1, 2, 1]}}, "scene.inner.color: must be <= 1.0"),
    ({"inner": {"color": "red"}}, "scene.inner.color: expected a list"),
    ({"count": -1}, "scene.count: must be >= 0"),
    ({"count": 1.5}, "scene.count: expected a whole number"),
    ({"count": True}, "scene.count: expected a whole number"),
    ({"enabled": "yes"}, "scene.enabled: expected true or false"),
    ({"inner": [1]}, "scene.inner: expected a mapping"),
])
def test_bad_values_name_their_path(data, message):
    with pytest.raises(ConfigError) as info:
        from_mapping(Outer, data, "scene")
    assert str(info.value).startswith(message)


def test_good_values_load_and_round_trip():
    cfg = from_mapping(Outer, {"inner": {"kind": "nut", "color": [0, 0.5, 1]}, "count": 3,
                               "name": "x"}, "scene")
    assert cfg.inner.color == (0.0, 0.5, 1.0) and cfg.count == 3
    assert from_mapping(Outer, to_mapping(cfg), "scene") == cfg


def test_cross_field_errors_carry_the_section_path():
    with pytest.raises(ConfigError, match="safety"):
        from_mapping(SafetyLimits, {"workspace_min_mm": [0, 0, 0],
                                    "workspace_max_mm": [0, 1, 1]}, "safety")


def test_yaml_file_errors(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("scene: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_yaml_file(bad)
    lst = tmp_path / "list.yaml"
    lst.write_text("- 1\n")
    with pytest.raises(ConfigError, match="top level must be a mapping"):
        load_yaml_file(lst)
    with pytest.raises(ConfigError, match="cannot read"):
        load_yaml_file(tmp_path / "missing.yaml")


# -- hardening (issue 15): a config file that cannot be loaded gives one ConfigError line --------
def _load_error(path) -> str:
    import pytest as _pytest

    from drivers.core.errors import ConfigError
    from drivers.core.typed_config import load_yaml_file

    with _pytest.raises(ConfigError) as refused:
        load_yaml_file(path)
    message = str(refused.value)
    assert message.startswith(str(path)) and "\n" not in message, message
    return message


def test_non_utf8_config_names_the_byte_and_line(tmp_path):
    path = tmp_path / "finepos.yaml"
    path.write_bytes(b"service:\n  idle_poll_s: 2.0\n# caf\xe9\n")
    assert "not UTF-8 text (byte 0xe9 on line 3)" in _load_error(path)


def test_fifo_device_and_huge_configs_are_refused_at_once(tmp_path):
    import os

    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    assert "not a regular file" in _load_error(fifo)
    zero = tmp_path / "zero.yaml"
    zero.symlink_to("/dev/zero")
    assert "not a regular file" in _load_error(zero)
    big = tmp_path / "big.yaml"
    big.write_bytes(b"#" * ((1 << 20) + 1))
    assert "larger than" in _load_error(big)


def test_bad_yaml_is_one_line(tmp_path):
    path = tmp_path / "finepos.yaml"
    path.write_text("service:\n  idle_poll_s: [1,\n  x: {\n")
    assert "not valid YAML" in _load_error(path)


def test_sizes_have_upper_limits_that_fit_the_machine():
    import pytest as _pytest

    from controller.config import config_from_mapping
    from controller.recipe import recipe_from_mapping
    from drivers.core.errors import ConfigError

    for data, key in (({"perception": {"nn2_hidden": [100000000]}}, "perception.nn2_hidden"),
                      ({"perception": {"nn2_hidden": [8] * 9}}, "nn2_hidden"),
                      ({"perception": {"gabor": {"roi_px": 100000000}}},
                       "perception.gabor.roi_px")):
        with _pytest.raises(ConfigError, match=key.replace(".", r"\.")):
            recipe_from_mapping(data)
    for data, key in (({"service": {"stop_timeout_s": 1e308}}, "service.stop_timeout_s"),
                      ({"service": {"abort_wait_s": float("inf")}}, "service.abort_wait_s")):
        with _pytest.raises(ConfigError, match=key.replace(".", r"\.")):
            config_from_mapping(data)


@pytest.mark.parametrize("text,message", [
    ("inner:\n  color: [" + "1" + "0" * 400 + ", 0, 0]\n", "scene.inner.color[0]: out of range"),
    ("count: " + "9" * 30 + "\n", "scene.count: out of range: 999999... (30 digits)"),
    ("count: -" + "9" * 5000 + "\n", "big.yaml: a value out of range"),
])
def test_numbers_out_of_range_are_one_config_error(tmp_path, text, message):
    path = tmp_path / "big.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message.replace("[", r"\[").replace("(", r"\(")
                       .replace(")", r"\)").replace(".", r"\.")) as error:
        from_mapping(Outer, load_yaml_file(path), "scene")
    assert "\n" not in str(error.value)
