"""The Fig. 5 filter sets: names, geometry, selection."""

from __future__ import annotations

import pytest

from calibration_free.gabor import GaborBank, GaborConfig
from controller.evaluation.comparison.filter_sets import (
    FILTER_SETS,
    PAPER_SET,
    grid_centres_px,
    orientations_deg,
    select_sets,
)
from drivers.core.errors import ConfigError


def test_the_paper_set_is_the_default_bank():
    assert FILTER_SETS[PAPER_SET] == GaborConfig()


def test_grids_are_centred_with_12_px_spacing():
    assert grid_centres_px(1) == (25.0,)
    assert grid_centres_px(2) == (19.0, 31.0)
    assert grid_centres_px(4) == (7.0, 19.0, 31.0, 43.0)
    assert orientations_deg(8)[1] == 22.5 and len(orientations_deg(2)) == 2


def test_every_set_builds_a_bank_of_its_feature_count():
    assert 12 <= len(FILTER_SETS) <= 20
    for name, config in FILTER_SETS.items():
        grid, rest = name.split("x", 1)
        assert config.n_filters == int(grid) ** 2 * int(rest.split("x")[1].split("-")[0])
        assert GaborBank(config).n_features == config.n_filters
    kinds = {c.kind for c in FILTER_SETS.values()}
    assert kinds == {"even", "odd", "magnitude"}


def test_select_sets_keeps_order_and_rejects_unknown_names():
    names = ["1x1x4-l30-s12.5-even", PAPER_SET]
    assert list(select_sets(names)) == names
    assert len(select_sets(None)) == len(FILTER_SETS)
    with pytest.raises(ConfigError, match="unknown filter set '5x5'"):
        select_sets(["5x5"])
