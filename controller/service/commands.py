"""The control API's commands and their arguments: names, types, ranges, defaults (pure data).

``COMMANDS`` maps each command to its arguments; ``validate_args`` checks a request's ``args``
object against it (unknown names, wrong JSON types, out-of-range values, non-finite numbers are
refused with a ValueError naming the argument) and fills in the defaults. Job commands take
``wait``: false answers as soon as the job started, true when it ended.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from controller.calibration.rezero import REZERO_FRAMES, REZERO_SYSTEMS
from controller.fine_positioner import DATASETS
from controller.systems.registry import SYSTEMS
from drivers.core.parts import PARTS

REQUIRED = object()


@dataclass(frozen=True)
class Arg:
    """One argument: JSON type (bool, int, float, str, or list for a fixed-length list of
    numbers), default (REQUIRED: must be given; None: optional), inclusive range, choices,
    and for lists the range of each element."""

    kind: type
    default: Any = None
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    max_chars: int = 256
    items: tuple[tuple[float, float], ...] = ()
    help: str = ""


WAIT = Arg(bool, False, help="answer when the job ended (default: when it started)")
PART = Arg(str, None, max_chars=32,
           help=f"the part: {' | '.join(PARTS)} or one declared under parts: in the config "
                "(default: the one taught, else the cell's; teach: the cell's); on the "
                "simulated cell it is put on the table")

COMMANDS: dict[str, dict[str, Arg]] = {
    "status": {},
    "teach": {
        "part": PART,
        "auto": Arg(bool, False, help="simulated cell: place the gripper at the true pose"),
        "grasp_depth_mm": Arg(float, None, 0.0, 500.0, help="descent from the pose to grip"),
        "object_width_mm": Arg(float, None, 0.0, 300.0, help="finger width holding the part"),
        "wait": WAIT,
    },
    "acquire": {
        "part": PART,
        "set": Arg(str, REQUIRED, choices=DATASETS, help="which dataset"),
        "seed": Arg(int, 0, 0, 2**31 - 1, help="seed of the random test set"),
        "wait": WAIT,
    },
    "train": {
        "part": PART,
        "system": Arg(str, "gabor", choices=tuple(SYSTEMS), help="vision system"),
        "wait": WAIT,
    },
    "rezero": {
        "part": PART,
        "frames": Arg(int, REZERO_FRAMES, 1, 100, help="frames at the taught pose"),
        "system": Arg(str, "gabor", choices=REZERO_SYSTEMS, help="the model to re-zero"),
        "heading_step": Arg(float, None, 0.5, 180.0,
                            help="also the zero by heading, the arm turning the part in "
                                 "steps of at most this (deg; gabor; one symmetry period "
                                 "centred on the taught heading)"),
        "wait": WAIT,
    },
    "position": {
        "part": PART,
        "max_loops": Arg(float, None, 0.5, 1000.0, help="loop budget (default from config)"),
        "offset": Arg(list, None, items=((-50.0, 50.0), (-50.0, 50.0), (-180.0, 180.0)),
                      help="simulated cell: first displace the arm from the taught pose by "
                           "[dx_mm, dy_mm, dphi_deg]"),
        "grasp": Arg(bool, False, help="then grasp (where the loop ended converged or at its "
                                       "budget), the converged step made by the grasp's "
                                       "first descent move"),
        "wait": WAIT,
    },
    "grasp": {"part": PART, "wait": WAIT},
    "abort": {},
    "reload": {
        "part": Arg(str, None, max_chars=32,
                    help="whose model to load (default: every taught part's)"),
        "system": Arg(str, None, choices=tuple(SYSTEMS),
                      help="model to load (default: the one in use, else gabor)"),
    },
    "reset": {},
    "stream": {},
    "auth": {"token": Arg(str, REQUIRED, max_chars=1024, help="the TCP listener's token")},
}

JOB_COMMANDS = ("teach", "acquire", "train", "rezero", "position", "grasp")


def _number(name: str, value: Any, kind: type, low: float | None, high: float | None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            (kind is int and not isinstance(value, int)):
        raise ValueError(f"{name}: expected {'an integer' if kind is int else 'a number'}, "
                         f"got {type(value).__name__}")
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{name}: expected a finite number")
    # Compared before any conversion: Python compares a huge int with a float exactly, while
    # float() of it would overflow.
    if (low is not None and value < low) or (high is not None and value > high):
        raise ValueError(f"{name}: must be within [{low:g}, {high:g}], got {value!r:.40}")
    return float(value) if kind is float else value


def _check(name: str, spec: Arg, value: Any) -> Any:
    if spec.kind is bool:
        if not isinstance(value, bool):
            raise ValueError(f"{name}: expected true or false, got {type(value).__name__}")
        return value
    if spec.kind in (int, float):
        return _number(name, value, spec.kind, spec.low, spec.high)
    if spec.kind is str:
        if not isinstance(value, str):
            raise ValueError(f"{name}: expected a string, got {type(value).__name__}")
        if len(value) > spec.max_chars:
            raise ValueError(f"{name}: longer than {spec.max_chars} characters")
        if spec.choices and value not in spec.choices:
            raise ValueError(f"{name}: one of {', '.join(spec.choices)}, got {value[:40]!r}")
        return value
    if not isinstance(value, list) or len(value) != len(spec.items):
        raise ValueError(f"{name}: expected a list of {len(spec.items)} numbers")
    return [_number(f"{name}[{i}]", v, float, lo, hi)
            for i, (v, (lo, hi)) in enumerate(zip(value, spec.items, strict=True))]


def validate_args(cmd: str, args: dict[str, Any]) -> dict[str, Any]:
    """``args`` checked against COMMANDS[cmd], with defaults filled in (raises ValueError)."""
    specs = COMMANDS[cmd]
    unknown = sorted(str(k)[:40] for k in args if k not in specs)
    if unknown:
        allowed = ", ".join(specs) or "none"
        raise ValueError(f"unknown argument {unknown[0]!r} (allowed: {allowed})")
    checked = {}
    for name, spec in specs.items():
        if name not in args or args[name] is None:
            if spec.default is REQUIRED:
                raise ValueError(f"{name}: required")
            checked[name] = spec.default
        else:
            checked[name] = _check(name, spec, args[name])
    return checked
