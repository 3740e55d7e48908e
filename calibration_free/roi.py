"""Region of interest: a square window of the normalised image centred on the object.

The window is sampled bilinearly at the sub-pixel centre (u, v), so its contents, and the Gabor
features computed from it, vary continuously as the object moves by fractions of a pixel.

Geometry: ROI pixel (i, j) samples the image at (u - (size - 1) / 2 + j, v - (size - 1) / 2 + i),
so the ROI's own centre (at 25.0 in ROI edge coordinates for 50 px, between pixels 24 and 25)
lies exactly on (u, v).

Border: where the window reaches past the image, each missing pixel repeats the nearest edge
pixel of the image (replicated border, as ``cv2.getRectSubPix`` does). Features stay finite
and continuous as the object approaches the border; they are, of course, less informative.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from calibration_free.errors import ImageError

ROI_PX = 50


def extract_roi(normalised: np.ndarray, u_px: float, v_px: float, size_px: int = ROI_PX) \
        -> np.ndarray:
    """The size x size float32 window of ``normalised`` centred on (u_px, v_px).

    Args:
        normalised: HxW float32 image.
        u_px: column of the centre (pixel-centre coordinates, sub-pixel).
        v_px: row of the centre.
        size_px: side of the square window.

    Raises:
        ImageError: the image is not HxW float32, the centre is not finite or lies outside
            the image, or the size is not a positive integer.
    """
    if not isinstance(normalised, np.ndarray) or normalised.dtype != np.float32 \
            or normalised.ndim != 2 or normalised.size == 0:
        raise ImageError(f"normalised image: expected HxW float32, got "
                         f"{getattr(normalised, 'shape', None)} "
                         f"{getattr(normalised, 'dtype', type(normalised))}")
    height, width = normalised.shape
    if not (math.isfinite(u_px) and math.isfinite(v_px)
            and -0.5 <= u_px <= width - 0.5 and -0.5 <= v_px <= height - 0.5):
        raise ImageError(f"ROI centre ({u_px!r}, {v_px!r}) is not inside the "
                         f"{width}x{height} image")
    if not isinstance(size_px, int) or size_px < 1:
        raise ImageError(f"ROI size must be a positive integer, got {size_px!r}")
    return cv2.getRectSubPix(normalised, (size_px, size_px), (float(u_px), float(v_px)))


def above(roi: np.ndarray, level: float, top: float | None = None) -> np.ndarray:
    """``roi`` less ``level``, and 0 where it is below: only what stands above the level;
    with ``top``, at most ``top - level`` (everything from ``top`` up reads the same).
    In place (``roi`` is a window ``extract_roi`` has just cut); returns ``roi``."""
    np.subtract(roi, np.float32(level), out=roi)
    if top is None:
        return np.maximum(roi, np.float32(0.0), out=roi)
    return np.clip(roi, np.float32(0.0), np.float32(top - level), out=roi)
