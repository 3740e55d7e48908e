"""Training the Hough system from the NN1 and NN2 image sets (paper sections 2.3 and 4.3).

1. The shared front end (normalisation, threshold, localisation).
2. Edge thresholds: fractions of the median gradient on the training outlines.
3. The constellation model: lines of every training image, constellations under a loose prior
   scaled by the part's size, tolerances learned from them.
4. The angle map: the outline angles of the NN2 set against its labelled rotations.
5. The PSOM: a dx x dy x 3 grid of nodes (3 x 3 x 3 on the paper's grid) from the NN1 set:
   every dx and dy level and the three rotation levels nearest -2/3, 0, +2/3 of 180/kappa;
   each node embeds its image's object centroid, its labelled rotation and its labelled
   (dx, dy). The object must be located in every node image.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Mapping
from typing import Literal

import numpy as np

from calibration_free.baselines.grid import grid_indices
from calibration_free.baselines.hough.angle_map import fit_angle_map
from calibration_free.baselines.hough.constellation import (
    Constellation,
    ConstellationModel,
    find_constellation,
    learn_model,
    pair_count,
    prior_model,
)
from calibration_free.baselines.hough.edges import outline_gradient, silhouette
from calibration_free.baselines.hough.model import (
    PSOM_INPUTS,
    EdgeSettings,
    HoughConfig,
    HoughModel,
    find_outline,
)
from calibration_free.baselines.hough.psom import PSOM
from calibration_free.dataset import Dataset
from calibration_free.errors import TrainingError
from calibration_free.localise import Localisation, Polarity
from calibration_free.training import PreparedSets, check_part, prepare_training
from drivers.core.errors import ConfigError
from drivers.core.pose import Pose

logger = logging.getLogger(__name__)

# PSOM rotation nodes: the grid levels nearest these fractions of 180/kappa.
PHI_NODE_FRACTIONS = (-2.0 / 3.0, 0.0, 2.0 / 3.0)


def _phi_levels(levels: np.ndarray, kappa: int) -> list[int]:
    """Indices of the rotation levels used as PSOM nodes (distinct, increasing)."""
    half = 180.0 / kappa
    picked = sorted({int(np.argmin(np.abs(levels - f * half))) for f in PHI_NODE_FRACTIONS})
    if len(picked) < 2:
        raise TrainingError(f"the NN1 grid has rotation levels {levels.round(1).tolist()}; the "
                            f"PSOM needs at least two distinct ones")
    return picked


def _edge_settings(prep: PreparedSets, config: HoughConfig) -> EdgeSettings:
    """Canny thresholds from the median outline gradient of the NN2 images; the least edge
    points of a line from the part's size."""
    images = [prep.normalised["nn2"][i] for i in prep.usable["nn2"]]
    gradient = float(np.median([
        outline_gradient(n, silhouette(n, prep.front.threshold, prep.front.polarity, u, v),
                         config.blur_sigma_px)
        for n, (u, v) in zip(images, prep.centres("nn2"), strict=True)]))
    if not gradient > 0:
        raise TrainingError("the training outlines show no contrast; check the scene")
    return EdgeSettings(config.edge_low * gradient, config.edge_high * gradient,
                        config.min_line_fraction * math.sqrt(prep.front.expected_area_px))


def _psom(labels: np.ndarray, locs: list[Localisation], kappa: int) \
        -> tuple[PSOM, list[float]]:
    """The translation PSOM on the NN1 grid, and the rotation levels of its nodes."""
    idx, levels = grid_indices(labels)
    phi_nodes = _phi_levels(levels[2], kappa)
    shape = (levels[0].size, levels[1].size, len(phi_nodes))
    weights = np.full((*shape, 5), np.nan)
    missing = []
    for k, (ix, iy, ip) in enumerate(idx):
        if ip not in phi_nodes:
            continue
        if not locs[k].ok:
            missing.append(labels[k].round(1).tolist())
            continue
        dx, dy, dphi = labels[k]
        weights[ix, iy, phi_nodes.index(ip)] = [locs[k].u_px, locs[k].v_px, dphi, dx, dy]
    if missing:
        raise TrainingError(f"nn1: the object was not located in {len(missing)} of "
                            f"{int(np.prod(shape))} PSOM node images (labels {missing})")
    inputs = weights[..., list(PSOM_INPUTS)].reshape(-1, len(PSOM_INPUTS))
    psom = PSOM(tuple(np.arange(n, dtype=np.float64) for n in shape), weights, PSOM_INPUTS,
                np.maximum(inputs.std(axis=0), 1e-6))
    return psom, [float(levels[2][i]) for i in phi_nodes]


