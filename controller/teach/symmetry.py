"""A part's rotational symmetry (kappa) found from its own images at the taught pose.

At teach-in of a part declared without ``kappa``, the tool turns a full turn about its
approach axis at the taught pose in ``LOOKS`` equal steps, taking ``FRAMES`` frames at each
look. Turning the camera-in-hand by a turn t shows the part as if the part had turned by -t,
so the view repeats after 360/kappa deg. Each look is reduced to the part's silhouette (the
most saturated blob, its holes filled: the outline, which the light changes least) and every
pair of looks is compared by the mean distance between their outlines (px). The score of a
shift by d steps is the mean over the pairs d apart; the repeat score is the distance between
two frames of one look (the camera's noise).

Judging (``judge``): a kappa k (a divisor of LOOKS) fits when the shifts by multiples of
LOOKS/k show the same view (at most SAME_PX) and every other shift a clearly other one (at
least GAP_RATIO times as far, and MIN_GAP_PX more). The largest k that fits is the part's
kappa; with none, a part whose view barely changes at any turn (round) is unsure, else kappa
is 1 if no shift comes within DIFFERENT_PX, and unsure otherwise (a part nearly but not
quite symmetric). Where it is unsure, teach-in refuses to guess: a wrong kappa is worse than
none. The thresholds and their evidence: docs/decisions/0023-parts-declared-in-config.md.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import cv2
import numpy as np

from drivers.core.pose import Pose, ToolStep

logger = logging.getLogger(__name__)

LOOKS = 12  # one every 30 deg: kappa 1, 2, 3, 4 or 6 can be told (12: round, unsure)
FRAMES = 2  # frames per look; two of one look give the repeat score
SAME_PX = 0.5  # outlines at most this far apart (mean, px) show the same view
DIFFERENT_PX = 1.0  # outlines at least this far apart show another view
GAP_RATIO = 1.3  # every other shift at least this many times as far as a repeating one
MIN_GAP_PX = 0.06  # ... and this much farther (about the repeat score in poor light)
SURE_CONFIDENCE = 0.25  # below it, the kappa found is reported as unsure


@dataclass(frozen=True)
class SymmetryEvidence:
    """What the looks tell of a part's symmetry.

    kappa: the kappa found (None: none fits, see ``reason``); sure: whether it may be used
    without confirmation; confidence: 0..1, how far apart the repeating and the other views
    are; scores_px: the mean outline distance for a shift of 1..LOOKS-1 steps; repeat_px:
    the distance between two frames of one look; reason: one line saying what was found.
    """

    kappa: int | None
    sure: bool
    confidence: float
    scores_px: tuple[float, ...] = field(default=())
    repeat_px: float = 0.0
    reason: str = ""

    def as_dict(self) -> dict:
        return {"kappa": self.kappa, "sure": self.sure, "confidence": round(self.confidence, 3),
                "scores_px": [round(s, 3) for s in self.scores_px],
                "repeat_px": round(self.repeat_px, 3), "reason": self.reason}


def part_silhouette(image: np.ndarray) -> np.ndarray:
    """The part's silhouette in an RGB image: the largest blob of saturated colour (Otsu's
    threshold on the saturation), its holes filled (uint8, 1 inside)."""
    saturation = cv2.GaussianBlur(cv2.cvtColor(image, cv2.COLOR_RGB2HSV)[..., 1], (3, 3), 0)
    _, mask = cv2.threshold(saturation, 0, 1, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask)
    out = np.zeros_like(mask)
    if count < 2:
        return out
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    contours, _ = cv2.findContours((labels == largest).astype(np.uint8), cv2.RETR_EXTERNAL,
                                   cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(out, contours, -1, 1, thickness=-1)
    return out


def _outline(mask: np.ndarray) -> np.ndarray:
    return cv2.morphologyEx(mask, cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)) > 0


def outline_distance(a: np.ndarray, b: np.ndarray) -> float:
    """The mean distance (px) from each silhouette's outline to the other's, both ways."""
    ea, eb = _outline(a), _outline(b)
    if not ea.any() or not eb.any():
        return float("inf")
    da = cv2.distanceTransform((~ea).astype(np.uint8), cv2.DIST_L2, 5)
    db = cv2.distanceTransform((~eb).astype(np.uint8), cv2.DIST_L2, 5)
    return 0.5 * float(da[eb].mean() + db[ea].mean())


def shift_scores(silhouettes: list[np.ndarray]) -> list[float]:
    """For a shift of 1..n-1 looks (n looks over a full turn), the mean outline distance
    between the looks that far apart."""
    n = len(silhouettes)
    return [float(np.mean([outline_distance(silhouettes[i], silhouettes[(i + d) % n])
                           for i in range(n)])) for d in range(1, n)]


def judge(scores_px: list[float], repeat_px: float) -> SymmetryEvidence:
    """The kappa the shift scores (``shift_scores`` of LOOKS = len(scores_px) + 1 looks over
    a full turn) show, and how sure it is (see the module docstring)."""
    looks = len(scores_px) + 1
    scores = np.asarray(scores_px, dtype=float)
    shifts = np.arange(1, looks)
    common = dict(scores_px=tuple(float(s) for s in scores), repeat_px=float(repeat_px))
    for k in sorted((k for k in range(2, looks) if looks % k == 0), reverse=True):
        repeating = shifts % (looks // k) == 0
        same, other = scores[repeating].max(), scores[~repeating].min()
        if same <= SAME_PX and other >= GAP_RATIO * same and other - same >= MIN_GAP_PX:
            confidence = float((other - same) / other)
            sure = confidence >= SURE_CONFIDENCE
            reason = (f"the view repeats every {360 // k} deg ({same:.2f} px) and differs "
                      f"between ({other:.2f} px)")
            return SymmetryEvidence(k, sure, confidence, reason=reason, **common)
    if scores.max() <= SAME_PX:
        return SymmetryEvidence(None, False, 0.0, reason="the view barely changes at any turn "
                                f"(every shift within {SAME_PX:g} px): a round part?", **common)
    nearest = float(scores.min())
    turn = 360 * (int(np.argmin(scores)) + 1) // looks
    confidence = float(np.clip((nearest - SAME_PX) / (DIFFERENT_PX - SAME_PX), 0.0, 1.0))
    if nearest >= DIFFERENT_PX:
        return SymmetryEvidence(1, True, confidence, reason=f"no turn repeats the view (the "
                                f"nearest, {turn} deg, {nearest:.2f} px away)", **common)
    return SymmetryEvidence(1, False, confidence, reason=f"nearly symmetric: a turn of {turn} "
                            f"deg almost repeats the view ({nearest:.2f} px), no kappa fits "
                            "clearly", **common)


def find_symmetry(arm, camera, taught: Pose, move_to, looks: int = LOOKS,
                  frames: int = FRAMES) -> SymmetryEvidence:
    """Turn the tool a full turn about its approach axis at ``taught`` in ``looks`` steps,
    ``frames`` frames a look, judge the part's symmetry, and return to ``taught``.

    Args:
        arm, camera: the cell's arm and hand camera (connected, active).
        move_to: moves the arm to a pose within the safety limits.
    """
    silhouettes, repeats = [], []
    try:
        for i in range(looks):
            move_to(taught.moved_in_tool_frame(ToolStep(dphi_deg=360.0 * i / looks)))
            shots = [part_silhouette(camera.grab().image) for _ in range(max(frames, 1))]
            silhouettes.append(shots[0])
            repeats += [outline_distance(shots[0], s) for s in shots[1:]]
    finally:
        move_to(taught)
    if any(not s.any() for s in silhouettes):
        return SymmetryEvidence(None, False, 0.0, reason="the part is not in view at every "
                                "turn of the taught pose")
    evidence = judge(shift_scores(silhouettes), float(np.mean(repeats)) if repeats else 0.0)
    logger.info("symmetry: kappa %s (%s, confidence %.2f): %s", evidence.kappa,
                "sure" if evidence.sure else "unsure", evidence.confidence, evidence.reason)
    return evidence
