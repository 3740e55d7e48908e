"""The Fig. 5 experiment: which Gabor filter set gives the most accurate fine positioning.

Every filter set (``filter_sets``) is trained and evaluated ``repeats`` times; repeat r uses
seed + r for the networks' initial weights, the open-loop test set and the closed-loop
placements, the same for every set, so sets are compared on identical trials (paired).

1. Acquire the NN1 and NN2 training grids once, on the default scene (the images do not depend
   on the filter bank).
2. Per repeat (parallel jobs): train the paper's system (NN1, normalisation, localisation and
   the paper's NN2) with that repeat's seed; cut the 50x50 ROIs of the NN2 training images; and
   acquire a random open-loop test set near the nominal pose (NN2's domain: +/-a of the NN2
   grid, +/-180/kappa deg), cutting its ROIs.
3. Per set and repeat (parallel jobs): train NN2 on the set's features of the stored ROIs
   (exactly what ``train_bundle`` would do with that bank: same ROIs, same seed, same settings;
   NN1 and the localisation are shared), then measure (a) the open-loop rotation RMS on the
   repeat's test set and (b) the whole system in closed loop: ``trials`` random placements on
   the config's scene, RMS after 2.5 loops (the paper's Table-1 budget), no grasp.

Sets are ranked by the closed-loop angle RMS after 2.5 loops (the filters only feed the
rotation network), averaged over repeats.
"""

from __future__ import annotations

import dataclasses
import logging
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibration_free import angles, training
from calibration_free.dataset import Dataset, random_offsets
from calibration_free.gabor import GaborBank, GaborConfig
from calibration_free.perception import Perception
from controller.devices import open_devices
from controller.evaluation.comparison.pools import Tick, open_pool
from controller.evaluation.metrics import is_safe, state_at
from controller.evaluation.trials import default_scene_config, run_trials
from controller.fine_positioner import FinePositioner
from controller.loop.checks import STOPPED
from controller.systems.base import TrainedModel
from controller.systems.gabor import GaborSystem
from controller.teach.acquisition import acquire, transfer
from drivers.core.cell_state import CellState
from drivers.core.errors import FineposError

logger = logging.getLogger(__name__)

SEARCH_BUDGET = 2.5  # loops: the closed-loop runs stop here; the RMS is taken here


@dataclass(frozen=True)
class RoiSet:
    """Normalised 50x50 ROIs of a dataset's images where the object was found, and their
    rotation labels (deg); ``missed`` images had no object found and are left out."""

    rois: np.ndarray
    dphi_deg: np.ndarray
    missed: int


@dataclass(frozen=True)
class RepeatData:
    """What every filter set of one repeat shares: the base model (NN1, normalisation,
    localisation, the paper's NN2), the training ROIs and the open-loop test ROIs."""

    repeat: int
    seed: int
    base: TrainedModel
    train: RoiSet
    test: RoiSet


@dataclass(frozen=True)
class SetRun:
    """One filter set in one repeat.

    Attributes:
        name: the filter set's name.
        repeat, seed: which repeat, and its seed.
        feature_count: features the bank produces.
        nn2_seconds: NN2's training time.
        open_loop_phi_rms_deg: NN2's rotation RMS on the repeat's random test set.
        closed_rms: RMS (x mm, y mm, phi deg) after SEARCH_BUDGET loops over the trials.
        safe_rate: share of trials safe to grasp after SEARCH_BUDGET loops.
        failures: trials that stopped without success (no object, ambiguous, rejected).
    """

    name: str
    repeat: int
    seed: int
    feature_count: int
    nn2_seconds: float
    open_loop_phi_rms_deg: float
    closed_rms: tuple[float, float, float]
    safe_rate: float
    failures: int


@dataclass
class SearchResult:
    """The whole search: its settings, every run, and what it cost."""

    sets: dict[str, GaborConfig]
    runs: list[SetRun]
    repeats: int
    trials: int
    seed: int
    test_images: int
    workers: int
    wall_seconds: float
    source: str


@dataclass(frozen=True)
class _RepeatJob:
    repeat: int
    seed: int
    nn1: Dataset
    nn2: Dataset
    state: CellState
    config: object


