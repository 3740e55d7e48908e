"""The translation nets' zero, pinned on frames at the taught pose as the loop reads them.

Training fits each translation net to the images' labels, then shifts its output so that it
reads zero on the images taken at the taught pose (``training._train_pinned``), with the part's
turn there as labelled: zero. The loop feeds the rotation-aware nets (``nn1_rot`` and the near
correction) what NN2, or an elongated part's axis map, reads instead, and NN2's fit does not
read exactly zero there: the nut's, with its strong weight decay and widened copies, reads
0.15-0.27 deg on its own taught-pose frames, which ``nn1_rot`` turned into +0.005 mm of y
(docs/decisions/0006-taught-pose-frames-and-pinning.md). ``pinned`` shifts the nets once
more, by what they read on those frames through ``Perception``, the loop's own path;
``calibration_free.rezero`` does the same on frames taken later in another light.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np

from calibration_free.bundle import ModelBundle
from calibration_free.errors import TrainingError
from calibration_free.perception import Percept, Perception

# A frame shows the part whole where its blob is within this share of the taught area.
WHOLE_SHARE = 0.9


def seen_whole(share: float | None) -> bool:
    """Whether a blob's share of the taught area (None: not known) shows the part whole."""
    return share is None or share >= WHOLE_SHARE


def whole(percept: Percept) -> bool:
    """Whether ``percept`` found the part, seen whole (no hidden end, no outline fit)."""
    return percept.ok and percept.hidden_share is None and percept.hidden_px is None and \
        seen_whole(percept.seen_share)


def pinned(bundle: ModelBundle, images: Sequence[np.ndarray],
           check: Callable[[float], None] | None = None
           ) -> tuple[ModelBundle, dict[str, tuple[float, float]]]:
    """The bundle with NN1, ``nn1_rot`` and the near correction shifted so that, read on
    ``images`` (frames at the taught pose) the way the loop reads them, each reads zero on
    average; and each shift (mm). Frames where the part is not seen whole are left out.

    Args:
        bundle: the trained model.
        images: frames at the taught pose.
        check: called with the larger of NN1's and ``nn1_rot``'s mean reading (mm) before
            anything is shifted; it raises to refuse.

    Raises:
        TrainingError: no frame shows the part whole.
    """
    perception = Perception(bundle)
    seen = [(image, percept) for image, percept in
            ((image, perception.perceive(image)) for image in images) if whole(percept)]
    if not seen:
        raise TrainingError(f"none of the {len(images)} frames at the taught pose shows the "
                            "part whole")
    nn1 = np.mean([p.nn1_mm for _, p in seen], axis=0)
    rot = np.mean([p.rot_mm for _, p in seen], axis=0)
    if check is not None:
        check(max(float(math.hypot(*nn1)), float(math.hypot(*rot))))
    shifted = dataclasses.replace(bundle, nn1=bundle.nn1.shifted(nn1),
                                  nn1_rot=bundle.nn1_rot.shifted(rot))
    shift = {"nn1": tuple(map(float, nn1)), "nn1_rot": tuple(map(float, rot))}
    if bundle.near_mm > 0.0:  # the near correction adds to nn1_rot's reading where it is near
        again = Perception(shifted)
        near = np.mean([again.perceive(image).full_mm for image, _ in seen], axis=0)
        shifted = dataclasses.replace(shifted, nn1_near=shifted.nn1_near.shifted(near))
        shift["nn1_near"] = tuple(map(float, near))
    return shifted, shift
