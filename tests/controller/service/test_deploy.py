"""The deployment files: the systemd unit passes ``systemd-analyze verify`` with no warning, the
example config loads and shows every section, and ``finepos ctl`` offers every command."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from controller.cli import build_parser
from controller.config import SECTIONS, config_from_mapping, load_config
from controller.service.bench import summarise_ms
from controller.service.commands import COMMANDS

DEPLOY = Path(__file__).resolve().parents[3] / "deploy"
INSTALLED_FINEPOS = "/opt/finepos/.venv/bin/finepos"


@pytest.mark.skipif(shutil.which("systemd-analyze") is None,
                    reason="systemd-analyze is missing (Debian: apt-get install -y systemd)")
def test_unit_passes_systemd_analyze_verify(tmp_path):
    unit = (DEPLOY / "finepos.service").read_text()
    assert INSTALLED_FINEPOS in unit
    # verify insists that ExecStart exists: point it at this checkout's entry point
    local = tmp_path / "finepos.service"
    local.write_text(unit.replace(INSTALLED_FINEPOS, str(Path(sys.executable).parent /
                                                         "finepos")))
    result = subprocess.run(["systemd-analyze", "verify", "--man=no", str(local)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert [line for line in result.stderr.splitlines() if "finepos.service" in line] == []


def test_unit_has_the_required_settings():
    settings = dict(re.findall(r"^(\w+)=(.*)$", (DEPLOY / "finepos.service").read_text(), re.M))
    for key, value in {"Type": "notify", "Restart": "on-failure", "User": "finepos",
                       "SupplementaryGroups": "dialout", "NoNewPrivileges": "yes",
                       "ProtectSystem": "strict", "ProtectHome": "yes", "PrivateTmp": "yes",
                       "DevicePolicy": "closed", "StateDirectory": "finepos",
                       "LogsDirectory": "finepos", "RuntimeDirectory": "finepos"}.items():
        assert settings.get(key) == value, key
    assert settings["WatchdogSec"] and settings["ExecReload"].endswith("-HUP $MAINPID")


def test_example_config_loads_and_shows_every_section():
    config = load_config(DEPLOY / "finepos.yaml")
    assert config.service.socket_path == "/run/finepos/finepos.sock"
    assert config.controller.paths.state_dir == "/var/lib/finepos"
    text = (DEPLOY / "finepos.yaml").read_text()
    for section in SECTIONS:
        assert re.search(rf"^{section}:", text, re.M), section


def commented_blocks(text: str) -> dict[str, str]:
    """The commented-out alternative of each section (``#  key: value`` lines, and the
    ``  # tcp:`` block of service), uncommented."""
    blocks: dict[str, list[str]] = {}
    section = ""
    for line in text.splitlines():
        if re.match(r"^\w+:", line):
            section = line.split(":")[0]
        elif line.startswith("#  "):
            blocks.setdefault(section, []).append(line[1:])
        elif re.match(r"^  # (tcp:|  )", line):
            blocks.setdefault(section, []).append("  " + line[4:])
    return {name: f"{name}:\n" + "\n".join(lines) for name, lines in blocks.items()}


def test_example_config_hardware_alternatives_load_when_uncommented():
    blocks = commented_blocks((DEPLOY / "finepos.yaml").read_text())
    assert set(blocks) == {"arm", "camera", "wrench", "service"}
    config = config_from_mapping({name: yaml.safe_load(block)[name]
                                  for name, block in blocks.items()})
    assert (config.arm.type, config.camera.type, config.wrench.type) == ("val", "opencv", "ati")
    assert config.arm.options.port == "/dev/ttyS0" and config.service.tcp.port == 7878


def test_ctl_offers_every_command_with_its_arguments():
    parser = build_parser()
    args = parser.parse_args(["ctl", "--socket", "/tmp/x.sock", "position", "--offset",
                              "1,2,3", "--max-loops", "2", "--no-wait"])
    assert (args.ctl_command, args.offset, args.max_loops, args.no_wait) == \
        ("position", "1,2,3", 2.0, True)
    ctl = next(a for a in parser._actions if a.dest == "command").choices["ctl"]
    leaves = next(a for a in ctl._actions if a.dest == "ctl_command").choices
    assert set(leaves) == set(COMMANDS) - {"auth"}


def test_bench_summary():
    summary = summarise_ms([10.0, 12.0, 11.0, 30.0, 10.5])
    assert summary["count"] == 5 and summary["median_ms"] == 11.0
    assert summary["p95_ms"] == 30.0 and summary["jitter_ms"] == 19.0
    assert summarise_ms([]) == {"count": 0}
