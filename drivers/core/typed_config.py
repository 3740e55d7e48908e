"""Strict loading of YAML mappings into typed, frozen dataclasses.

Unknown keys, wrong types and out-of-range values fail at load with a ConfigError whose message
starts with the key's full path (``scene.lighting.preset: ...``). Range limits are field
metadata: ``min``, ``max``, ``exclusive_min``, ``length`` (for tuples/lists).
"""

from __future__ import annotations

import dataclasses
import math
import os
import stat
import sys
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar, Union

import yaml

from drivers.core.errors import ConfigError

T = TypeVar("T")


MAX_CONFIG_BYTES = 1 << 20  # a config file is a few KB; more is a wrong file
MAX_CONFIG_INT = (1 << 63) - 1  # a whole number beyond int64 is no count, port or size


def load_yaml_file(path: str | Path) -> dict[str, Any]:
    """Read a YAML file that must hold a mapping (an empty file is an empty mapping).

    Raises:
        ConfigError: one line naming the file and what is wrong: unreadable, not a regular
            file (a FIFO or device would block or never end), over MAX_CONFIG_BYTES, not UTF-8,
            not YAML, a number too long to read, or not a mapping.
    """
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
        with os.fdopen(fd, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                raise ConfigError(f"{path}: not a regular file")
            raw = f.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config file: {exc.strerror or exc}") from exc
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError(f"{path}: larger than {MAX_CONFIG_BYTES} bytes: not a config file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise ConfigError(f"{path}: not UTF-8 text (byte {raw[exc.start]:#04x} on line "
                          f"{line})") from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        detail = " ".join(str(exc).split())
        raise ConfigError(f"{path}: not valid YAML: {detail}") from exc
    except RecursionError as exc:
        raise ConfigError(f"{path}: not valid YAML: nested too deeply") from exc
    except (ValueError, OverflowError) as exc:  # e.g. a whole number of over 4300 digits
        raise ConfigError(f"{path}: a value out of range: {' '.join(str(exc).split())}") from exc
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: the top level must be a mapping, got {type(data).__name__}")
    return data


def from_mapping(cls: type[T], data: Any, path: str = "") -> T:
    """Build dataclass ``cls`` from ``data`` (a mapping), checking every key and value."""
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path or '<root>'}: expected a mapping, got {_describe(data)}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(str(k) for k in data if k not in fields)
    if unknown:
        where = f"{path}." if path else ""
        raise ConfigError(f"{where}{unknown[0]}: unknown key (allowed: {', '.join(fields)})")
    kwargs = {}
    for name, f in fields.items():
        if name not in data:
            continue
        key_path = f"{path}.{name}" if path else name
        value = _convert(hints[name], data[name], key_path)
        _check_range(f.metadata, value, key_path)
        kwargs[name] = value
    try:
        return cls(**kwargs)
    except ConfigError:
        raise
    except (TypeError, ValueError) as exc:
        msg = str(exc)
        raise ConfigError(msg if msg.startswith(path) and path else f"{path or '<root>'}: {msg}") \
            from exc


def to_mapping(obj: Any) -> Any:
    """Plain YAML/JSON-able form of a config dataclass (tuples become lists)."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_mapping(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (list, tuple)):
        return [to_mapping(v) for v in obj]
    if isinstance(obj, Mapping):
        return {k: to_mapping(v) for k, v in obj.items()}
    return obj


def _describe(value: Any) -> str:
    return f"{type(value).__name__} {value!r}" if not isinstance(value, dict) else "a mapping"


def _convert(tp: Any, value: Any, path: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        options = [a for a in args if a is not type(None)]
        errors = []
        for option in options:
            try:
                return _convert(option, value, path)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if len(errors) == 1 else
                          f"{path}: {_describe(value)} matches none of the allowed forms")
    if origin is Literal:
        if value in args and not isinstance(value, bool):
            return value
        allowed = " | ".join(str(a) for a in args)
        raise ConfigError(f"{path}: must be one of {allowed}, got {value!r}")
    if dataclasses.is_dataclass(tp):
        return from_mapping(tp, value, path)
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{path}: expected a list, got {_describe(value)}")
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise ConfigError(f"{path}: expected {len(args)} values, got {len(value)}")
            pairs = enumerate(zip(args, value, strict=True))
            items = [_convert(a, v, f"{path}[{i}]") for i, (a, v) in pairs]
        else:
            item_tp = args[0] if args else Any
            items = [_convert(item_tp, v, f"{path}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{path}: expected a mapping, got {_describe(value)}")
        kt, vt = args or (Any, Any)
        return {_convert(kt, k, path): _convert(vt, v, f"{path}.{k}") for k, v in value.items()}
    if tp is Any:
        return value
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise ConfigError(f"{path}: expected true or false, got {_describe(value)}")
    if tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            if abs(value) > MAX_CONFIG_INT:
                raise ConfigError(f"{path}: out of range: {_digits(value)}")
            return value
        raise ConfigError(f"{path}: expected a whole number, got {_describe(value)}")
    if tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if isinstance(value, int) and abs(value) > sys.float_info.max:
                raise ConfigError(f"{path}: out of range: {_digits(value)}")
            if not math.isfinite(value):
                raise ConfigError(f"{path}: expected a finite number, got {value!r}")
            return float(value)
        raise ConfigError(f"{path}: expected a number, got {_describe(value)}")
    if tp is str:
        if isinstance(value, str):
            return value
        raise ConfigError(f"{path}: expected a string, got {_describe(value)}")
    raise TypeError(f"{path}: unsupported config type {tp!r}")


def _digits(value: int) -> str:
    """A whole number for an error message: in full if short, else its first digits."""
    text = str(abs(value)) if abs(value).bit_length() < 4000 else "a very large number"
    sign = "-" if value < 0 else ""
    return f"{sign}{text}" if len(text) <= 24 else f"{sign}{text[:6]}... ({len(text)} digits)"


def _check_range(meta: Any, value: Any, path: str) -> None:
    if value is None or not meta:
        return
    if "length" in meta and len(value) != meta["length"]:
        raise ConfigError(f"{path}: expected {meta['length']} values, got {len(value)}")
    values = value if isinstance(value, (list, tuple)) else [value]
    for v in values:
        if not isinstance(v, (int, float)):
            continue
        lo, hi = meta.get("min"), meta.get("max")
        if lo is not None and (v < lo or (meta.get("exclusive_min") and v == lo)):
            op = ">" if meta.get("exclusive_min") else ">="
            raise ConfigError(f"{path}: must be {op} {lo}, got {v!r}")
        if hi is not None and v > hi:
            raise ConfigError(f"{path}: must be <= {hi}, got {v!r}")
