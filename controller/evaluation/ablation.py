"""What each perception stage and loop check earns on randomized cells: an ablation table.

Example: finepos bench ablation --trials 100 --workers 2 --seed 1 --json out/ablation.json

The randomized yardstick's draws (``finepos evaluate --randomize``: cells, lights, cards,
clutter) are run once with the method whole and once per variant that leaves one stage or
check out, or puts the plain path in its place, on the same cells and trials. A variant that
only changes what runs (a stage skipped, a check off, NN1 in place of ``nn1_rot``) runs on
the cell's one trained model; one that changes training (``grey-edge``) trains a model of its
own on the same cell. Each variant's row gives the yardstick's figures (safe within
2.5 loops and RMS where at least 80% of the part is visible, stops where at least 85% is) and
the trials paired with the whole method: how many only the whole method made safe, how many
only the variant, and the exact two-sided McNemar p-value of the difference. A stage whose
removal changes nothing beyond that spread (p >= 0.05) does not earn its place on these
draws. A variant the part cannot have (``no-axis`` for the cube) is listed as not applicable.
Prints the JSON summary; --json writes it with every trial's record.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import shlex
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibration_free.bundle import ModelBundle
from calibration_free.mlp import NumpyMLP
from calibration_free.stages import OPTIONAL_STAGES, OptionalStages
from controller.commands.common import (
    add_config_file_option,
    add_part_option,
    add_recipe_option,
    positive_int,
    run_config_from_args,
)
from controller.config import recipe_of, with_recipe
from controller.evaluation.comparison.pools import Tick, open_pool
from controller.evaluation.randomized import (
    TRIALS_PER_CELL,
    VISIBLE_SAFE,
    CellDraw,
    TrialDraw,
    planned,
    run_cell_trial,
    summarise_randomized,
    train_cell,
    training_config,
    untrained_record,
)
from controller.recipe import Recipe, recipe_of_model, with_recipe_stored
from drivers.core.errors import FineposError
from drivers.core.files import atomic_write_text

SYSTEM = "gabor"  # the method whose stages are ablated
# A difference in safe trials below this two-sided p-value is beyond the draws' spread.
SIGNIFICANCE = 0.05


@dataclass(frozen=True)
class Variant:
    """The method with one stage or check left out, or the plain path in its place.

    Attributes:
        name: the row's name (``--variants``).
        what: one line: what is left out and what stands in.
        recipe: where the variant changes training: the recipe it trains with (from the
            whole method's); it trains a model of its own on each cell.
        edit: where it changes only what runs: the trained model as it runs (None: the part
            has no such stage).
    """

    name: str
    what: str
    recipe: Callable[[Recipe], Recipe] | None = None
    edit: Callable[[ModelBundle], ModelBundle | None] | None = None


def _runs(bundle: ModelBundle) -> list[str]:
    """The optional stages ``bundle`` runs."""
    stages = OptionalStages.of(bundle.training.get("stages"), bundle.axis, bundle.front,
                               bundle.gabor.roi_px)
    return [s for s in OPTIONAL_STAGES if getattr(stages, s) is not None]


def _without_stage(stage: str) -> Callable[[ModelBundle], ModelBundle | None]:
    def edit(bundle: ModelBundle) -> ModelBundle | None:
        runs = _runs(bundle)
        if stage not in runs:
            return None
        return dataclasses.replace(bundle, training={
            **bundle.training, "stages": [s for s in runs if s != stage]})
    return edit


def _without_near(bundle: ModelBundle) -> ModelBundle:
    return dataclasses.replace(bundle, near_mm=0.0)


def nn1_as_rot(nn1: NumpyMLP) -> NumpyMLP:
    """NN1 as a net of ``nn1_rot``'s inputs (u, v, sin, cos) that reads only (u, v): the
    paper's translation on every look."""
    first = np.hstack([nn1.weights[0], np.zeros((nn1.weights[0].shape[0], 2))])
    return NumpyMLP([first, *nn1.weights[1:]], nn1.biases,
                    np.concatenate([nn1.x_mean, [0.0, 0.0]]),
                    np.concatenate([nn1.x_std, [1.0, 1.0]]), nn1.y_mean, nn1.y_std)


def _without_rot(bundle: ModelBundle) -> ModelBundle:
    return dataclasses.replace(bundle, nn1_rot=nn1_as_rot(bundle.nn1), near_mm=0.0)


def _loop_key(**keys) -> Callable[[ModelBundle], ModelBundle]:
    def edit(bundle: ModelBundle) -> ModelBundle:
        recipe = recipe_of_model(bundle)
        return with_recipe_stored(bundle, dataclasses.replace(
            recipe, loop=dataclasses.replace(recipe.loop, **keys)))
    return edit


def _grey_edge(recipe: Recipe) -> Recipe:
    return dataclasses.replace(recipe, perception=dataclasses.replace(
        recipe.perception, edge_coverage="grey"))


VARIANTS: tuple[Variant, ...] = (
    Variant("no-ends", "a bar with one end hidden is centred on the blob it shows "
            "(stage ends)", edit=_without_stage("ends")),
    Variant("no-outline", "a part partly hidden is centred on the blob it shows "
            "(stage outline)", edit=_without_stage("outline")),
    Variant("no-axis", "an elongated part's turn from NN2 alone (stage axis)",
            edit=_without_stage("axis")),
    Variant("grey-edge", "the centre read from the localisation channel's grey levels, not "
            "from each pixel's colour (coverage), trained so", recipe=_grey_edge),
    Variant("no-nn1-near", "no near correction of nn1_rot (nn1_near)", edit=_without_near),
    Variant("no-nn1-rot", "every look translates by NN1 on the centre alone, the paper's "
            "(nn1_rot and nn1_near)", edit=_without_rot),
    Variant("no-settling", "one frame per settling look (settle_frames 1)",
            edit=_loop_key(settle_frames=1)),
    Variant("no-turn-check", "no turn-consistency check (turn_check_deg null)",
            edit=_loop_key(turn_check_deg=None)),
    Variant("no-hidden-check", "no partly-hidden check where the loop ends "
            "(hidden_check_share null)", edit=_loop_key(hidden_check_share=None)),
    Variant("no-look-around", "no look-around before the first full loop "
            "(look_around_deg null)", edit=_loop_key(look_around_deg=None)),
    Variant("no-reach-check", "a correction beyond the training range is taken "
            "(reach_factor 1e6)", edit=_loop_key(reach_factor=1e6)),
)
BY_NAME = {v.name: v for v in VARIANTS}
WHOLE = "whole"


@dataclass(frozen=True)
class _CellJob:
    config: object
    cell: CellDraw
    trials: tuple[TrialDraw, ...]
    variants: tuple[str, ...]


def _edited(trained, variant: Variant):
    bundle = variant.edit(trained.model)
    return None if bundle is None else dataclasses.replace(trained, model=bundle)


def _run_cell(job: _CellJob, tick: Tick) -> dict:
    """Train on a drawn cell (the whole method, and each variant that trains its own), then
    run every trial with the whole method and every variant; records by variant name."""
    cell = job.cell
    names = (WHOLE, *job.variants)
    records: dict[str, list[dict]] = {name: [] for name in names}
    applicable: dict[str, bool] = {}
    train_cfg, _ = training_config(job.config, cell)
    camera = train_cfg.scene.camera
    with tempfile.TemporaryDirectory(prefix="finepos-ablation-") as tmp:
        models = {}
        for name in names:
            variant = BY_NAME.get(name)
            if variant is not None and variant.recipe is None:
                continue
            config = train_cfg if variant is None else with_recipe(
                train_cfg, variant.recipe(recipe_of(train_cfg)))
            try:
                models[name] = train_cell(SYSTEM, config, cell, Path(tmp) / f"train-{name}")
            except FineposError as exc:
                models[name] = str(exc)
        whole = models[WHOLE]
        for name in names:
            variant = BY_NAME.get(name)
            if variant is not None and variant.edit is not None:
                models[name] = whole if isinstance(whole, str) else _edited(whole, variant)
            applicable[name] = models[name] is not None
        for trial in job.trials:
            for name in names:
                model = models[name]
                if model is None:
                    continue
                if isinstance(model, str):
                    records[name].append(untrained_record(cell, trial, model))
                else:
                    records[name].append(run_cell_trial(
                        SYSTEM, model, job.config, cell, camera, trial,
                        Path(tmp) / f"eval-{name}", grasp=False))
            tick()
    return {"cell": cell.index, "records": records, "applicable": applicable}


def mcnemar_p(only_a: int, only_b: int) -> float:
    """Exact two-sided McNemar p-value of ``only_a`` against ``only_b`` discordant pairs."""
    n = only_a + only_b
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, i) for i in range(min(only_a, only_b) + 1)) / 2.0 ** n
    return min(1.0, 2.0 * tail)


