"""Loading the VAL driver config strictly from YAML-like mappings."""

from __future__ import annotations

import pytest
import yaml

from drivers.core.errors import ConfigError
from drivers.core.typed_config import from_mapping
from drivers.val import ValCommands, ValConfig


def test_defaults_are_the_puma_260_line():
    cfg = from_mapping(ValConfig, {"port": "/dev/ttyS0"}, "arm")
    assert (cfg.baudrate, cfg.bytesize, cfg.parity, cfg.stopbits) == (9600, 8, "N", 1)
    assert cfg.line_ending == "\r" and cfg.echo
    assert cfg.commands.move.format(x_mm=1, y_mm=2, z_mm=3, o_deg=4, a_deg=5, t_deg=6) == \
        "do move trans(1.00,2.00,3.00,4.000,5.000,6.000)"
    assert cfg.commands.speed.format(percent=50.0) == "speed 50"


def test_yaml_overrides_unconfirmed_strings():
    data = yaml.safe_load("""
        port: socket://127.0.0.1:5000
        line_ending: "\\n\\r"
        boot_answers: {"Load VAL": n}
        rejection_errors: [position out of range, joint limit]
        commands: {gripper_open: do open, halt: panic}
    """)
    cfg = from_mapping(ValConfig, data, "arm")
    assert cfg.line_ending == "\n\r"
    assert cfg.boot_answers == {"Load VAL": "n"}
    assert cfg.commands == ValCommands(gripper_open="do open", halt="panic")


@pytest.mark.parametrize("data, path", [
    ({"port": "/dev/ttyS0", "baud": 9600}, "arm.baud"),
    ({"port": "/dev/ttyS0", "baudrate": "fast"}, "arm.baudrate"),
    ({"port": "/dev/ttyS0", "line_ending": ";"}, "arm.line_ending"),
    ({"port": "/dev/ttyS0", "exchange_timeout_s": 0}, "arm.exchange_timeout_s"),
    ({"port": "/dev/ttyS0", "commands": {"moove": "x"}}, "arm.commands.moove"),
    ({"port": "/dev/ttyS0", "commands": {"move": "do move {where}"}}, "arm.commands"),
    ({"port": "/dev/ttyS0", "commands": {"halt": "a\rb"}}, "arm.commands"),
    ({"port": "/dev/ttyS0", "gripper_closed_width_mm": 50.0}, "arm"),
    ({}, "arm"),
])
def test_bad_values_fail_with_the_key_path(data, path):
    with pytest.raises(ConfigError, match=rf"^{path}"):
        from_mapping(ValConfig, data, "arm")
