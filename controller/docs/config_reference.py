"""Write the configuration reference (docs/configuration.md) from the typed config.

Example: finepos docs config --out docs/configuration.md

Every key with its full dotted path, type, unit, range, default and description, in four
tiers: the cell config's operator keys (``OPERATOR_KEYS``), its advanced keys (the rest of the
cell config: driver protocol, service limits, acquisition grids), the recipe
(``controller.recipe``: ``perception`` and the loop's tuned keys, kept in the model file) and
the simulator (``scene``, ``timing`` and the simulated devices' options). A key's
description is its field's ``metadata["doc"]`` where given, else its entry in the class
docstring, where keys are described as ``name: text`` (several
names sharing a text as ``a / b:`` or ``a, b:``), entries separated by ``;`` or a sentence
end. The unit comes from the name's suffix (``_mm``, ``_deg``, ``_s``...). The device sections
(``arm``, ``camera``, ``wrench``) list each backend's options under its ``type``.

``render()`` returns the page; ``tests/controller/docs/test_config_reference.py`` fails when the
committed page differs from it. Without ``--out`` the page goes to stdout; ``--check`` exits 1
when the file differs from the code instead of writing it.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
import types
import typing
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Union

from controller.config import FineposConfig
from controller.devices import REGISTRIES
from controller.loop.positioning import LoopConfig
from controller.recipe import RECIPE_LOOP_KEYS, PerceptionConfig
from drivers.core.files import atomic_write_text
from drivers.core.parts import PartDeclaration
from sim_backend.cell.scene_config import SceneConfig

COMMAND = "finepos docs config --out docs/configuration.md"

# Name suffix -> unit, longest first where one ends another.
UNITS = (
    ("_n_per_mm", "N/mm"), ("_deg_s2", "deg/s^2"), ("_deg_s", "deg/s"), ("_mm_s", "mm/s"),
    ("_mm", "mm"), ("_deg", "deg"), ("_ms", "ms"), ("_s", "s"), ("_hz", "Hz"), ("_px", "px"),
    ("_n", "N"), ("_e", "electrons"), ("_baud", "baud"), ("_bytes", "bytes"),
)

# The keys an operator sets on a cell; the other keys of the cell config keep their defaults
# on most cells (docs/configuration.md lists them as advanced).
OPERATOR_KEYS = (
    "arm.type", "arm.port", "arm.baudrate", "arm.line_ending", "arm.gripper_open_width_mm",
    "arm.gripper_closed_width_mm", "arm.programs", "arm.program_input",
    "camera.type", "camera.source",
    "wrench.type", "wrench.port", "wrench.baud", "wrench.counts_per_force",
    "wrench.counts_per_torque", "wrench.monitor_output",
    "safety.workspace_min_mm", "safety.workspace_max_mm", "safety.max_step_mm",
    "safety.max_step_deg", "safety.on_violation",
    "controller.part", "controller.paths.state_dir", "controller.paths.log_dir",
    "controller.loop.converge_mm", "controller.loop.converge_deg", "controller.loop.max_loops",
    "controller.loop.save_images",
    "controller.grasp.free_descent_mm", "controller.grasp.step_mm", "controller.grasp.check",
    "controller.grasp.lift_mm", "controller.grasp.min_held_weight_n",
    "controller.grasp.max_closing_force_n", "controller.grasp.guards",
    "controller.grasp.guards[].quantity", "controller.grasp.guards[].op",
    "controller.grasp.guards[].limit", "controller.grasp.guards[].action",
    "controller.teach.socket_path", "controller.teach.record_button",
    "controller.teach.abort_button", "controller.teach.jog.max_speed_mm_s",
    "controller.teach.jog.max_speed_deg_s",
    "service.socket_path", "service.socket_group", "service.allowed_users",
    "service.allowed_groups", "service.tcp", "service.tcp.port", "service.tcp.token_file",
    "service.tcp.host", "service.record_dir", "service.live", "service.live.port",
    "service.live.address", "service.metrics_port",
    "service.metrics_address", "service.self_check_at_start",
    "parts.<name>.grasp_width_mm",
)
CELL_SECTIONS = ("arm", "camera", "wrench", "safety", "controller", "service", "parts")
SIMULATOR_SECTIONS = ("scene", "timing")
TIERS = ("operator", "advanced", "recipe", "simulator")

# Where each root section is documented further, and what it is for.
SECTION_NOTES = {
    "arm": "The arm: `type` picks the backend, the other keys are that backend's options.",
    "camera": "The hand camera: `type` picks the backend, the other keys are its options.",
    "wrench": "The wrist force-torque sensor: `type` picks the backend, the other keys are its "
              "options.",
    "scene": "The simulated cell only: read where a simulated device or an emulator is built "
             "([simulator.md](simulator.md)).",
    "safety": "Limits every motion command must respect, applied in one place.",
    "controller": "The part, the positioning loop, the grasp, acquisition, teach-in and paths.",
    "service": "`finepos serve` ([service.md](service.md)).",
    "parts": "Parts the cell knows beside the built-in cube, nut, ledge and screw, each under "
             "its name (`parts: {bracket: {mesh: parts/bracket.obj, grasp_width_mm: 12}}`); "
             "`--part NAME` then takes it ([quickstart.md](quickstart.md#adding-a-part)).",
    "timing": "How long every action of the cell takes: the simulated cell and the emulators "
              "take it, `finepos fit-timing` fits `timing.arm` on a real arm "
              "([simulator.md](simulator.md#timing)).",
}


@dataclass(frozen=True)
class Key:
    """One documented key: its dotted path and what the page says of it."""

    path: str
    type: str
    unit: str
    range: str
    default: str
    doc: str
    backend: str = ""  # a device section's backend (``type``) the key belongs to


def field_docs(cls: type) -> dict[str, str]:
    """Each field's description from ``metadata["doc"]``, else the docstring entries of the
    class or, for a field it inherits, of the dataclass it inherits it from."""
    names = [f.name for f in dataclasses.fields(cls)]
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if dataclasses.is_dataclass(klass):
            docs.update(_docstring_entries(klass.__doc__ or "", names))
    for f in dataclasses.fields(cls):
        if "doc" in f.metadata:
            docs[f.name] = str(f.metadata["doc"])
    return docs


def _docstring_entries(doc: str, names: list[str]) -> dict[str, str]:
    """``{name: text}`` for every ``name: text`` entry of ``doc`` naming a field."""
    text = " ".join(doc.split())
    word = "|".join(sorted((re.escape(n) for n in names), key=len, reverse=True))
    if not word:
        return {}
    group = rf"(?:``)?(?:{word})(?:``)?(?:\s*(?:/|,)\s*(?:``)?(?:{word})(?:``)?)*"
    pattern = re.compile(rf"(?:^|(?<=[;.]\s)|(?<=:\s)|(?<=\sand\s))({group}):\s")
    matches = list(pattern.finditer(text))
    entries: dict[str, str] = {}
    for i, match in enumerate(matches):
        end = matches[i + 1].start() if i + 1 < len(matches) else len(text)
        body = text[match.end():end].strip().rstrip(";").strip()
        body = body[:-4].rstrip(" ,;") if body.endswith(" and") else body
        for name in re.split(r"\s*(?:/|,)\s*", match.group(1).replace("``", "")):
            entries.setdefault(name, _markdown(body))
    return entries


def _markdown(text: str) -> str:
    """Docstring text as Markdown table text: ``code`` -> `code`, no pipes breaking the cell."""
    text = text.replace("``", "`").replace("|", "\\|")
    return text[:1].upper() + text[1:] if text else text


def unit_of(name: str) -> str:
    """The unit a key's name carries (``step_mm`` -> mm), or ""."""
    for suffix, unit in UNITS:
        if name.endswith(suffix):
            return unit
    return ""