def paired(whole: list[dict], variant: list[dict]) -> dict:
    """The trials where at least ``VISIBLE_SAFE`` of the part is seen, paired by trial: safe
    only with the whole method, safe only with the variant, and the McNemar p-value."""
    pairs = [(w["safe_2.5"], v["safe_2.5"]) for w, v in zip(whole, variant, strict=True)
             if (w["visible"] is None or w["visible"] >= VISIBLE_SAFE)]
    only_whole = sum(1 for w, v in pairs if w and not v)
    only_variant = sum(1 for w, v in pairs if v and not w)
    p = mcnemar_p(only_whole, only_variant)
    if p >= SIGNIFICANCE:
        verdict = "within the spread"
    else:
        verdict = "the stage helps" if only_whole > only_variant else "the stage hurts"
    return {"trials": len(pairs), "safe_only_whole": only_whole,
            "safe_only_variant": only_variant, "p_value": p, "verdict": verdict}


def _figures(records: list[dict], cells: list[dict]) -> dict:
    summary = summarise_randomized(records, cells)
    return {key: summary[key] for key in ("all", "visible_0.8", "stops_visible_0.85",
                                          "outcomes")}


def evaluate_ablation(config, *, variants: tuple[str, ...], trials: int, seed: int,
                      trials_per_cell: int = TRIALS_PER_CELL, workers: int = 1,
                      progress: bool = True) -> dict:
    """The ablation report (module docstring) of ``variants`` (names in ``BY_NAME``).

    Raises:
        FineposError: an unknown variant, or no trials.
    """
    unknown = [v for v in variants if v not in BY_NAME]
    if unknown:
        raise FineposError(f"unknown variant {unknown[0]!r} (one of {', '.join(BY_NAME)})")
    t0 = time.perf_counter()
    config, plan = planned(config, trials=trials, seed=seed, trials_per_cell=trials_per_cell)
    jobs = [_CellJob(config, cell, draws, variants) for cell, draws in plan]
    with open_pool(min(workers, len(jobs))) as pool:
        results = pool.run(_run_cell, jobs, weights=[len(j.trials) for j in jobs],
                           desc="ablation", unit="trial", progress=progress)
    records = {name: [r for res in results for r in res["records"][name]]
               for name in (WHOLE, *variants)}
    cells = [{"index": cell.index, "seed": cell.seed, **cell.factors} for cell, _ in plan]
    rows = [{"variant": WHOLE, "what": "the method as trained",
             **_figures(records[WHOLE], cells)}]
    for name in variants:
        if not all(res["applicable"][name] for res in results):
            rows.append({"variant": name, "what": BY_NAME[name].what, "applicable": False})
            continue
        rows.append({"variant": name, "what": BY_NAME[name].what, "applicable": True,
                     **_figures(records[name], cells),
                     "paired": paired(records[WHOLE], records[name])})
    return {"object": config.scene.object.kind, "trials": trials, "seed": seed,
            "trials_per_cell": trials_per_cell, "wall_seconds": time.perf_counter() - t0,
            "rows": rows, "trial_records": records}