def train_hough(nn1_data: Dataset, nn2_data: Dataset, *, object_kind: str, kappa: int,
                nominal_pose: Pose | Mapping[str, float], config: HoughConfig | None = None,
                polarity: Polarity | Literal["auto"] = "auto") -> HoughModel:
    """Train the Hough system.

    Args:
        nn1_data: the translation set, a grid (paper: 3x3x7, a = 25 mm); its dx, dy levels and
            three rotation levels become the PSOM's nodes.
        nn2_data: the rotation set (paper: 3x3x7 grid, a = 5 mm, b = 180/kappa deg).
        object_kind, kappa, nominal_pose: what is taught (kappa even, >= 4).
        config: the Hough system's settings; None is HoughConfig().
        polarity: "bright", "dark" or "auto" (``training.prepare_training``).

    Raises:
        TrainingError: bad arguments or images, an odd kappa, no training outline, a valid
            outline in fewer than half of the NN2 images, NN1 labels that are not a grid, or
            a PSOM node image where the object is not located.
    """
    start = time.perf_counter()
    config = config or HoughConfig()
    pose = check_part(object_kind, kappa, nominal_pose)
    try:
        pairs = pair_count(kappa)
    except ConfigError as exc:
        raise TrainingError(str(exc)) from exc
    sets = {"nn1": nn1_data, "nn2": nn2_data}
    prep = prepare_training(sets, polarity)
    front, locs = prep.front, prep.found
    settings = _edge_settings(prep, config)

    model, found = _constellations(prep, config, settings, kappa, pairs)
    rot = [i for i, c in enumerate(found["nn2"]) if c is not None]
    if len(rot) < max(4, len(found["nn2"]) // 2):
        raise TrainingError(f"nn2: a valid outline in only {len(rot)} of {len(found['nn2'])} "
                            f"images; the Hough system needs clear straight edges")
    amap = fit_angle_map([found["nn2"][i].angle_deg for i in rot], nn2_data.labels[rot, 2],
                         kappa, config.angle_harmonics)
    residual = [(amap(found["nn2"][i].angle_deg) - nn2_data.labels[i, 2] + 180.0 / kappa)
                % (360.0 / kappa) - 180.0 / kappa for i in rot]

    # the PSOM's nodes are the grid's images: frames taken at the taught pose before the grid
    # (``metadata["taught_frames"]``) are not nodes
    first_node = int(nn1_data.metadata.get("taught_frames", 0))
    psom, phi_levels = _psom(nn1_data.labels[first_node:], locs["nn1"][first_node:], kappa)

    training = {
        "samples": {name: len(d) for name, d in sets.items()},
        "images": len(nn1_data) + len(nn2_data),
        "located": {name: int(sum(loc.ok for loc in locs[name])) for name in sets},
        "outlines": {name: int(sum(c is not None for c in found[name])) for name in sets},
        "edge_thresholds": [settings.low, settings.high],
        "angle_map_rms_deg": float(np.sqrt(np.mean(np.square(residual)))),
        "psom_nodes": list(psom.weights.shape[:-1]),
        "psom_phi_levels_deg": phi_levels,
        "preprocess_seconds": prep.seconds,
        "seconds": time.perf_counter() - start,
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    logger.info("trained hough model for %s in %.2f s (outlines in %d/%d nn1 and %d/%d nn2 "
                "images, angle map RMS %.2f deg)", object_kind, training["seconds"],
                training["outlines"]["nn1"], len(nn1_data), training["outlines"]["nn2"],
                len(nn2_data), training["angle_map_rms_deg"])
    return HoughModel(object_kind=object_kind, kappa=kappa, nominal_pose=pose, front=front,
                      config=config, edge_settings=settings, constellation=model,
                      angle_map=amap, psom=psom, training=training)


def _constellations(prep, config: HoughConfig, settings, kappa: int, pairs: int):
    """The constellation model learnt from the training outlines (first matched against the
    part's prior model), and each training image's constellation under it (None where its
    outline is not found)."""
    front, locs = prep.front, prep.found
    sets = prep.found.keys()
    outlines = {name: [find_outline(n, front, loc, config, settings, 2 * pairs)
                       if loc.ok else None
                       for n, loc in zip(prep.normalised[name], locs[name], strict=True)]
                for name in sets}

    def constellations(model: ConstellationModel) -> dict[str, list[Constellation | None]]:
        return {name: [find_constellation(o.lines, model, (loc.u_px, loc.v_px))[0]
                       if o is not None else None
                       for o, loc in zip(outlines[name], locs[name], strict=True)]
                for name in sets}

    first = constellations(prior_model(kappa, math.sqrt(front.expected_area_px)))
    model = learn_model([c for cs in first.values() for c in cs if c is not None], kappa,
                        width_margin=config.width_margin,
                        angle_margin_deg=config.angle_margin_deg,
                        vote_fraction=config.line_vote_fraction)
    found = constellations(model)
    return model, found