@dataclass(frozen=True)
class _SetJob:
    name: str
    gabor: GaborConfig
    data: RepeatData
    config: object
    trials: int


def roi_set(perception: Perception, data: Dataset, roi_px: int) -> RoiSet:
    """The ROIs of ``data``'s images as the trained system cuts them (normalised, centred on
    the located object)."""
    rois, labels, missed = [], [], 0
    for image, label in zip(data.images, data.labels, strict=True):
        normalised, loc = perception.locate(image)
        if not loc.ok:
            missed += 1
            continue
        rois.append(perception.bundle.front.feature_roi(normalised, loc, roi_px))
        labels.append(label[2])
    return RoiSet(np.stack(rois), np.asarray(labels, dtype=float), missed)


def acquire_training_grids(config, seed: int, work_dir: Path,
                           progress: bool) -> tuple[Dataset, Dataset, CellState]:
    """Teach (auto) and acquire the NN1 and NN2 grids on the default scene."""
    train_cfg = default_scene_config(config)
    with open_devices(train_cfg, seed=seed) as devices:
        fp = FinePositioner(devices, train_cfg, state_dir=work_dir)
        state = fp.teach_auto()
        return fp.acquire("nn1", progress=progress), fp.acquire("nn2", progress=progress), state


def _test_set(config, state: CellState, seed: int) -> Dataset:
    """Random displacements in NN2's domain around the nominal pose, on the default scene."""
    train_cfg = default_scene_config(config)
    acq = train_cfg.controller.acquisition
    b_deg = acq.nn2.b_deg if acq.nn2.b_deg is not None else 180.0 / state.kappa
    offsets = random_offsets(np.random.default_rng(seed), acq.test_count, acq.nn2.a_mm, b_deg)
    limits = train_cfg.safety
    with open_devices(train_cfg, seed=seed) as devices:
        transfer(devices.arm, state.nominal_pose, limits)
        return acquire(devices.arm, devices.camera, state.nominal_pose, offsets, name="test",
                       limits=limits, progress=False)


def prepare_repeat(job: _RepeatJob, tick: Tick) -> RepeatData:
    """Stage 2: the base model, training ROIs and test ROIs of one repeat."""
    perception_cfg = dataclasses.replace(job.config.perception, seed=job.seed)
    base = GaborSystem.train(job.nn1, job.nn2, job.state, perception_cfg)
    perception = Perception(base.model)
    roi_px = base.model.gabor.roi_px
    test = _test_set(job.config, job.state, job.seed)
    return RepeatData(job.repeat, job.seed, base, roi_set(perception, job.nn2, roi_px),
                      roi_set(perception, test, roi_px))


def train_nn2(data: RepeatData, gabor: GaborConfig, perception_cfg) -> TrainedModel:
    """The repeat's base model with NN2 retrained on ``gabor``'s features of the stored ROIs.

    NN2 is trained by ``calibration_free.training.train_nn2``, the recipe ``train_bundle``
    uses, with the repeat's seed and the config's hidden sizes and weight decay.

    Args:
        data: the repeat (its base model, seed and training ROIs).
        gabor: the filter bank to train on.
        perception_cfg: the perception config (``nn2_hidden``, ``nn2_weight_decay``,
            ``nn2_widen_px``).

    Returns:
        The base model with ``gabor`` and the new NN2; its train_seconds are NN2's.
    """
    base = data.base.model
    nn2 = training.train_nn2(data.train.rois, data.train.dphi_deg, base.kappa, gabor,
                             seed=data.seed, hidden=tuple(perception_cfg.nn2_hidden),
                             weight_decay=perception_cfg.nn2_weight_decay,
                             widen_px=perception_cfg.nn2_widen_px)
    meta = {**base.training, "nn2": {"layers": list(nn2.model.layer_sizes),
                                     "seconds": nn2.seconds,
                                     "epochs": len(nn2.loss_curve),
                                     "final_loss": nn2.loss_curve[-1]}}
    bundle = dataclasses.replace(base, gabor=gabor, nn2=nn2.model, training=meta)
    return TrainedModel("gabor", bundle, nn2.seconds, data.base.train_images, gabor.n_filters)


