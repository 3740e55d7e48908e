"""Training the image-alignment servo from the NN1 and NN2 image sets.

The shared front end (the Gabor system's: channel, threshold, localisation), the template
from the frames at the taught pose, every usable image registered to it, then weighted least
squares from each registration to the image's label (the tool step back to the taught pose).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Mapping
from typing import Literal

import cv2
import numpy as np

from calibration_free.baselines.align.model import (
    XY_TERMS,
    AlignConfig,
    AlignModel,
    phi_basis,
    xy_basis,
)
from calibration_free.baselines.align.register import Template, wrap_deg
from calibration_free.dataset import Dataset
from calibration_free.errors import TrainingError
from calibration_free.localise import Polarity
from calibration_free.preprocess import Channel
from calibration_free.training import (
    at_taught_pose,
    check_part,
    prepare_training,
    training_sets,
)
from drivers.core.pose import Pose

logger = logging.getLogger(__name__)


def train_align(nn1_data: Dataset, nn2_data: Dataset, *, object_kind: str, kappa: int,
                nominal_pose: Pose | Mapping[str, float], config: AlignConfig | None = None,
                polarity: Polarity | Literal["auto"] = "auto",
                localisation_channel: Channel | Literal["auto"] = "auto") -> AlignModel:
    """Train the image-alignment servo.

    Args:
        nn1_data: the translation set (3x3x7 grid, a = 25 mm, frames at the taught pose first).
        nn2_data: the rotation set (3x3x7 grid, a = 5 mm, b = 180/kappa deg).
        object_kind, kappa, nominal_pose: what is taught.
        config: the servo's settings; None is AlignConfig().
        polarity: "bright", "dark" or "auto" (``training.prepare_training``).
        localisation_channel: as for the Gabor system (``train_bundle``).

    Raises:
        TrainingError: bad arguments or images (``training.prepare_training``), no frame at
            the taught pose, or too few images registered for the fit.
    """
    start = time.perf_counter()
    config = config or AlignConfig()
    pose = check_part(object_kind, kappa, nominal_pose)
    sets = training_sets(nn1_data, nn2_data)
    prep = prepare_training(sets, polarity, localisation_channel)
    samples = [(name, int(i)) for name in sets for i in prep.usable[name]]
    labels = np.array([sets[name].labels[i] for name, i in samples])
    at_nominal = at_taught_pose(labels)
    if not at_nominal.any():
        raise TrainingError("align: no training image at the taught pose to take the "
                            "template from")
    nominal_uv = tuple(float(v) for v in np.mean(
        [(prep.found[name][i].u_px, prep.found[name][i].v_px)
         for (name, i), here in zip(samples, at_nominal, strict=True) if here], axis=0))
    front = dataclasses.replace(prep.front, nominal_uv_px=nominal_uv)

    def silhouette(name: str, i: int) -> np.ndarray:
        return front.feature_frame(prep.normalised[name][i], prep.found[name][i])

    taught = [(name, i) for (name, i), here in zip(samples, at_nominal, strict=True) if here]
    image, size = _template_image(prep, taught, silhouette, nominal_uv, config.margin_px)
    template = Template(image, kappa, config.scan_step_deg, config.ecc_iterations,
                        config.ecc_epsilon)
    regs = [template.register(silhouette(name, i), prep.found[name][i].u_px,
                              prep.found[name][i].v_px) for name, i in samples]
    phi, xy, fitted = _fit(regs, nominal_uv, labels, samples, at_nominal, kappa, config)
    model = AlignModel(object_kind=object_kind, kappa=kappa, nominal_pose=pose, front=front,
                       config=config, template=image, xy=xy, phi=phi.reshape(-1),
                       training={})
    residual = np.array([model.step(r) for r in regs]) - labels
    residual[:, 2] = [wrap_deg(d, 360.0 / kappa) for d in residual[:, 2]]
    near = ~np.array([name == "nn1" for name, _ in samples])
    training = {
        "samples": {name: len(d) for name, d in sets.items()},
        "images": len(nn1_data) + len(nn2_data),
        "skipped": {name: len(sets[name]) - int(prep.usable[name].size) for name in sets},
        "preprocess_seconds": prep.seconds,
        "template_px": size,
        "refined": int(sum(r.refined for r in regs)),
        "fitted": int(fitted.sum()),
        "fit_rms": {"all": np.sqrt(np.mean(residual[fitted] ** 2, axis=0)).tolist(),
                    "near": np.sqrt(np.mean(residual[near & fitted] ** 2, axis=0)).tolist()},
        "seconds": time.perf_counter() - start,
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    logger.info("trained align model for %s in %.2f s (template %d px, %d of %d refined, "
                "fit RMS near %s)", object_kind, training["seconds"], size,
                training["refined"], len(regs),
                ", ".join(f"{v:.3f}" for v in training["fit_rms"]["near"]))
    return dataclasses.replace(model, training=training)


def _template_image(prep, taught: list[tuple[str, int]], silhouette, nominal_uv: tuple,
                    margin_px: int) -> tuple[np.ndarray, int]:
    """The template: the mean silhouette of the frames at the taught pose, cut square around
    the taught position, the part's diagonal plus ``margin_px`` on each side; and its size."""
    extent = 0
    for name, i in taught:
        _, _, w, h = cv2.boundingRect(prep.found[name][i].part_mask)
        extent = max(extent, int(math.ceil(math.hypot(w, h))))
    size = extent + 2 * margin_px
    image = np.mean([cv2.getRectSubPix(silhouette(name, i), (size, size), nominal_uv)
                     for name, i in taught], axis=0).astype(np.float32)
    return image, size


