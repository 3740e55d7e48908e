"""Training the PCA system from the NN1 and NN2 image sets (paper sections 2.2 and 4.2).

Shared front end (normalisation, threshold, localisation), NN1 as in the Gabor system, then the
eigenimages of the NN2 images' ROIs (SVD of the centred data matrix) and the B-spline fuzzy
controller fitted by penalised least squares from the projections to (sin, cos) of kappa dphi.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from typing import Literal

import numpy as np

from calibration_free import angles
from calibration_free.baselines.pca.eigenimages import fit_eigenimages, roi_vector
from calibration_free.baselines.pca.fuzzy_controller import fit_fuzzy_controller
from calibration_free.baselines.pca.model import PcaConfig, PcaModel
from calibration_free.dataset import Dataset
from calibration_free.localise import Polarity
from calibration_free.mlp import train_mlp
from calibration_free.roi import extract_roi
from calibration_free.training import (
    NN1_EPOCHS,
    NN1_HIDDEN,
    check_part,
    nn1_samples,
    prepare_training,
    training_sets,
)
from drivers.core.pose import Pose

logger = logging.getLogger(__name__)


def train_pca(nn1_data: Dataset, nn2_data: Dataset, *, object_kind: str, kappa: int,
              nominal_pose: Pose | Mapping[str, float], config: PcaConfig | None = None,
              seed: int = 0, nn1_extra: Dataset | None = None,
              polarity: Polarity | Literal["auto"] = "auto") -> PcaModel:
    """Train the PCA system.

    Args:
        nn1_data: NN1's set (paper: 3x3x7 grid, a = 25 mm).
        nn2_data: the rotation set (paper: 3x3x7 grid, a = 5 mm, b = 180/kappa deg).
        object_kind, kappa, nominal_pose: what is taught.
        config: eigenimages and fuzzy controller settings; None is PcaConfig().
        seed: seeds NN1.
        nn1_extra: more (u, v) -> (dx, dy) samples for NN1 (as the Gabor system: the NN2 set).
        polarity: "bright", "dark" or "auto" (``training.prepare_training``).

    Raises:
        TrainingError: bad arguments or images (see ``training.prepare_training``), m larger
            than the rank of the ROIs, or a projection that does not vary.
    """
    start = time.perf_counter()
    config = config or PcaConfig()
    pose = check_part(object_kind, kappa, nominal_pose)
    sets = training_sets(nn1_data, nn2_data, nn1_extra)
    prep = prepare_training(sets, polarity)
    uv, labels = nn1_samples(sets, prep)
    nn1 = train_mlp(uv, np.ascontiguousarray(labels[:, :2]), NN1_HIDDEN, seed=seed,
                    epochs=NN1_EPOCHS)

    t_pca = time.perf_counter()
    vectors = np.stack([roi_vector(extract_roi(prep.normalised["nn2"][i], u, v, config.roi_px))
                        for i, (u, v) in zip(prep.usable["nn2"], prep.centres("nn2"),
                                             strict=True)])
    eigen = fit_eigenimages(vectors, config.eigenimages)
    features = eigen.project(vectors)
    pca_seconds = time.perf_counter() - t_pca

    t_fc = time.perf_counter()
    s, c = angles.encode(nn2_data.labels[prep.usable["nn2"], 2], kappa)
    targets = np.stack([s, c], axis=1)
    controller = fit_fuzzy_controller(features, targets, n_sets=config.fuzzy_sets,
                                      order=config.fuzzy_order, smoothing=config.smoothing)
    fit_rms = float(np.sqrt(np.mean((controller(features) - targets) ** 2)))
    fc_seconds = time.perf_counter() - t_fc

    training = {
        "seed": seed,
        "samples": {name: len(d) for name, d in sets.items()},
        "images": len(nn1_data) + len(nn2_data),
        "skipped": {name: len(sets[name]) - int(prep.usable[name].size) for name in sets},
        "preprocess_seconds": prep.seconds,
        "nn1": {"layers": list(nn1.model.layer_sizes), "seconds": nn1.seconds,
                "epochs": len(nn1.loss_curve), "final_loss": nn1.loss_curve[-1]},
        "pca": {"seconds": pca_seconds, "rois": int(vectors.shape[0]),
                "explained_variance": eigen.explained_variance},
        "fuzzy": {"seconds": fc_seconds, "rules": controller.n_rules, "fit_rms": fit_rms},
        "seconds": time.perf_counter() - start,
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    logger.info("trained pca model for %s in %.2f s (%d eigenimages hold %.0f%% of the "
                "variance, %d rules, fit RMS %.3f)", object_kind, training["seconds"],
                eigen.m, 100 * eigen.explained_variance, controller.n_rules, fit_rms)
    return PcaModel(object_kind=object_kind, kappa=kappa, nominal_pose=pose, front=prep.front,
                    config=config, nn1=nn1.model, eigen=eigen, controller=controller,
                    training=training)
