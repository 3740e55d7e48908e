"""Re-zero a trained model in the light the cell works in.

Training pins the translation nets to read zero on the frames taken at the taught pose
(``training._train_pinned``): that is where the loop settles. Under another light (a low side
lamp, the room dimmed) the part's silhouette itself changes by a quarter to half a pixel (its
side faces and bevels shade differently; docs/decisions/0011-rezero-in-the-cells-light.md), the
nets read 0.2-0.3 mm at the taught pose, and the loop settles that far off. Frames taken at the
taught pose in the new light move the nets' zero back there, without a new acquisition: the
same shift of each net's output that training applied, measured again. NN2's reading there is
turned back to zero the same way (its (sin, cos) output layer turned) where it is at least
NN2_MIN_DEG: the nut's read -1.1 deg at the taught pose under the side lamp (its lit and
shaded flanks), everywhere alike (RMS after 2.5 loops 1.90 -> 0.92 deg); the cube's 0.3-0.6
deg is its reading at the taught heading only (it moves by +/-0.3 deg with the part's heading
under the lamp), and turning it back made the angle worse (0.38 -> 0.57 deg; 0.35 -> 0.69
deg where it read 0.58). A long part's axis map
(``calibration_free.axis``), which takes over near the pose, is left as trained.

The part must lie where it was taught and be seen whole: a reading far from zero (over
MAX_SHIFT_MM) means it does not, or the camera moved, and nothing is changed.

The report also tells how much of the part the camera clips there (``clipped_share``: of the
part's pixels in the frames, those with a channel at 255). An auto-exposure that keeps a dark
frame's mean grey up drives a lamp-lit face into white; where part of the outline is clipped,
what the centre reads there depends on the camera's gain from one look to the next, which no
zero takes away (docs/decisions/0013-expose-for-the-part.md: under the poor preset's lamp, a
fifth of the cube's pixels clipped and its x scattered 0.058 mm after 2.5 loops; exposed for
the part, 0.042 mm).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibration_free import angles
from calibration_free.bundle import ModelBundle
from calibration_free.errors import TrainingError
from calibration_free.perception import Perception
from calibration_free.pin import pinned
from calibration_free.pin import whole as seen_whole_part
from calibration_free.preprocess import frame_groups, frame_means

# A reading at the taught pose beyond these is not a change of light (a quarter pixel is about
# 0.25 mm): the part is not where it was taught, or the camera was knocked.
MAX_SHIFT_MM = 1.0
MAX_TURN_DEG = 3.0
# NN2 is turned back only where it reads at least this at the taught pose (module docstring).
NN2_MIN_DEG = 1.0
# At least this share of the frames must show the part whole.
MIN_FOUND_SHARE = 0.75
# More of the part's pixels clipped than this: the camera's exposure should come down
# (``FinePositioner.rezero`` warns).
CLIPPED_WARN_SHARE = 0.05


@dataclass(frozen=True)
class Rezeroed:
    """A re-zeroed model and what moved: each translation net's mean reading at the taught
    pose before (mm), NN2's (deg; None where an axis map reads the turn there) and whether NN2
    was turned back by it, how many frames were used of how many taken, how many the nets read
    at a time (their mean frame), and the share of the part's pixels the camera clipped in
    the frames used (a channel at 255)."""

    bundle: ModelBundle
    shift_mm: dict[str, tuple[float, float]]
    nn2_deg: float | None
    nn2_turned: bool
    frames_used: int
    frames: int
    average: int = 1
    clipped_share: float = 0.0

    def report(self) -> dict:
        """JSON-able: the shifts (rounded to a micrometre, a thousandth of a degree) and the
        frame counts."""
        return {"shift_mm": {k: [round(v, 3) for v in s] for k, s in self.shift_mm.items()},
                "nn2_deg": None if self.nn2_deg is None else round(self.nn2_deg, 3),
                "nn2_turned": self.nn2_turned,
                "frames_used": self.frames_used, "frames": self.frames,
                "average": self.average, "clipped_share": round(self.clipped_share, 3)}


def rezero(bundle: ModelBundle, images: Sequence[np.ndarray], average: int = 1) -> Rezeroed:
    """The bundle with its translation nets reading zero on ``images`` (frames at the taught
    pose in the cell's light); its ``training`` metadata records the shift.

    ``average``: the nets read the frames' means (``preprocess.mean_frame``) in consecutive
    groups of this many (the last one may be smaller), as the loop's settling look reads its
    step on the mean of ``settle_frames`` frames: in a dark frame the camera's noise moves
    what the nets read, so a zero read on single frames sits off the one the loop reads
    (docs/decisions/0011-rezero-in-the-cells-light.md). A mean that does not show the part whole
    leaves all its frames out of the seen-whole share.

    Raises:
        TrainingError: the part is seen whole in too few frames, or the nets read more than
            MAX_SHIFT_MM there (the part is not where it was taught).
        ImageError: a frame of the wrong size or type.
    """
    require_frames(images)
    if isinstance(average, bool) or not isinstance(average, int) or average < 1:
        raise TrainingError(f"rezero: average must be a whole number >= 1, got {average!r}")
    frames, groups = len(images), frame_groups(images, average)
    images = frame_means(images, average)
    perception = Perception(bundle)
    percepts = [perception.perceive(image) for image in images]
    whole = [i for i, p in enumerate(percepts) if seen_whole_part(p)]
    used = sum(len(groups[i]) for i in whole)
    require_seen_whole(used, frames)
    clipped = clipped_share([(groups[i], percepts[i].localisation.part_mask) for i in whole])
    nn2_deg, turned = None, False
    if bundle.axis is None:  # NN2 first: the translation nets read its (sin, cos)
        kappa = bundle.kappa
        s, c = np.mean([angles.encode(percepts[i].nn2_deg, kappa) for i in whole], axis=0)
        nn2_deg = float(angles.decode(float(s), float(c), kappa))
        require_near_turn("NN2", nn2_deg)
        turned = abs(nn2_deg) >= NN2_MIN_DEG
        if turned:
            bundle = dataclasses.replace(bundle, nn2=bundle.nn2.turned(
                math.radians(kappa * nn2_deg)))
    shifted, shift = pinned(bundle, [images[i] for i in whole],
                            check=lambda mm: require_near_shift("the model", mm))
    result = Rezeroed(shifted, shift, nn2_deg, turned, used, frames, average, clipped)
    history = [*bundle.training.get("rezero", []), result.report()]
    return dataclasses.replace(result, bundle=dataclasses.replace(
        shifted, training={**bundle.training, "rezero": history}))


def clipped_share(groups: Sequence[tuple[Sequence[np.ndarray], np.ndarray | None]]) -> float:
    """The share of the part's pixels with a channel at 255, over (frames, the part's mask
    read on their mean) groups; 0 without a mask."""
    clipped = total = 0
    for frames, mask in groups:
        if mask is None:
            continue
        part = mask > 0
        for frame in frames:
            clipped += int(np.count_nonzero((frame[part] >= 255).any(axis=-1)))
            total += int(np.count_nonzero(part))
    return clipped / total if total else 0.0


def require_frames(images: Sequence[np.ndarray]) -> None:
    """Refuse a re-zero without frames."""
    if not images:
        raise TrainingError("rezero: no frames")


def require_seen_whole(whole: int, frames: int) -> None:
    """Refuse a re-zero where the part was seen whole in fewer than MIN_FOUND_SHARE of the
    frames at the taught pose."""
    if whole < max(1, math.ceil(MIN_FOUND_SHARE * frames)):
        raise TrainingError(f"rezero: the part was seen whole in only {whole} of {frames} "
                            f"frames at the taught pose; put it where it was taught, uncovered")


def require_near_turn(reader: str, deg: float) -> None:
    """Refuse a re-zero where ``reader`` reads a turn over MAX_TURN_DEG at the taught pose."""
    if abs(deg) > MAX_TURN_DEG:
        raise TrainingError(f"rezero: at the taught pose {reader} reads {deg:.1f} deg, over "
                            f"{MAX_TURN_DEG:g} deg: the part was turned since it was taught, "
                            f"or the camera moved (teach again); the model is unchanged")


def require_near_shift(reader: str, mm: float) -> None:
    """Refuse a re-zero where ``reader`` reads a shift over MAX_SHIFT_MM at the taught pose."""
    if mm > MAX_SHIFT_MM:
        raise TrainingError(f"rezero: at the taught pose {reader} reads {mm:.2f} mm, over "
                            f"{MAX_SHIFT_MM:g} mm: the part is not where it was taught, or the "
                            f"camera moved (teach again); the model is unchanged")