def _fit(regs: list, nominal_uv: tuple, labels: np.ndarray, samples: list[tuple[str, int]],
         at_nominal: np.ndarray, kappa: int, config: AlignConfig
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The weighted least-squares maps from the registrations to the turn (``phi``) and to
    the translation (``xy``), and which registrations were fitted (correlation high enough).

    Raises:
        TrainingError: too few images registered well, or the image turn does not follow the
            tool's.
    """
    du = np.array([r.u_px for r in regs]) - nominal_uv[0]
    dv = np.array([r.v_px for r in regs]) - nominal_uv[1]
    angle = np.array([r.angle_deg for r in regs])
    weights = np.where(at_nominal, config.taught_weight,
                       np.where([name == "nn2" for name, _ in samples], config.near_weight, 1.0))
    correlation = np.array([r.correlation for r in regs])
    fitted = correlation >= config.min_correlation * np.median(correlation)
    weights = np.where(fitted, weights, 0.0)
    if fitted.sum() < 2 * XY_TERMS:
        raise TrainingError(f"align: only {int(fitted.sum())} of {len(samples)} images "
                            f"registered well enough for the fit; check the scene")
    # The image turn is read within one symmetry period of the template; a label may lie a
    # period away from it (the grid's end angles are the same view): each label is carried
    # to the period the image reads it in.
    period = 360.0 / kappa
    small = (np.abs(labels[:, 2]) < period / 4) & fitted
    slope = float(np.dot(angle[small], labels[small, 2]) / max(np.dot(angle[small],
                                                                       angle[small]), 1e-12))
    if abs(slope) < 0.1:
        raise TrainingError(f"align: the image turn does not follow the tool's (slope "
                            f"{slope:.3f}); check the scene")
    turn = labels[:, 2] + period * np.round((slope * angle - labels[:, 2]) / period)
    sw = np.sqrt(weights)[:, None]
    phi, *_ = np.linalg.lstsq(phi_basis(du, dv, angle, kappa) * sw, turn[:, None] * sw,
                              rcond=None)
    read = phi_basis(du, dv, angle, kappa) @ phi[:, 0]
    xy, *_ = np.linalg.lstsq(xy_basis(du, dv, read, kappa) * sw, labels[:, :2] * sw,
                             rcond=None)
    return phi, xy, fitted
