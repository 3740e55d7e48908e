"""Procedural textures (RGB uint8 arrays): table surfaces, part shading, the robot's paint.

Textures are pure functions of their arguments (fixed internal seeds), so a scene renders the
same in every run. ``TextureFiles`` writes them where PyBullet's ``loadTexture`` can read them
and deletes them on ``close()``.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import cv2
import numpy as np

from sim_backend.cell.meshes import DARK_U_END, DARK_U_START

TABLE_TILE_MM = 200.0  # one table texture tile covers this square
_TABLE_TEXTURE_PX = 512
_PATTERN_SEED = 260  # textures look the same in every run


def part_shading() -> np.ndarray:
    """Greyscale ramp for parts: white where u < 0.5 (tinted by the part's colour), darkening
    from the rim of a hole (u = 0.5) to its bottom (u = 1)."""
    width = 128
    u = (np.arange(width) + 0.5) / width
    ramp = np.interp(u, [DARK_U_START, DARK_U_END], [0.42, 0.08])
    value = np.where(u < DARK_U_START, 1.0, ramp)
    row = np.repeat((value * 255).astype(np.uint8)[:, None], 3, axis=1)
    return np.repeat(row[None], 4, axis=0)


# Swatches of the palette texture: name -> RGB (0..1), in order along u.
PALETTE: dict[str, tuple[float, float, float]] = {
    "paint": (0.86, 0.84, 0.78),      # the PUMA's cream paint
    "joint": (0.30, 0.30, 0.32),      # motor covers, wrist
    "metal": (0.55, 0.56, 0.58),      # sensor, gripper body
    "finger": (0.16, 0.16, 0.18),     # dark anodised fingers
    "camera": (0.05, 0.05, 0.06),     # camera housing
}


def palette_u(name: str) -> float:
    """Texture u at the centre of swatch ``name``."""
    index = list(PALETTE).index(name)
    return (index + 0.5) / len(PALETTE)


def palette_texture() -> np.ndarray:
    swatch = 8
    colors = np.array(list(PALETTE.values()))
    row = np.repeat((colors * 255).round().astype(np.uint8), swatch, axis=0)
    return np.repeat(row[None], 4, axis=0)


def table_texture(kind: str, color: tuple[float, float, float]) -> np.ndarray:
    """One square tile (TABLE_TILE_MM wide) of the table top: ``wood``, ``checker``, ``noise``.

    The pattern modulates ``color``; tiles repeat seamlessly.
    """
    n = _TABLE_TEXTURE_PX
    rng = np.random.default_rng(_PATTERN_SEED)
    yy, xx = np.mgrid[0:n, 0:n] / n  # tile coordinates in [0, 1)
    if kind == "checker":
        squares = 10  # 20 mm squares
        shade = np.where(((xx * squares).astype(int) + (yy * squares).astype(int)) % 2, 1.2, 0.8)
    elif kind == "wood":
        # Grain along x: annual rings of a board cut lengthwise, slowly wandering, plus fibres.
        warp = (_periodic_noise(rng, n, cells=8, stretch_x=8) * 0.8
                + _periodic_noise(rng, n, cells=16, stretch_x=4) * 0.2)
        rings = np.sin(2 * math.pi * (yy * 12.0 + warp)) ** 3
        fibres = _periodic_noise(rng, n, cells=128, stretch_x=16)
        shade = 1.0 + 0.14 * rings + 0.07 * fibres
    elif kind == "noise":
        shade = 1.0 + 0.35 * _periodic_noise(rng, n, cells=24) + 0.1 * _periodic_noise(
            rng, n, cells=96)
    else:
        raise ValueError(f"unknown table texture {kind!r}")
    rgb = np.clip(shade[..., None] * np.asarray(color)[None, None, :], 0.0, 1.0)
    return (rgb * 255).round().astype(np.uint8)


def _periodic_noise(rng: np.random.Generator, size: int, cells: int,
                    stretch_x: int = 1) -> np.ndarray:
    """Smooth, tileable value noise in about [-1, 1] (cells x cells random values, cubic)."""
    grid = rng.uniform(-1.0, 1.0, (cells, max(1, cells // stretch_x)))
    tiled = np.tile(grid, (3, 3))
    big = cv2.resize(tiled, (3 * size, 3 * size), interpolation=cv2.INTER_CUBIC)
    return np.clip(big[size:2 * size, size:2 * size], -1.0, 1.0)


class TextureFiles:
    """A private folder of PNG files for PyBullet's ``loadTexture``; ``close()`` removes it."""

    def __init__(self) -> None:
        self._dir = tempfile.TemporaryDirectory(prefix="finepos-textures-")
        self._count = 0

    def write(self, rgb: np.ndarray) -> str:
        path = Path(self._dir.name) / f"texture{self._count}.png"
        self._count += 1
        if not cv2.imwrite(str(path), cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR)):
            raise OSError(f"cannot write texture {path}")
        return str(path)

    def close(self) -> None:
        self._dir.cleanup()

