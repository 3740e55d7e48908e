"""Automatic acquisition of training and test images around the taught nominal pose.

For each displacement (dx, dy, dphi) of a grid (or a random set), the arm is moved to the
nominal pose displaced by -(dx, dy, dphi) in its tool frame, an image is grabbed, and the
label is the exact tool-frame step from the pose actually reached back to the nominal pose
(so the arm's repeatability error is in the label, not in the network). Grids are visited in
serpentine order so consecutive moves stay short.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

import numpy as np
from tqdm import tqdm

from calibration_free.dataset import (
    Dataset,
    grid_offsets,
    random_offsets,
    staggered_grid_offsets,
)
from drivers.camera.settle import settled_frame
from drivers.core.pose import Pose, ToolStep
from drivers.interfaces import Arm, Camera
from drivers.safety import SafetyLimits, split_target

logger = logging.getLogger(__name__)

# Each frame at the taught pose is taken after the arm left the pose by this much (mm) and
# came back: a move of its own, so each frame carries its own repeatability error.
TAUGHT_APPROACH_MM = 1.0


def serpentine(offsets: np.ndarray) -> np.ndarray:
    """Order displacements so each move to the next one is short (boustrophedon on x, y)."""
    offsets = np.asarray(offsets, dtype=float)
    xs = np.unique(offsets[:, 0])
    ordered = []
    for i, x in enumerate(xs):
        row = offsets[offsets[:, 0] == x]
        row = row[np.lexsort((row[:, 2], row[:, 1]))]
        ordered.append(row if i % 2 == 0 else row[::-1])
    return np.concatenate(ordered)


def transfer(arm: Arm, target: Pose, limits: SafetyLimits | None) -> None:
    """Move to ``target`` in segments within the step limits (``drivers.safety.split_target``;
    None: one move)."""
    for pose in split_target(arm.pose(), target, limits):
        arm.move_to(pose)


def acquire(arm: Arm, camera: Camera, nominal: Pose, offsets: np.ndarray, *,
            name: str, metadata: dict | None = None, limits=None,
            ground_truth: Callable[[], tuple[float, float, float]] | None = None,
            progress: bool = True, taught_frames: int = 0) -> Dataset:
    """Grab one image per displacement; returns the labelled dataset and returns to nominal.

    ``taught_frames``: that many frames are first grabbed at ``nominal`` itself, before the
    displacements, each after its own approach: the arm leaves the pose by
    ``TAUGHT_APPROACH_MM``, each frame towards another side, and comes back. The loop settles
    at the taught pose, but NN1's grid has one image there (NN1's zero was pinned on that one
    frame's camera noise) and NN2's staggered grid none (``calibration_free.training``).
    Every move ends off its target by the arm's repeatability error, which the camera on the
    gripper sees (a tilt of 0.02 deg moves the image of the part about 0.03 mm); frames taken
    after one approach share one such error, and NN1's zero pinned on them keeps it; after
    separate approaches their mean averages it. The set's metadata
    ``taught_frames`` says how many come first (the Hough system's PSOM takes the grid's
    images only). The camera's exposure first settles (``drivers.camera.settle``)."""
    images, labels, truth = [], [], []
    t0 = time.perf_counter()
    settled_frame(camera)  # every image of the set exposed alike
    if taught_frames > 0:
        transfer(arm, nominal, limits)
        for i in range(taught_frames):
            side = math.radians(360.0 * i / taught_frames)
            arm.move_to(nominal.moved_in_tool_frame(ToolStep(
                TAUGHT_APPROACH_MM * math.cos(side), TAUGHT_APPROACH_MM * math.sin(side))))
            arm.move_to(nominal)
            back = arm.pose().tool_step_to(nominal)
            images.append(camera.grab().image)
            labels.append((back.dx_mm, back.dy_mm, back.dphi_deg))
            if ground_truth is not None:
                truth.append(ground_truth())
    # disable=None: tqdm draws only when stderr is a terminal (no \r spam in logs)
    for dx, dy, dphi in tqdm(offsets, desc=f"acquire {name}", unit="img",
                             disable=None if progress else True, leave=False):
        target = nominal.moved_in_tool_frame(ToolStep(-dx, -dy, 0.0, -dphi))
        transfer(arm, target, limits)
        reached = arm.pose()
        images.append(camera.grab().image)
        back = reached.tool_step_to(nominal)
        labels.append((back.dx_mm, back.dy_mm, back.dphi_deg))
        if ground_truth is not None:
            truth.append(ground_truth())
    transfer(arm, nominal, limits)
    meta = {"set": name, "count": len(labels), "taught_frames": max(taught_frames, 0),
            "seconds": time.perf_counter() - t0,
            "nominal_pose": nominal.as_dict(), **(metadata or {})}
    samples = ([{"ground_truth_error": [float(v) for v in t]} for t in truth]
               if truth else None)
    logger.info("acquired %d images for %s in %.1f s", len(labels), name, meta["seconds"])
    return Dataset(images=np.stack(images), labels=np.asarray(labels, dtype=np.float64),
                   samples=samples, metadata=meta)


def grid_for(grid_cfg, kappa: int) -> np.ndarray:
    """The displacement grid of a GridConfig (b = 180/kappa unless set; its rotations
    staggered over the positions if ``staggered``), serpentine ordered."""
    b = grid_cfg.b_deg if grid_cfg.b_deg is not None else 180.0 / max(kappa, 1)
    offsets = staggered_grid_offsets if getattr(grid_cfg, "staggered", False) else grid_offsets
    return serpentine(offsets(grid_cfg.a_mm, b, tuple(grid_cfg.shape)))


def random_set(rng: np.random.Generator, n: int, a_mm: float, kappa: int) -> np.ndarray:
    """``n`` random displacements (dx_mm, dy_mm, dphi_deg), uniform in +/-a_mm and +/-180/kappa deg.

    Returns:
        An (n, 3) array, in drawing order (not serpentine).

    Raises:
        DatasetError: n < 1 or a_mm < 0.
    """
    return random_offsets(rng, n, a_mm, 180.0 / max(kappa, 1))