def type_name(tp: Any) -> str:
    """A config type as the page names it."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (Union, types.UnionType):
        options = [type_name(a) for a in args if a is not type(None)]
        text = " or ".join(options)
        return f"{text} or null" if type(None) in args else text
    if origin is Literal:
        return " \\| ".join(f"`{default_text(a)}`" for a in args)
    if origin in (tuple, list):
        if origin is tuple and args and args[-1] is not Ellipsis:
            inner = {type_name(a) for a in args}
            return f"list of {len(args)} {inner.pop()}s" if len(inner) == 1 else \
                "list (" + ", ".join(type_name(a) for a in args) + ")"
        if args and typing.get_origin(args[0]) is Literal:
            return f"list of {type_name(args[0])}"
        return f"list of {type_name(args[0])}s" if args else "list"
    if origin is dict:
        return f"mapping {type_name(args[0])} -> {type_name(args[1])}" if args else "mapping"
    if dataclasses.is_dataclass(tp):
        return "mapping"
    return {bool: "boolean", int: "integer", float: "number", str: "string"}.get(tp, str(tp))


def range_of(meta: Any) -> str:
    """The range a field's metadata sets (``min``, ``max``, ``exclusive_min``, ``length``)."""
    lo, hi = meta.get("min"), meta.get("max")
    low = None if lo is None else (f"> {lo:g}" if meta.get("exclusive_min") else f">= {lo:g}")
    if low is not None and hi is not None:
        text = f"{lo:g} .. {hi:g}" if not meta.get("exclusive_min") else f"{low}, <= {hi:g}"
    else:
        text = low if low is not None else (f"<= {hi:g}" if hi is not None else "")
    return text


