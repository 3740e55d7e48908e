"""``finepos evaluate --teach-lighting``: the model is taught, acquired and trained under that
light (a cell taught in the light it works in), the trials run in theirs."""

from __future__ import annotations

import json

import pytest

from controller import cli
from controller.evaluation import trials
from tests.controller.evaluation.test_parts_table import SMALL_GRIDS


@pytest.mark.parametrize("extra,message", [
    (["--model", "model-gabor.fpm"], "--teach-lighting: not with --model"),
    (["--mounts", "2"], "--teach-lighting: not with --mounts"),
])
def test_teach_lighting_is_refused_where_nothing_is_taught_here(extra, message, capsys):
    assert cli.main(["evaluate", "--teach-lighting", "poor", "--trials", "1", *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_a_model_file_cannot_be_taught_again():
    with pytest.raises(trials.FineposError, match="trained already"):
        trials.evaluate("gabor", None, trials=1, seed=1, model_path="model-gabor.fpm",
                        teach_lighting="poor")


@pytest.mark.slow
def test_the_cell_is_taught_in_one_light_and_tested_in_another(tmp_path, capsys, monkeypatch):
    opened = []
    real = trials.open_devices

    def recording(config, **kwargs):
        opened.append(config.scene.lighting.preset)
        return real(config, **kwargs)

    monkeypatch.setattr(trials, "open_devices", recording)
    config = tmp_path / "grids.yaml"
    config.write_text(json.dumps(SMALL_GRIDS))
    assert cli.main(["evaluate", "--config", str(config), "--teach-lighting", "poor",
                     "--lighting", "good", "--trials", "2", "--no-grasp", "--quiet"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert opened == ["poor", "good"]  # teach-in, acquisition, training; then the trials
    assert report["teach_lighting"] == "poor" and report["lighting"] == "good"
    assert sum(report["outcomes"].values()) == 2
