"""The cell's self-check: is the learned image-to-motion mapping still this cell's?

Nobody calibrates the camera, so nobody notices when it is knocked, or when another part
lies on the table: the trained model would keep positioning, on a wrong mapping. At the taught
pose the arm is, by definition, where the model should command no move. ``self_check`` goes
there and looks:

* correction: the trained model's corrective step, averaged over a few frames, must be near
  zero (``max_correction_mm`` / ``max_correction_deg``); a camera moved on its mount (or a
  shifted part) shows here as a step the model wants to make;
* appearance: the frame must look like the image the acquisition took at the same pose
  (zero-mean normalised cross-correlation of the blurred grey images, at least
  ``min_similarity``); a changed part, lens or view shows here even when the step happens to
  be small.

When either fails, the check fires: the camera or the part has changed and the cell needs a
new teach-in (teach, acquire, train). ``finepos check`` runs it; the service runs it at start
(``run_self_check``).
"""

from __future__ import annotations

import logging
import math
from dataclasses import asdict, dataclass, field

import cv2
import numpy as np

from calibration_free.dataset import Dataset
from controller.systems.estimator import corrective_step
from controller.systems.registry import SYSTEMS

logger = logging.getLogger(__name__)

MAX_CORRECTION_MM = 0.6
MAX_CORRECTION_DEG = 1.5
MIN_SIMILARITY = 0.95
SETTLE_FRAMES = 3  # frames dropped first (auto-exposure settling after the move)
CHECK_FRAMES = 3
_BLUR_SIGMA_PX = 1.5


@dataclass(frozen=True)
class CheckLimits:
    """When the self-check fires (see the module docstring)."""

    max_correction_mm: float = MAX_CORRECTION_MM
    max_correction_deg: float = MAX_CORRECTION_DEG
    min_similarity: float = MIN_SIMILARITY


@dataclass
class SelfCheckResult:
    """What the self-check measured and its verdict.

    Attributes:
        fired: the camera or the part has changed: the cell needs a new teach-in.
        reasons: why it fired (empty when it did not).
        correction: the mean corrective step at the taught pose (dx_mm, dy_mm, dphi_deg), or
            None when the part was not found.
        similarity: the frame's similarity to the acquisition's image at the taught pose
            (1: the same), or None when no acquired set is stored.
        limits: the limits it was checked against.
        message: one line for the user.
    """

    fired: bool
    reasons: list[str]
    correction: dict[str, float] | None
    similarity: float | None
    limits: CheckLimits
    frames: int
    message: str = ""
    reference: str | None = field(default=None)

    def as_dict(self) -> dict:
        """The result as plain JSON-able values."""
        out = asdict(self)
        out["limits"] = asdict(self.limits)
        return out


def _grey(image: np.ndarray) -> np.ndarray:
    grey = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY).astype(np.float32)
    return cv2.GaussianBlur(grey, (0, 0), _BLUR_SIGMA_PX)


def similarity(a: np.ndarray, b: np.ndarray) -> float:
    """Zero-mean normalised cross-correlation of two RGB images' blurred grey levels
    (1: identical up to brightness and contrast; 0: unrelated)."""
    ga, gb = _grey(a), _grey(b)
    if ga.shape != gb.shape:
        return 0.0
    ga, gb = ga - ga.mean(), gb - gb.mean()
    denom = float(np.sqrt((ga * ga).sum() * (gb * gb).sum()))
    return float((ga * gb).sum() / denom) if denom > 0 else 0.0


def reference_image(fp) -> tuple[np.ndarray, str] | None:
    """The acquired image taken at the taught pose (the nn1 or nn2 image with the smallest step),
    and where it comes from; None when no acquired set with one is stored.

    Every stored set is read and checked whole (``Dataset.load``), the one not used for the
    reference too: the check vouches for the files a re-training would use.

    Raises:
        DatasetError: a set is stored but cannot be read or is not a finepos dataset (a damaged
            or replaced file); the message names it.
    """
    found = None
    for name in ("nn1", "nn2"):
        path = fp.dataset_path(name)
        if not (path.exists() or path.is_symlink()):  # not acquired (a dangling link is read)
            continue
        data = Dataset.load(path)
        if found is not None or data.images is None or not len(data):
            continue
        norms = np.abs(data.labels).sum(axis=1)
        index = int(np.argmin(norms))
        if norms[index] <= 0.5:  # the grid point at the pose (plus the arm's repeatability)
            found = data.images[index], f"{name}[{index}]"
    return found


def self_check(fp, system: str = "gabor", limits: CheckLimits = CheckLimits(),
               frames: int = CHECK_FRAMES, model=None) -> SelfCheckResult:
    """Move to the taught pose and check the model's correction and the part's appearance.

    Args:
        fp: the FinePositioner on the opened cell (taught, acquired and trained).
        system: whose stored model to check (unless ``model`` is given).
        limits: when it fires.
        frames: frames averaged.
        model: the TrainedModel to check (default: ``system``'s stored model).

    Everything it reads (the teach-in, the acquired sets, the model) is read and checked before
    the arm moves.

    Raises:
        StateError: nothing taught yet. BundleError: no model stored, or a damaged one.
        DatasetError: an acquired set is stored but unreadable (``reference_image``).
    """
    state = fp.state()
    ref = reference_image(fp)
    model = model if model is not None else fp.load_model(system=system)
    estimator = SYSTEMS[model.system].estimator(model)
    fp.move_to(state.nominal_pose)
    camera = fp.devices.camera
    for _ in range(SETTLE_FRAMES):
        camera.grab()
    steps, images, reasons = [], [], []
    for _ in range(frames):
        image = camera.grab().image
        images.append(image)
        tr = estimator.estimate_translation(image)
        if tr.status != "ok":
            reasons.append(f"the model does not find the part at the taught pose "
                           f"({tr.reason or tr.status})")
            break
        step = corrective_step(tr, estimator.estimate_rotation(tr))
        steps.append((step.dx_mm, step.dy_mm, step.dphi_deg))
    correction = None
    if steps and not reasons:
        dx, dy, dphi = (float(v) for v in np.mean(steps, axis=0))
        correction = {"dx_mm": dx, "dy_mm": dy, "dphi_deg": dphi}
        shift = math.hypot(dx, dy)
        if shift > limits.max_correction_mm or abs(dphi) > limits.max_correction_deg:
            reasons.append(f"at the taught pose the model wants to move {shift:.2f} mm / "
                           f"{dphi:+.2f} deg (limits {limits.max_correction_mm:g} mm / "
                           f"{limits.max_correction_deg:g} deg)")
    score = None
    if ref is not None:
        score = float(np.mean([similarity(image, ref[0]) for image in images]))
        if score < limits.min_similarity:
            reasons.append(f"the view at the taught pose no longer looks like the training "
                           f"images (similarity {score:.3f} < {limits.min_similarity:g})")
    fired = bool(reasons)
    if fired:
        message = ("the camera or the part has changed since teach-in: " + "; ".join(reasons)
                   + ". The cell needs a new teach-in (teach, acquire, train) before it "
                   "positions again.")
    else:
        message = "the camera and the part are as taught"
        if ref is None:
            message += " (correction checked; no acquired set stored for the appearance)"
    result = SelfCheckResult(fired, reasons, correction, score, limits, len(images), message,
                             ref[1] if ref is not None else None)
    (logger.error if fired else logger.info)("self-check: %s", message)
    return result


def run_self_check(fp, system: str = "gabor") -> SelfCheckResult:
    """The service's start-up check: ``self_check`` with the default limits (the caller
    refuses to position while ``fired``)."""
    return self_check(fp, system)
