"""Replace a device backend in a loaded config (command-line options, hardware-in-the-loop)."""

from __future__ import annotations

import dataclasses

from controller.devices import parse_device_section
from drivers.core.typed_config import to_mapping


def with_device(config, kind: str, backend_type: str, **options):
    """``config`` with device ``kind`` (arm, camera, wrench) on ``backend_type``.

    ``options`` override that backend's options; the options already configured are kept when
    the backend stays the same. The result is validated as strictly as a config file
    (ConfigError naming the key).
    """
    section = getattr(config, kind)
    data = to_mapping(section.options) if section.type == backend_type else {}
    data.update(options)
    replaced = parse_device_section(kind, {"type": backend_type, **data})
    return dataclasses.replace(config, **{kind: replaced})
