"""Edge points of the object's outline: the Hough system's image preprocessing (paper 4.3).

smoothing (Gaussian) -> edge filter (Sobel gradients) -> binarisation (Canny: non-maximum
suppression and hysteresis thresholds on the gradient magnitude) -> masking. The mask keeps
only edges in a band around the outline of the object's filled silhouette: edges inside it
(screw-hole rings, the border between the top and the side faces) and outside it (shadows,
other parts) are dropped, which leaves the "empty outline" of the paper's Fig. 3c. Each kept
edge pixel is moved to the sub-pixel maximum of the gradient magnitude across the edge.

Points are pixel-centre coordinates (x = column, y = row), as in ``calibration_free.localise``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from calibration_free.errors import ImageError
from calibration_free.localise import MIN_BLOB_PX, Polarity, binarise

# Sobel gradients are stored as int16 for cv2.Canny, multiplied by this for sub-unit steps.
GRADIENT_SCALE = 16.0


def _check_float_image(image: np.ndarray) -> None:
    if not isinstance(image, np.ndarray) or image.dtype != np.float32 or image.ndim != 2 \
            or image.size == 0:
        raise ImageError(f"normalised image: expected HxW float32, got "
                         f"{getattr(image, 'shape', None)} "
                         f"{getattr(image, 'dtype', type(image))}")


def silhouette(normalised: np.ndarray, threshold: float, polarity: Polarity, u_px: float,
               v_px: float) -> np.ndarray:
    """The filled silhouette (HxW uint8, 1 inside) of the blob whose centroid is nearest
    (u_px, v_px): the binarised object with its holes filled.

    Raises:
        ImageError: bad image or polarity, or no blob of MIN_BLOB_PX pixels or more.
    """
    mask = binarise(normalised, threshold, polarity).astype(np.uint8)
    n, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
    big = [i for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= MIN_BLOB_PX]
    if not big:
        raise ImageError("silhouette: no blob in the binarised image")
    best = min(big, key=lambda i: float(np.hypot(*(centroids[i] - (u_px, v_px)))))
    blob = (labels == best).astype(np.uint8)
    contours, _ = cv2.findContours(blob, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    filled = np.zeros_like(blob)
    cv2.drawContours(filled, contours, -1, 1, thickness=cv2.FILLED)
    return filled


def gradients(normalised: np.ndarray, blur_sigma_px: float) -> tuple[np.ndarray, np.ndarray]:
    """Sobel x and y gradients (3x3 kernels, unnormalised) of the Gaussian-smoothed image,
    float32; a ramp of 1 grey level per pixel gives 8.

    Raises:
        ImageError: bad image or a sigma that is not > 0.
    """
    _check_float_image(normalised)
    if not blur_sigma_px > 0:
        raise ImageError(f"blur_sigma_px: must be > 0, got {blur_sigma_px!r}")
    smooth = cv2.GaussianBlur(normalised, (0, 0), blur_sigma_px,
                              borderType=cv2.BORDER_REPLICATE)
    gx = cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=3, borderType=cv2.BORDER_REPLICATE)
    gy = cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=3, borderType=cv2.BORDER_REPLICATE)
    return gx, gy


def outline_gradient(normalised: np.ndarray, filled: np.ndarray, blur_sigma_px: float) \
        -> float:
    """Median gradient magnitude on the outline of a filled silhouette (the contrast the
    binarisation thresholds are learned from)."""
    gx, gy = gradients(normalised, blur_sigma_px)
    ring = filled - cv2.erode(filled, np.ones((3, 3), np.uint8))
    values = np.hypot(gx, gy)[ring > 0]
    return float(np.median(values)) if values.size else 0.0


@dataclass(frozen=True)
class EdgeMap:
    """Binary edges (HxW uint8, 255 on an edge) and the gradients they were found in."""

    binary: np.ndarray
    gx: np.ndarray
    gy: np.ndarray


def edge_map(normalised: np.ndarray, blur_sigma_px: float, low: float, high: float) -> EdgeMap:
    """Canny edges of the smoothed image, with its gradients.

    Args:
        normalised: HxW float32 normalised image.
        blur_sigma_px: Gaussian smoothing.
        low, high: hysteresis thresholds on the gradient magnitude (units of ``gradients``).

    Raises:
        ImageError: bad image, sigma or thresholds (need 0 < low <= high).
    """
    if not 0 < low <= high:
        raise ImageError(f"edge thresholds: need 0 < low <= high, got {low!r}, {high!r}")
    gx, gy = gradients(normalised, blur_sigma_px)
    limit = np.iinfo(np.int16).max
    dx = np.clip(np.rint(gx * GRADIENT_SCALE), -limit, limit).astype(np.int16)
    dy = np.clip(np.rint(gy * GRADIENT_SCALE), -limit, limit).astype(np.int16)
    binary = cv2.Canny(dx, dy, low * GRADIENT_SCALE, high * GRADIENT_SCALE, L2gradient=True)
    return EdgeMap(binary, gx, gy)


def _subpixel(rows: np.ndarray, cols: np.ndarray, edges: EdgeMap) -> np.ndarray:
    """Edge pixels moved along their gradient to the parabola vertex of the gradient
    magnitude sampled at -1, 0, +1 px across the edge (at most half a pixel)."""
    magnitude = np.hypot(edges.gx, edges.gy)
    g = np.stack([edges.gx[rows, cols], edges.gy[rows, cols]], axis=1)
    unit = g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
    centre = np.stack([cols, rows], axis=1).astype(np.float32)
    xy = np.concatenate([centre - unit, centre + unit]).astype(np.float32)
    sampled = cv2.remap(magnitude, xy[:, 0].reshape(1, -1), xy[:, 1].reshape(1, -1),
                        cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[0]
    before, after = sampled[: rows.size], sampled[rows.size:]
    here = magnitude[rows, cols]
    curvature = before - 2.0 * here + after
    shift = np.where(curvature < 0, 0.5 * (before - after) / np.where(curvature < 0,
                                                                       curvature, -1.0), 0.0)
    return centre + np.clip(shift, -0.5, 0.5)[:, None] * unit


def outline_points(edges: EdgeMap, filled: np.ndarray, band_px: int) -> np.ndarray:
    """Sub-pixel edge points within ``band_px`` of the silhouette's outline, (K, 2) float64
    (x, y).

    Raises:
        ImageError: edges and silhouette differ in shape, or band_px < 1.
    """
    if edges.binary.shape != filled.shape or filled.ndim != 2:
        raise ImageError(f"edges {edges.binary.shape} and silhouette {filled.shape} must be "
                         f"one HxW size")
    if isinstance(band_px, bool) or not isinstance(band_px, int) or band_px < 1:
        raise ImageError(f"band_px: must be a whole number >= 1, got {band_px!r}")
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * band_px + 1, 2 * band_px + 1))
    band = (cv2.dilate(filled, kernel) > 0) & (cv2.erode(filled, kernel) == 0)
    rows, cols = np.nonzero((edges.binary > 0) & band)
    return _subpixel(rows, cols, edges).astype(np.float64)