def default_text(value: Any) -> str:
    """A default as YAML would write it."""
    if value is dataclasses.MISSING:
        return "required"
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(default_text(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {default_text(v)}" for k, v in value.items()) + "}"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, str):
        return repr(value)[1:-1] if value else '""'
    if dataclasses.is_dataclass(value):
        return "(below)"
    return str(value)


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


def keys(cls: type, prefix: str) -> Iterator[Key]:
    """Every key of dataclass ``cls`` under ``prefix``, nested sections recursed into."""
    hints = typing.get_type_hints(cls)
    docs = field_docs(cls)
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        path = f"{prefix}.{f.name}"
        tp = hints[f.name]
        nested = _nested_dataclass(tp)
        doc = docs.get(f.name, "")
        if nested is not None:
            if not doc:
                doc = _markdown(_summary(nested))
            if typing.get_origin(tp) in (tuple, list):
                yield Key(path, f"list of mappings ({nested.__name__})", "", "",
                          default_text(_default(f)), doc)
            elif _optional(tp):
                yield Key(path, "mapping or null", "", "", default_text(_default(f)), doc)
            yield from keys(nested, path + ("[]" if typing.get_origin(tp) in (tuple, list)
                                            else ""))
            continue
        meta = dict(f.metadata)
        length = meta.get("length")
        type_text = type_name(tp)
        if length is not None and "list" not in type_text:
            type_text += f" ({length} values)"
        yield Key(path, type_text, unit_of(f.name), range_of(meta), default_text(_default(f)),
                  doc)


def _nested_dataclass(tp: Any) -> type | None:
    """The dataclass a field holds (itself, optional, or a list of them), or None."""
    if dataclasses.is_dataclass(tp):
        return tp
    for arg in typing.get_args(tp):
        if dataclasses.is_dataclass(arg):
            return arg
    return None


def _optional(tp: Any) -> bool:
    return typing.get_origin(tp) in (Union, types.UnionType) and type(None) in typing.get_args(tp)


def _summary(cls: type) -> str:
    """A class docstring's first paragraph, on one line."""
    return " ".join((cls.__doc__ or "").strip().split("\n\n")[0].split())


def section_keys(section: str) -> Iterator[Key]:
    """The keys of one root section; a device section's backends each under their ``type``."""
    if section in REGISTRIES:
        registry = REGISTRIES[section]
        choices = " \\| ".join(f"`{name}`" for name in registry)
        yield Key(f"{section}.type", choices, "", "", "sim",
                  "The backend; the other keys are that backend's options.")
        for name, backend in registry.items():
            options = backend.options_type
            if not dataclasses.fields(options):
                continue
            for key in keys(options, section):
                yield dataclasses.replace(key, backend=name)
        return
    if section == "scene":  # a SceneConfig where a device is simulated (controller.simulated)
        yield from keys(SceneConfig, section)
        return
    if section == "parts":  # a mapping of names to declarations, built into a Catalogue
        yield from keys(PartDeclaration, "parts.<name>")
        return
    hints = typing.get_type_hints(FineposConfig, localns={"SceneConfig": SceneConfig})
    yield from keys(hints[section], section)


def sections() -> list[str]:
    """The cell config's root sections in file order (the recipe is not one of them)."""
    return [f.name for f in dataclasses.fields(FineposConfig)
            if f.name not in ("source", "perception")]


def tier_of(key: Key) -> str:
    """Which tier a key of the cell config's sections is in: ``operator``, ``advanced``,
    ``recipe`` (a recipe key of ``controller.loop``) or ``simulator``."""
    section = key.path.split(".")[0]
    if section in SIMULATOR_SECTIONS or key.backend == "sim":
        return "simulator"
    if key.path.startswith("controller.loop.") and \
            key.path.removeprefix("controller.loop.") in RECIPE_LOOP_KEYS:
        return "recipe"
    return "operator" if key.path in OPERATOR_KEYS else "advanced"


def recipe_keys() -> Iterator[Key]:
    """The recipe's keys, as a recipe file names them."""
    yield from keys(PerceptionConfig, "perception")
    yield from (key for key in keys(LoopConfig, "loop")
                if key.path.removeprefix("loop.") in RECIPE_LOOP_KEYS)


def tiered() -> dict[str, dict[str, list[Key]]]:
    """Every key by tier, then by root section, in file order."""
    out: dict[str, dict[str, list[Key]]] = {tier: {} for tier in TIERS}
    for section in sections():
        for key in section_keys(section):
            tier = tier_of(key)
            if tier != "recipe":
                out[tier].setdefault(section, []).append(key)
    for key in recipe_keys():
        out["recipe"].setdefault(key.path.split(".")[0], []).append(key)
    return out


def operator_keys() -> list[str]:
    """The operator keys the page documents."""
    return [key.path for keys_ in tiered()["operator"].values() for key in keys_]


RECIPE_NOTES = {
    "perception": "The vision pipeline and the systems it is compared with "
                  "([method.md](method.md)).",
    "loop": "The positioning loop's tuned keys (its convergence thresholds and budget are the "
            "cell's, under `controller.loop`).",
}

TIER_TEXT = {
    "operator": ["## Operator keys", "",
                 "What an operator sets on a cell: the devices and their ports, the safety "
                 "limits, the part, the paths, the loop's precision and budget, the grasp's "
                 "guards and checks, teach-in and the service."],
    "advanced": ["## Advanced keys", "",
                 "The rest of the cell config. Most cells keep these defaults: the drivers' "
                 "protocol details and templates (for a controller that speaks differently), "
                 "the service's limits, the acquisition grids, the grasp's sampling and the "
                 "3D mouse's axes."],
    "recipe": ["## Recipe", "",
               "The perception and loop settings tuned by experiment. They are not in the cell "
               "config (a cell config that sets one is refused, naming its home): "
               "`finepos train --recipe FILE` trains with a recipe file (YAML, sections "
               "`perception` and `loop`, every key optional, `deploy/recipe.yaml` is a "
               "commented example) and writes the recipe into the model file; every run reads "
               "it back from there. `finepos train` without `--recipe` keeps the model file's "
               "recipe; a model file without one runs with these defaults. The lab commands "
               "(`evaluate`, `table1`, `demo`, ...) take `--recipe` too."],
    "simulator": ["## Simulator", "",
                  "Read only where a simulated cell or an emulator is built "
                  "([simulator.md](simulator.md)): the scene, the timing model, and the options "
                  "of the simulated devices (`type: sim`)."],
}


def render() -> str:
    """The whole page (Markdown)."""
    tiers = tiered()
    lines = [
        "# Configuration reference",
        "",
        f"<!-- Generated by `{COMMAND}` from the typed config; do not edit. -->",
        "",
        "finepos reads its settings from three places:",
        "",
        f"- **The cell config**, one YAML file given with `--config FILE` (the service: "
        f"`/etc/finepos/finepos.yaml`; `deploy/finepos.yaml` is a commented example): its "
        f"[{len(operator_keys())} operator keys](#operator-keys) and its "
        f"[advanced keys](#advanced-keys).",
        "- **The recipe**, kept in the model file: the perception and loop settings tuned by "
        "experiment ([recipe](#recipe)).",
        "- **The simulator's sections** of the cell config ([simulator](#simulator)).",
        "",
        "Every key is optional unless its default says `required`; with no file every default",
        "applies (the simulated cell, good light, the cube). Unknown keys, wrong types and",
        "out-of-range values fail at load with the key's full path, e.g.",
        "`scene.lighting.preset: must be one of good | poor | dim | side`. A key under `[]` is a",
        "key of each entry of a list.",
    ]
    for tier in TIERS:
        lines += ["", *TIER_TEXT[tier]]
        for section, section_keys_ in tiers[tier].items():
            note = (RECIPE_NOTES if tier == "recipe" else SECTION_NOTES).get(section, "")
            lines += ["", f"### {section}", ""] + ([note, ""] if note else []) + [
                "| key | type | unit | range | default | description |",
                "|---|---|---|---|---|---|"]
            for key in section_keys_:
                doc = f"(`type: {key.backend}`) {key.doc}".rstrip() if key.backend else key.doc
                lines.append(f"| `{key.path}` | {key.type} | {key.unit} | {key.range} | "
                             f"{_cell(key.default)} | {doc} |")
    return "\n".join(lines) + "\n"


def _cell(text: str) -> str:
    return f"`{text}`" if text not in ("required", "(below)", "") else text


def undocumented() -> list[str]:
    """The keys without a description (the test keeps this list from growing)."""
    return [key.path for by_section in tiered().values() for section_keys_ in by_section.values()
            for key in section_keys_ if not key.doc]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``finepos docs config`` options."""
    parser.add_argument("--out", metavar="FILE", help="write the page here (default: stdout)")
    parser.add_argument("--check", action="store_true",
                        help="with --out: exit 1 when FILE differs from the code, write nothing")


def run(args) -> int:
    """Write (or check) the page; 1 when ``--check`` finds it out of date."""
    return write_or_check(render(), args.out, args.check, COMMAND)


def write_or_check(page: str, out: str | None, check: bool, command: str) -> int:
    """Print ``page``, write it to ``out``, or (``check``) compare ``out`` with it."""
    if out is None:
        sys.stdout.write(page)
        return 0
    path = Path(out)
    if check:
        current = path.read_text(encoding="utf-8") if path.exists() else ""
        if current != page:
            print(f"{out} is out of date: run {command}", file=sys.stderr)
            return 1
        return 0
    atomic_write_text(path, page)
    print(f"wrote {out}", file=sys.stderr)
    return 0
