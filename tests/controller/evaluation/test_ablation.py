"""``finepos bench ablation``: the variants, their pairing with the whole method, the run."""

import json

import numpy as np
import pytest

from calibration_free.mlp import NumpyMLP
from calibration_free.perception import Perception
from calibration_free.synthetic import render
from calibration_free.training import TrainingSettings, train_bundle
from controller.cli import main
from controller.evaluation import ablation as ab
from controller.recipe import recipe_of_model
from tests.synthetic_scene import KAPPA, NOMINAL_POSE


@pytest.fixture(scope="module")
def bundle(grids):
    nn1_data, nn2_data = grids
    return train_bundle(nn1_data, nn2_data, object_kind="cube", kappa=KAPPA,
                        nominal_pose=NOMINAL_POSE, nn1_extra=nn2_data,
                        settings=TrainingSettings(seed=0, localisation_channel="auto"))


def test_mcnemar_p_is_the_exact_two_sided_binomial_tail():
    assert ab.mcnemar_p(0, 0) == 1.0
    assert ab.mcnemar_p(5, 0) == pytest.approx(2 / 32)
    assert ab.mcnemar_p(0, 6) == pytest.approx(2 / 64)
    assert ab.mcnemar_p(3, 3) == 1.0
    # 10 against 2: 2 * P(X <= 2), X ~ Bin(12, 1/2)
    assert ab.mcnemar_p(10, 2) == pytest.approx(2 * (1 + 12 + 66) / 4096)


def _rec(safe, visible=1.0):
    return {"safe_2.5": safe, "visible": visible}


def test_trials_are_paired_where_the_part_is_seen_and_judged_against_the_spread():
    whole = [_rec(True)] * 8 + [_rec(True, 0.5)] * 5 + [_rec(False)] * 2
    variant = [_rec(False)] * 8 + [_rec(False, 0.5)] * 5 + [_rec(False)] * 2
    out = ab.paired(whole, variant)
    assert out["trials"] == 10  # the 5 trials with half the part seen are left out
    assert (out["safe_only_whole"], out["safe_only_variant"]) == (8, 0)
    assert out["p_value"] == pytest.approx(2 / 256) and out["verdict"] == "the stage helps"
    out = ab.paired(variant, whole)
    assert out["verdict"] == "the stage hurts"
    few = ab.paired([_rec(True), _rec(False)], [_rec(False), _rec(True)])
    assert few["verdict"] == "within the spread"


def test_nn1_as_rot_reads_the_centre_alone_whatever_the_turn():
    rng = np.random.default_rng(0)
    nn1 = NumpyMLP([rng.normal(size=(3, 2)), rng.normal(size=(2, 3))],
                   [rng.normal(size=3), rng.normal(size=2)], np.array([90.0, 70.0]),
                   np.array([20.0, 15.0]), np.array([0.5, -0.2]), np.array([8.0, 6.0]))
    rot = ab.nn1_as_rot(nn1)
    for uv in rng.uniform(0.0, 190.0, size=(5, 2)):
        turn = rng.uniform(-np.pi, np.pi)
        np.testing.assert_allclose(rot(np.array([*uv, np.sin(turn), np.cos(turn)])),
                                   nn1(uv), rtol=1e-12, atol=1e-12)


def test_run_time_variants_leave_out_their_stage_and_nothing_else(bundle, cell):
    outline = ab.BY_NAME["no-outline"].edit(bundle)
    assert Perception(bundle).optional.outline is not None
    assert Perception(outline).optional.outline is None
    assert outline.nn1_rot is bundle.nn1_rot and outline.front is bundle.front
    # the cube has no long axis: the variant does not apply to it
    assert ab.BY_NAME["no-axis"].edit(bundle) is None
    assert ab.BY_NAME["no-ends"].edit(bundle) is None
    assert ab.BY_NAME["no-nn1-near"].edit(bundle).near_mm == 0.0
    plain = Perception(ab.BY_NAME["no-nn1-rot"].edit(bundle))
    frame = render(cell, np.array([2.0, -1.5, 10.0]), np.random.default_rng(0))
    p = plain.perceive(frame)
    p = plain.rotation(p) if p.dphi_deg is None else p
    np.testing.assert_allclose(p.full_mm, p.nn1_mm, atol=1e-9)
    for name, key, value in (("no-turn-check", "turn_check_deg", None),
                             ("no-settling", "settle_frames", 1),
                             ("no-hidden-check", "hidden_check_share", None),
                             ("no-look-around", "look_around_deg", None),
                             ("no-reach-check", "reach_factor", 1e6)):
        loop = recipe_of_model(ab.BY_NAME[name].edit(bundle)).loop
        assert getattr(loop, key) == value
        assert loop.r_fine_mm == recipe_of_model(bundle).loop.r_fine_mm


def test_an_unknown_variant_is_refused_in_one_line(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["bench", "ablation", "--variants", "no-outline,no-magic"])
    assert exit_.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--variants: unknown variant 'no-magic'" in last


@pytest.mark.slow
@pytest.mark.timeout(900)  # two trainings on a drawn cell: the whole method's and grey-edge's
def test_a_small_ablation_pairs_every_variant_with_the_whole_method(tmp_path, capsys):
    out = tmp_path / "ablation.json"
    argv = ["bench", "ablation", "--trials", "2", "--trials-per-cell", "2", "--seed", "4",
            "--variants", "no-outline,grey-edge,no-axis", "--quiet", "--json", str(out)]
    assert main(argv) == 0
    printed = json.loads(capsys.readouterr().out)
    report = json.loads(out.read_text())
    assert printed["rows"] == report["rows"]
    assert report["command"] == "finepos " + " ".join(argv)
    rows = {row["variant"]: row for row in report["rows"]}
    assert list(rows) == ["whole", "no-outline", "grey-edge", "no-axis"]
    assert rows["no-axis"]["applicable"] is False
    for name in ("no-outline", "grey-edge"):
        assert rows[name]["applicable"] and rows[name]["all"]["trials"] == 2
        assert rows[name]["paired"]["trials"] <= 2
        assert 0.0 <= rows[name]["paired"]["p_value"] <= 1.0
    whole = report["trial_records"]["whole"]
    for name in ("no-outline", "grey-edge"):
        # the same draws: the same trials, the same share of the part in view
        assert [r["seed"] for r in report["trial_records"][name]] == [r["seed"] for r in whole]
        assert [r["visible"] for r in report["trial_records"][name]] == \
            [r["visible"] for r in whole]
