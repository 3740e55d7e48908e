"""The obvious alternative feature extractor, for comparison in ``finepos bench perception``.

What a user would write first: filter the whole normalised frame with one Gabor kernel per
orientation (``cv2.filter2D``, replicated border) and read each response at the nine centres
(bilinear, so sub-pixel centres count). The kernels are this package's own centred kernels, so
the features match ``GaborBank``'s for the centre filters exactly and for the off-centre ones up
to the window clipping (here the kernel always has its full 50x50 support).
"""

from __future__ import annotations

import cv2
import numpy as np

from calibration_free.gabor import GaborConfig, gabor_kernel


class Filter2DFeatures:
    """Gabor features by full-frame filtering, in ``GaborBank``'s feature order."""

    def __init__(self, config: GaborConfig):
        self.config = config
        half = config.roi_px / 2.0
        phases = ("even", "odd") if config.kind == "magnitude" else (config.kind,)
        self._kernels = {(phase, theta): gabor_kernel(half, half, theta, config, phase)
                         .astype(np.float32)
                         for phase in phases for theta in config.orientations_deg}
        # filter2D anchors a kernel at index size // 2, its Gabor centre lies at size/2 - 0.5:
        # the response at x0 is the Gabor centred at x0 - size // 2 + size / 2 - 0.5.
        self._anchor_shift = config.roi_px // 2 - half + 0.5
        self._offsets = np.array(config.centres_px) - half

    def features(self, normalised: np.ndarray, u_px: float, v_px: float) -> np.ndarray:
        """The n features of the ROI centred on (u_px, v_px) of the normalised frame."""
        cfg = self.config
        height, width = normalised.shape
        xs = np.clip(u_px + self._offsets + self._anchor_shift, 0.0, width - 1.0)
        ys = np.clip(v_px + self._offsets + self._anchor_shift, 0.0, height - 1.0)
        x0 = np.minimum(xs.astype(int), width - 2)
        y0 = np.minimum(ys.astype(int), height - 2)
        fx, fy = xs - x0, ys - y0
        out = {}
        for key, kernel in self._kernels.items():
            r = cv2.filter2D(normalised, cv2.CV_32F, kernel, borderType=cv2.BORDER_REPLICATE)
            top = r[y0[:, None], x0[None, :]] * (1 - fx) + r[y0[:, None], x0[None, :] + 1] * fx
            bottom = r[y0[:, None] + 1, x0[None, :]] * (1 - fx) \
                + r[y0[:, None] + 1, x0[None, :] + 1] * fx
            out[key] = top * (1 - fy)[:, None] + bottom * fy[:, None]  # (q, p)
        if cfg.kind == "magnitude":
            grids = [np.hypot(out[("even", t)], out[("odd", t)]) for t in cfg.orientations_deg]
        else:
            grids = [out[(cfg.kind, t)] for t in cfg.orientations_deg]
        return np.stack(grids, axis=-1).reshape(-1).astype(np.float32)
