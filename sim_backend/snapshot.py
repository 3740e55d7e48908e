"""Render what the hand camera sees at the pre-grasp pose, displaced by an offset.

Example: finepos sim snapshot --out hand.png --offset 10,-5,20

The cell is built from the ``scene:`` section of --config (defaults without it: the yellow cube,
good light); --part NAME puts another part on the table, built-in or declared in the config's
``parts:`` section (``finepos sim snapshot --config deploy/parts/example.yaml --part bracket
--out bracket.png``). The offset DX,DY,DPHI (mm, mm, deg) is a step in the tool frame from the
nominal pre-grasp pose: DX along the tool's x axis (the way the camera looks: the part then
moves down in the image), DY along its y axis (the jaw axis), DPHI about the approach axis;
write a negative first value as --offset=-5,0,0. The image is 192x144 RGB, camera noise included.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import math
from pathlib import Path

import cv2

from drivers.core.errors import ConfigError
from drivers.core.files import atomic_write_bytes
from drivers.core.parts import Catalogue
from drivers.core.pose import ToolStep
from sim_backend.cell.scene_config import SceneConfig, load_cell
from sim_backend.cell.sim_cell import SimCell

logger = logging.getLogger(__name__)

MAX_OFFSET_MM = 60.0
MAX_OFFSET_DEG = 360.0


def parse_offset(text: str) -> ToolStep:
    """``DX,DY,DPHI`` (mm, mm, deg) as a tool-frame step; ValueError explains a bad one."""
    parts = [s.strip() for s in text.split(",")]
    if len(parts) != 3:
        raise ValueError(f"expected DX,DY,DPHI (three numbers: mm, mm, deg), got {text!r}")
    try:
        dx, dy, dphi = (float(s) for s in parts)
    except ValueError:
        raise ValueError(f"expected DX,DY,DPHI as numbers, got {text!r}") from None
    if not all(math.isfinite(v) for v in (dx, dy, dphi)):
        raise ValueError(f"offset values must be finite, got {text!r}")
    if math.hypot(dx, dy) > MAX_OFFSET_MM:
        raise ValueError(f"offset of {math.hypot(dx, dy):.1f} mm is beyond the "
                         f"{MAX_OFFSET_MM:g} mm the hand camera can still see the part from")
    if abs(dphi) > MAX_OFFSET_DEG:
        raise ValueError(f"DPHI must be within +/-{MAX_OFFSET_DEG:g} deg, got {dphi:g}")
    return ToolStep(dx_mm=dx, dy_mm=dy, dphi_deg=dphi)


def _offset_arg(text: str) -> ToolStep:
    try:
        return parse_offset(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", type=Path, help="root config file (its scene: section)")
    parser.add_argument("--out", type=Path, required=True, help="PNG file to write")
    parser.add_argument("--offset", type=_offset_arg, default=ToolStep(),
                        metavar="DX,DY,DPHI", help="tool-frame offset from the pre-grasp pose "
                        "(mm, mm, deg; default 0,0,0)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the cell (noise, clutter)")
    parser.add_argument("--part", metavar="NAME",
                        help="the part on the table: a built-in one or one the config declares "
                             "under parts: (default: the scene's, scene.object.kind)")


def snapshot(scene: SceneConfig, offset: ToolStep, seed: int = 0,
             parts: Catalogue | None = None):
    """The hand camera's image (HxWx3 uint8 RGB) at the nominal pose moved by ``offset``;
    ``parts``: the catalogue the scene's part is looked up in (default: the built-in parts)."""
    with SimCell(scene, seed=seed, parts=parts) as cell:
        cell.move_arm(cell.nominal_grasp_pose().moved_in_tool_frame(offset))
        return cell.render()


def run(args: argparse.Namespace) -> int:
    if args.out.suffix.lower() != ".png":
        raise ConfigError(f"--out: the image is written as PNG, name it *.png (got {args.out})")
    scene, parts = load_cell(args.config)
    if args.part is not None:
        if args.part not in parts:
            raise ConfigError(f"--part: {parts.unknown(args.part)}")
        scene = dataclasses.replace(scene, object=dataclasses.replace(scene.object,
                                                                      kind=args.part))
    elif scene.object.kind not in parts:
        raise ConfigError(f"{args.config}: scene.object.kind: {parts.unknown(scene.object.kind)}")
    logger.info("scene: %s", scene)
    image = snapshot(scene, args.offset, args.seed, parts)
    ok, data = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    if not ok:
        raise ConfigError(f"--out: cannot encode the image as PNG for {args.out}")
    atomic_write_bytes(args.out, data.tobytes())
    logger.info("wrote %s (%dx%d, offset %s)", args.out, image.shape[1], image.shape[0],
                args.offset.as_dict())
    return 0
