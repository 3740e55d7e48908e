"""Device backends from the command line: --arm/--port, --camera, --wrench/--wrench-port."""

from __future__ import annotations

import argparse

import pytest

from controller.commands.device_options import add_device_options, apply_device_options
from controller.config import config_from_mapping
from controller.devices import with_device
from drivers.core.errors import ConfigError


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_device_options(parser)
    return parser.parse_args(argv)


def test_no_options_keep_the_config():
    config = config_from_mapping({})
    assert apply_device_options(config, parse()) == config


def test_serial_arm_wrench_and_stream_camera():
    config = apply_device_options(config_from_mapping({}), parse(
        "--arm", "val", "--port", "/dev/pts/7", "--wrench", "ati", "--wrench-port",
        "socket://127.0.0.1:9", "--camera", "http://127.0.0.1:8080/stream.mjpg"))
    assert (config.arm.type, config.arm.options.port) == ("val", "/dev/pts/7")
    assert (config.wrench.type, config.wrench.options.port) == ("ati", "socket://127.0.0.1:9")
    assert config.camera.type == "opencv"
    assert config.camera.options.source == "http://127.0.0.1:8080/stream.mjpg"


def test_a_port_keeps_the_other_configured_options():
    config = config_from_mapping({"arm": {"type": "val", "port": "/dev/ttyS0", "baudrate": 19200,
                                          "commands": {"halt": "panic"}}})
    moved = apply_device_options(config, parse("--port", "/dev/pts/3"))
    assert moved.arm.options.port == "/dev/pts/3"
    assert moved.arm.options.baudrate == 19200
    assert moved.arm.options.commands.halt == "panic"


def test_camera_index_and_back_to_sim():
    config = apply_device_options(config_from_mapping({}), parse("--camera", "0"))
    assert (config.camera.type, config.camera.options.source) == ("opencv", 0)
    assert apply_device_options(config, parse("--camera", "sim")).camera.type == "sim"


def test_bad_combinations_fail_like_a_config_file():
    with pytest.raises(ConfigError, match="arm: .*port"):
        apply_device_options(config_from_mapping({}), parse("--arm", "val"))
    with pytest.raises(ConfigError, match="arm.port: unknown key"):
        apply_device_options(config_from_mapping({}), parse("--port", "/dev/pts/1"))
    with pytest.raises(ConfigError, match="wrench.baud"):
        with_device(config_from_mapping({}), "wrench", "ati", port="/dev/pts/1", baud=-1)
