"""Perception's named stages (``calibration_free.stages``): which run, and a stage named
without its trained data refused in one line at load and at training."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calibration_free.errors import BundleError, TrainingError
from calibration_free.perception import Perception
from calibration_free.synthetic import render
from calibration_free.training import TrainingSettings, train_bundle
from tests.calibration_free.conftest import KAPPA, NOMINAL_POSE


def test_unnamed_stages_are_those_whose_data_the_model_has(bundle):
    optional = Perception(bundle).optional
    assert bundle.axis is None and optional.axis is None and optional.ends is None
    assert (optional.outline is not None) == bool(bundle.front.outlines)


def test_a_stage_left_out_is_skipped_and_the_rest_reads_as_before(bundle, cell):
    frame = render(cell, np.array([1.0, -2.0, 10.0]), np.random.default_rng(4))
    without = Perception(bundle, stages=())
    assert without.optional.outline is None
    whole, skipped = Perception(bundle).perceive(frame), without.perceive(frame)
    assert skipped.full_mm == whole.full_mm and skipped.dphi_deg == whole.dphi_deg


def test_a_stage_named_without_its_data_is_refused_in_one_line(bundle):
    with pytest.raises(BundleError, match=r"^perception\.stages: axis: the model has no axis "
                                          r"map[^\n]*$"):
        Perception(bundle, stages=("axis",))
    with pytest.raises(BundleError, match=r"^perception\.stages: ends: "):
        dataclasses.replace(bundle, training={**bundle.training, "stages": ["ends"]})


def test_a_model_keeps_its_stage_list_and_runs_it(bundle):
    named = dataclasses.replace(bundle, training={**bundle.training, "stages": []})
    assert Perception(named).optional.outline is None


def test_training_refuses_a_stage_the_part_cannot_have(grids):
    nn1_data, nn2_data = grids
    settings = TrainingSettings(seed=0, localisation_channel="max", nn1_epochs=20,
                                nn2_epochs=20, stages=("outline", "axis"))
    with pytest.raises(TrainingError, match=r"^cube: perception\.stages: axis: [^\n]*$"):
        train_bundle(nn1_data, nn2_data, object_kind="cube", kappa=KAPPA,
                     nominal_pose=NOMINAL_POSE, nn1_extra=nn2_data, settings=settings)
