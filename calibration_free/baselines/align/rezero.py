"""Re-zero the image-alignment servo in the light the cell works in.

The servo settles where the part's silhouette registers to its template with no shift and no
turn: the template, the mean silhouette of the frames taken at the taught pose, is its zero.
Under another light the silhouette itself changes by a quarter to half a pixel
(docs/decisions/0011-rezero-in-the-cells-light.md), and the servo settles 0.1-0.3 mm off.
As ``finepos rezero`` moves the Gabor nets' zero (``calibration_free.rezero``), the template
is taken again from frames at the taught pose in the new light, cut at the same reference
point; the fitted maps
from the registration to the tool step stay as trained. The same checks guard it: the part
seen whole in most frames, and what the servo reads there within MAX_SHIFT_MM and
MAX_TURN_DEG (farther, the part is not where it was taught, or the camera moved).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from calibration_free import angles
from calibration_free.baselines.align.model import AlignModel
from calibration_free.pin import seen_whole
from calibration_free.rezero import (
    require_frames,
    require_near_shift,
    require_near_turn,
    require_seen_whole,
)


@dataclass(frozen=True)
class AlignRezeroed:
    """A re-zeroed servo and what it read at the taught pose before (mm and deg), with how
    many frames were used of how many taken."""

    model: AlignModel
    read_mm: tuple[float, float]
    read_deg: float
    frames_used: int
    frames: int

    def report(self) -> dict:
        """JSON-able: what the servo read there (rounded to a micrometre, a thousandth of a
        degree) and the frame counts."""
        return {"read_mm": [round(v, 3) for v in self.read_mm],
                "read_deg": round(self.read_deg, 3),
                "frames_used": self.frames_used, "frames": self.frames}


def rezero_align(model: AlignModel, images: Sequence[np.ndarray]) -> AlignRezeroed:
    """The servo with its template taken again from ``images`` (frames at the taught pose in
    the cell's light); its ``training`` metadata records what it read there before.

    Raises:
        TrainingError: the part is seen whole in too few frames, or the servo reads more than
            MAX_SHIFT_MM or MAX_TURN_DEG there (the part is not where it was taught).
        ImageError: a frame of the wrong size or type.
    """
    require_frames(images)
    front = model.front
    located = [front.locate(image) for image in images]
    whole = [(front.feature_frame(pre, loc), loc) for pre, loc in located
             if loc.ok and seen_whole(front.seen_share(loc.area_px))]
    require_seen_whole(len(whole), len(images))
    steps = np.array([model.step(model.register_silhouette(silhouette, loc))
                      for silhouette, loc in whole])
    s, c = np.mean([angles.encode(d, model.kappa) for d in steps[:, 2]], axis=0)
    read_deg = float(angles.decode(float(s), float(c), model.kappa))
    require_near_turn("the servo", read_deg)
    read_mm = tuple(float(v) for v in steps[:, :2].mean(axis=0))
    require_near_shift("the servo", math.hypot(*read_mm))
    size = model.template.shape[0]
    template = np.mean([cv2.getRectSubPix(silhouette, (size, size), front.nominal_uv_px)
                        for silhouette, _ in whole], axis=0).astype(np.float32)
    result = AlignRezeroed(model, read_mm, read_deg, len(whole), len(images))
    history = [*model.training.get("rezero", []), result.report()]
    return dataclasses.replace(result, model=dataclasses.replace(
        model, template=template, training={**model.training, "rezero": history}))
