"""Synthetic hand-camera images of a cube on a grey table, for tests and benchmarks.

A stand-in for the real camera (and independent of the PyBullet cell): a yellow rounded square
with dark screw holes (by default the cube's top face: one central hole, so it looks the same
every 90 degrees, kappa = 4), drawn supersampled so edges land at sub-pixel positions, then
reduced by area averaging. The camera looks straight down; image position depends only on the
translation part of the corrective step (the step translates first, then turns about the new
approach axis, which then passes through the object), and the object's image angle is its
nominal angle plus dphi.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from calibration_free.dataset import Dataset

# Fixed-point bits for sub-pixel drawing with cv2 (coordinates are scaled by 2**_SHIFT).
_SHIFT = 4
_ARC_POINTS = 8


@dataclass(frozen=True)
class SyntheticCell:
    """Camera, object and lighting of the synthetic scene.

    Attributes:
        width_px, height_px: image size.
        px_per_mm: image scale at the table.
        nominal_uv_px: where the object's centre appears at the nominal pose.
        camera_angle_deg: rotation of the image axes against the tool axes.
        object_angle_deg: the object's angle in the image at the nominal pose.
        side_mm: side of the square top face; corner_mm: radius of its rounded corners.
        holes_mm: centres of the screw holes in the object frame; hole_radius_mm: their radius.
        object_rgb, hole_rgb, table_rgb: colours.
        noise_std: standard deviation of additive Gaussian pixel noise (grey levels).
        supersample: drawing resolution factor per axis.
    """

    width_px: int = 192
    height_px: int = 144
    px_per_mm: float = 1.5
    nominal_uv_px: tuple[float, float] = (98.0, 70.0)
    camera_angle_deg: float = 8.0
    object_angle_deg: float = 10.0
    side_mm: float = 20.0
    corner_mm: float = 3.0
    holes_mm: tuple[tuple[float, float], ...] = ((0.0, 0.0),)
    hole_radius_mm: float = 3.0
    object_rgb: tuple[int, int, int] = (225, 195, 40)
    hole_rgb: tuple[int, int, int] = (70, 55, 25)
    table_rgb: tuple[int, int, int] = (125, 125, 120)
    noise_std: float = 1.5
    supersample: int = 4


def image_pose(cell: SyntheticCell, label: np.ndarray) -> tuple[float, float, float]:
    """(u_px, v_px, angle_deg) of the object in the image taken where ``label`` corrects."""
    dx_mm, dy_mm, dphi_deg = (float(x) for x in label)
    a = math.radians(cell.camera_angle_deg)
    u = cell.nominal_uv_px[0] + cell.px_per_mm * (math.cos(a) * dx_mm - math.sin(a) * dy_mm)
    v = cell.nominal_uv_px[1] + cell.px_per_mm * (math.sin(a) * dx_mm + math.cos(a) * dy_mm)
    return u, v, cell.object_angle_deg + dphi_deg


def _outline_mm(cell: SyntheticCell) -> np.ndarray:
    """Rounded-square outline in the object frame, (K, 2) mm."""
    inner = cell.side_mm / 2.0 - cell.corner_mm
    points = []
    for k, (sx, sy) in enumerate(((1, 1), (-1, 1), (-1, -1), (1, -1))):
        start = k * math.pi / 2.0
        for t in np.linspace(start, start + math.pi / 2.0, _ARC_POINTS):
            points.append((sx * inner + cell.corner_mm * math.cos(t),
                           sy * inner + cell.corner_mm * math.sin(t)))
    return np.asarray(points)


def render_at(cell: SyntheticCell, u_px: float, v_px: float, angle_deg: float,
              rng: np.random.Generator | None = None, gain: float = 1.0,
              bias: float = 0.0) -> np.ndarray:
    """RGB uint8 image with the object's centre at (u_px, v_px), turned by angle_deg.

    Args:
        cell: the scene.
        u_px, v_px: object centre, pixel-centre coordinates, sub-pixel.
        angle_deg: object angle in the image (clockwise on screen, y pointing down).
        rng: noise source; None draws no noise.
        gain, bias: global lighting change applied before noise (``gain * I + bias``).
    """
    s = cell.supersample
    canvas = np.empty((cell.height_px * s, cell.width_px * s, 3), np.uint8)
    canvas[:] = cell.table_rgb
    a = math.radians(angle_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    scale = cell.px_per_mm * s
    centre = np.array([(u_px + 0.5) * s - 0.5, (v_px + 0.5) * s - 0.5])

    def to_fixed(points_mm: np.ndarray) -> np.ndarray:
        big = centre + scale * points_mm @ rot.T
        return np.round(big * (1 << _SHIFT)).astype(np.int32)

    cv2.fillPoly(canvas, [to_fixed(_outline_mm(cell))], cell.object_rgb, cv2.LINE_8, _SHIFT)
    radius = int(round(cell.hole_radius_mm * scale * (1 << _SHIFT)))
    for hole in to_fixed(np.asarray(cell.holes_mm, dtype=np.float64).reshape(-1, 2)):
        cv2.circle(canvas, (int(hole[0]), int(hole[1])), radius, cell.hole_rgb, -1,
                   cv2.LINE_8, _SHIFT)
    image = cv2.resize(canvas, (cell.width_px, cell.height_px),
                       interpolation=cv2.INTER_AREA).astype(np.float32)
    image = image * gain + bias
    if rng is not None and cell.noise_std > 0:
        image += rng.normal(0.0, cell.noise_std, image.shape).astype(np.float32)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def render(cell: SyntheticCell, label: np.ndarray, rng: np.random.Generator | None = None,
           gain: float = 1.0, bias: float = 0.0) -> np.ndarray:
    """RGB uint8 image taken where the corrective step ``label`` [dx_mm, dy_mm, dphi_deg]
    leads back to the nominal pose."""
    return render_at(cell, *image_pose(cell, label), rng=rng, gain=gain, bias=bias)


def render_dataset(cell: SyntheticCell, labels: np.ndarray, rng: np.random.Generator | None,
                   metadata: dict | None = None) -> Dataset:
    """A Dataset of rendered images for the given labels (N, 3)."""
    labels = np.asarray(labels, dtype=np.float64)
    images = np.stack([render(cell, label, rng) for label in labels])
    return Dataset(labels, images=images, metadata=dict(metadata or {}))