def open_loop_rms_deg(model: TrainedModel, test: RoiSet) -> float:
    """RMS of NN2's rotation error on the test ROIs, wrapped to the symmetry period."""
    bundle = model.model
    bank = GaborBank(bundle.gabor)
    sc = np.stack([bundle.nn2(bank.features(roi)) for roi in test.rois])
    predicted = angles.decode(sc[:, 0], sc[:, 1], bundle.kappa)
    period = 360.0 / bundle.kappa
    error = (predicted - test.dphi_deg + period / 2) % period - period / 2
    return float(np.sqrt(np.mean(error**2)))


def evaluate_set(job: _SetJob, tick: Tick) -> SetRun:
    """Stage 3: train NN2 for one filter set in one repeat; open- and closed-loop accuracy."""
    model = train_nn2(job.data, job.gabor, job.config.perception)
    open_loop = open_loop_rms_deg(model, job.data.test)
    with tempfile.TemporaryDirectory(prefix="finepos-search-") as tmp:
        run = run_trials("gabor", model, job.config, job.trials, job.data.seed,
                         work_dir=Path(tmp), grasp=False, progress=False, budget=SEARCH_BUDGET,
                         on_trial=tick)
    finals = [state_at(t, SEARCH_BUDGET).error for t in run["states"]]
    rms = np.sqrt(np.mean(np.square(np.array(finals, dtype=float)), axis=0))
    failures = sum(o in STOPPED for o in run["outcomes"])
    return SetRun(job.name, job.data.repeat, job.data.seed, model.feature_count,
                  model.train_seconds, open_loop, tuple(float(v) for v in rms),
                  float(np.mean([is_safe(e) for e in finals])), failures)


def run_filter_search(config, sets: dict[str, GaborConfig], *, repeats: int, trials: int,
                      seed: int, workers: int, ray_address: str | None = None,
                      progress: bool = True) -> SearchResult:
    """Acquire once, prepare every repeat, then train and evaluate every set in every repeat.

    Args:
        config: the finepos config; closed-loop trials run on its scene.
        sets: filter sets by name (see ``filter_sets.select_sets``).
        repeats: repeats per set (seeds seed, seed + 1, ...).
        trials: closed-loop placements per set and repeat.
        seed: base seed (also seeds the training acquisition's simulated cell).
        workers: local parallel processes (1: in this process); ignored with ``ray_address``.
        ray_address: run the jobs on this Ray cluster ("auto", "local", "ray://host:10001").
        progress: show progress bars.

    Raises:
        FineposError: no sets, repeats or trials; ray is not installed when asked for.
    """
    if not sets or repeats < 1 or trials < 1:
        raise FineposError(f"filter search needs at least one set, repeat and trial (got "
                           f"{len(sets)}, {repeats}, {trials})")
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="finepos-search-train-") as tmp:
        nn1, nn2, state = acquire_training_grids(config, seed, Path(tmp), progress)
    repeat_jobs = [_RepeatJob(r, seed + r, nn1, nn2, state, config) for r in range(repeats)]
    set_count = len(sets) * repeats
    with open_pool(min(workers, set_count), ray_address) as pool:
        data = pool.run(prepare_repeat, repeat_jobs, desc="filter-search: repeats",
                        unit="repeat", progress=progress)
        set_jobs = [_SetJob(name, gabor, d, config, trials)
                    for d in data for name, gabor in sets.items()]
        runs = pool.run(evaluate_set, set_jobs, weights=[trials] * len(set_jobs),
                        desc="filter-search: sets", unit="trial", progress=progress)
        used_workers = pool.workers
    wall = time.perf_counter() - t0
    logger.info("filter search: %d sets x %d repeats x %d trials in %.1f s on %d workers",
                len(sets), repeats, trials, wall, used_workers)
    return SearchResult(dict(sets), runs, repeats, trials, seed,
                        config.controller.acquisition.test_count, used_workers, wall,
                        config.source)