def _variants(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    unknown = [n for n in names if n not in BY_NAME]
    if not names or unknown:
        raise argparse.ArgumentTypeError(
            f"unknown variant {unknown[0] if unknown else text!r} (one of "
            f"{', '.join(BY_NAME)})")
    return names


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_file_option(parser)
    add_recipe_option(parser)
    add_part_option(parser, "the scene's, scene.object.kind")
    parser.add_argument("--trials", type=positive_int, default=50,
                        help="drawn trials (default 50)")
    parser.add_argument("--trials-per-cell", type=positive_int, default=TRIALS_PER_CELL,
                        metavar="N", help=f"trials sharing one drawn cell (default "
                                          f"{TRIALS_PER_CELL})")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--variants", type=_variants, default=tuple(BY_NAME),
                        help=f"comma-separated (default all: {', '.join(BY_NAME)})")
    parser.add_argument("--workers", type=positive_int, default=1,
                        help="cells in parallel processes (default 1)")
    parser.add_argument("--json", metavar="FILE",
                        help="also write the report, with every trial's record, here")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(timing=None)


def run(args: argparse.Namespace) -> int:
    config = run_config_from_args(args)
    report = evaluate_ablation(config, variants=args.variants, trials=args.trials,
                               seed=args.seed, trials_per_cell=args.trials_per_cell,
                               workers=args.workers, progress=not args.quiet)
    line = getattr(args, "command_line", None)
    report["command"] = None if line is None else shlex.join(line)
    if args.json:
        atomic_write_text(args.json, json.dumps(report, indent=2) + "\n")
    print(json.dumps({k: v for k, v in report.items() if k != "trial_records"}, indent=2))
    return 0
