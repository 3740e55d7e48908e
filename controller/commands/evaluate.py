"""Evaluate a system on random placements; JSON report.

Example: finepos evaluate --system gabor --lighting poor --trials 100 --seed 1 --json out/poor.json

Unless --model is given, first teach, acquire and train on the default scene; then test on the
scene of --config with random part placements and start offsets uniform in +/-25 mm,
+/-180/kappa deg.

Also: finepos evaluate --hil --model state/cube/model-gabor.fpm --trials 20

--hil: hardware in the loop on one machine: the same cell is served in this process over the
VAL, ATI and MJPEG emulators, and every arm, camera and wrench exchange goes through the real
drivers (placement and ground truth come from the cell).

--part NAME evaluates that part (default: the scene's, scene.object.kind): it is taught,
acquired and trained on the default scene with that part on the table and tested on the scene
of --config with that part on it.

Also: finepos evaluate --part all --trials 50 --json out/parts.json

--part all: every part of the catalogue in good and in poor light (each trained once); prints
one Markdown table (safe rates after 1.5 and 2.5 loops with 95% Wilson intervals, RMS after
1.5, 2.5 and 3.5 loops, loops to safe) instead of the JSON report; --json writes every row's
report; --workers runs the trials in parallel processes.

Also: finepos evaluate --part all --lighting poor --rezero --trials 50

--rezero: after training (or --model), re-zero the model at the taught pose in the trials'
light, as `finepos rezero` does on a cell whose light changed, then run the trials (the report's
rezero: what each translation net read there before, mm; --system align: the servo's template
taken again, and what it read there before). With --rezero-heading-step DEG the model also
gets its zero by heading in that light, as `finepos rezero --heading-step` reads it: the arm
turns the part itself, in steps of at most DEG over one symmetry period centred on its taught
heading (where the trials' tool ends), and reads NN2's turn and the translation there (the
report's rezero.heading_zero).

Also: finepos evaluate --lighting poor --teach-lighting poor --trials 50

--teach-lighting: teach-in, acquisition and training under that lighting preset instead of the
default scene's good light (with --part all: every part's), as on a cell taught in the light it
works in; the trials' light is still --lighting (or the scene's). The report's teach_lighting
names the light the model was taught in (null with --model).

Also: finepos evaluate --mounts 10 --trials 50 --json out/mounts.json

--mounts N: N random cameras (mount tilt +/-8 deg, roll and pan +/-4 deg, offset +/-5 mm, field
of view +/-15 %, k1 in [-0.35, 0.1], vignetting, blur, gamma and auto-exposure varied; the rest
as scene.camera), each taught, trained and tested on its own cell; one row per camera and a
summary (worst and median camera). The method never sees a camera parameter.

Also: finepos evaluate --randomize --trials 500 --workers 2 --seed 1 --json out/random.json

--randomize: the yardstick, randomized cells. Every --trials-per-cell trials share one drawn
cell: a camera (output gamma 1.0-2.4, auto-exposure on or off, a fixed exposure set within
0.7-1.4 times what auto-exposure settles on in the training light, gain cap, read noise, 1-3
samples a pixel, JPEG quality 60-100 or none, Bayer on or off; mount and lens as --mounts
draws them), a table (colour, texture, brightness) and the part's colour; it is taught,
acquired and trained under a drawn light. Each trial draws the light afresh (1-3 lamps at
random directions and heights, brightness from dim to bright, colour temperature 2,700-6,500
K, shadow strength), a card over 0-30% of the part and 0-3 other parts on the table. The
report records every draw and gives the yardstick's figures (safe within 2.5 loops and RMS
where at least 80% of the part is visible; stops where at least 85% is), its targets, and
the results by each drawn factor. --workers runs the cells in parallel processes. With
--rezero (and --rezero-heading-step) the cell's model is re-zeroed before each trial in the
trial's light, the part lying free, as `finepos rezero` does after the light changed; the
report's rezero gives the re-zeros refused and their median arm time.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys

from controller.calibration.rezero import HEADING_ZERO_SYSTEMS, REZERO_SYSTEMS
from controller.commands.common import (
    ALL_PARTS,
    PART_HELP,
    add_config_option,
    add_live_option,
    add_recipe_option,
    add_system_option,
    add_timing_option,
    part_name_or_all,
    positive_float,
    positive_int,
    run_config_from_args,
    run_recorder,
)
from controller.evaluation.mounts import evaluate_mounts
from controller.evaluation.parts_table import parts_markdown, run_parts_table
from controller.evaluation.randomized import TRIALS_PER_CELL, evaluate_randomized
from controller.evaluation.trials import evaluate
from controller.loop.iteration_log import IterationLog
from drivers.core.errors import ConfigError
from drivers.core.files import atomic_write_text, write_json


def command_of(args) -> str | None:
    """The command line that ran, as a shell would take it (None when not run from
    ``controller.cli.main``)."""
    line = getattr(args, "command_line", None)
    return None if line is None else shlex.join(line)


def run(args) -> int:
    """Run ``trials.evaluate`` with the options and print the JSON report (also to ``--json``)."""
    config = run_config_from_args(args)
    if args.rezero and args.system not in REZERO_SYSTEMS:
        raise ConfigError(f"--rezero: only with --system {' or '.join(REZERO_SYSTEMS)}, not "
                          f"{args.system}")
    if args.rezero_heading_step is not None and not args.rezero:
        raise ConfigError("--rezero-heading-step: only with --rezero")
    if args.rezero_heading_step is not None and args.system not in HEADING_ZERO_SYSTEMS:
        raise ConfigError(f"--rezero-heading-step: only with --system "
                          f"{' or '.join(HEADING_ZERO_SYSTEMS)} (the {args.system} system "
                          "keeps one zero)")
    if args.rezero and args.mounts is not None:
        raise ConfigError("--rezero: not with --mounts (each camera is trained on its own)")
    if args.teach_lighting and args.model:
        raise ConfigError("--teach-lighting: not with --model (the model is trained already)")
    if args.teach_lighting and args.mounts is not None:
        raise ConfigError("--teach-lighting: not with --mounts (each camera is taught in the "
                          "scene's light)")
    if args.part == ALL_PARTS:
        return _evaluate_parts(args, config)
    if args.randomize:
        return _evaluate_randomized(args, config)
    if args.trials_per_cell is not None:
        raise ConfigError("--trials-per-cell: only with --randomize")
    if args.workers != 1:
        raise ConfigError("--workers: only with --part all or --randomize")
    if args.mounts is not None:
        return _evaluate_mounts(args, config)
    log = IterationLog(args.log) if args.log else None
    try:
        with run_recorder(args, max_runs=args.record_trials) as recorder:
            report = evaluate(args.system, config, trials=args.trials, seed=args.seed,
                              lighting=args.lighting, model_path=args.model,
                              grasp=not args.no_grasp, log=log, progress=not args.quiet,
                              hil=args.hil, recorder=recorder, rezero=args.rezero,
                              teach_lighting=args.teach_lighting,
                              rezero_heading_step=args.rezero_heading_step)
    finally:
        if log:
            log.close()
    report["command"] = command_of(args)
    trial_states = report.pop("_trial_states")
    if args.states:
        atomic_write_text(args.states, json.dumps(trial_states))
    write_json(args.json, report)
    return 0


def _evaluate_parts(args, config) -> int:
    """``--part all``: ``parts_table.run_parts_table`` with the options; prints the Markdown
    table (every row's JSON report to ``--json``)."""
    for option in ("model", "log", "states", "record", "live", "mounts"):
        if getattr(args, option, None) is not None:
            raise ConfigError(f"--{option}: not with --part all (every part is trained and "
                              "tested on its own)")
    if args.hil:
        raise ConfigError("--hil: not with --part all")
    lightings = (args.lighting,) if args.lighting else ("good", "poor")
    report = run_parts_table(config, system=args.system, trials=args.trials, seed=args.seed,
                             part_names=tuple(config.parts), lightings=lightings,
                             grasp=not args.no_grasp, workers=args.workers,
                             progress=not args.quiet, rezero=args.rezero,
                             teach_lighting=args.teach_lighting,
                             rezero_heading_step=args.rezero_heading_step)
    report["command"] = command_of(args)
    if args.json:
        atomic_write_text(args.json, json.dumps(report, indent=2) + "\n")
        print(f"report: {args.json}", file=sys.stderr)
    print(parts_markdown(report), end="")
    return 0


def _evaluate_randomized(args, config) -> int:
    """``--randomize``: ``randomized.evaluate_randomized`` with the options; prints the JSON
    report."""
    for option in ("model", "log", "states", "record", "live", "mounts", "lighting",
                   "teach_lighting"):
        if getattr(args, option, None) is not None:
            raise ConfigError(f"--{option.replace('_', '-')}: not with --randomize (every cell "
                              "and its light are drawn)")
    if args.hil:
        raise ConfigError("--hil: not with --randomize")
    report = evaluate_randomized(args.system, config, trials=args.trials, seed=args.seed,
                                 trials_per_cell=args.trials_per_cell or TRIALS_PER_CELL,
                                 grasp=not args.no_grasp, workers=args.workers,
                                 progress=not args.quiet, rezero=args.rezero,
                                 rezero_heading_step=args.rezero_heading_step)
    report["command"] = command_of(args)
    write_json(args.json, report)
    return 0


def _evaluate_mounts(args, config) -> int:
    """``--mounts N``: ``mounts.evaluate_mounts`` with the options; prints the JSON report."""
    for option in ("model", "log", "states", "record", "live"):
        if getattr(args, option, None) is not None:
            raise ConfigError(f"--{option}: not with --mounts (every camera is set up, trained "
                              "and tested on its own)")
    report = evaluate_mounts(args.system, config, mounts=args.mounts, trials=args.trials,
                             seed=args.seed, lighting=args.lighting, grasp=not args.no_grasp,
                             progress=not args.quiet, hil=args.hil)
    report["command"] = command_of(args)
    write_json(args.json, report)
    return 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``finepos evaluate``."""
    add_config_option(parser)
    add_recipe_option(parser)
    add_system_option(parser)
    parser.add_argument("--part", metavar="NAME", type=part_name_or_all,
                        help=f"the part: {PART_HELP} (default: the scene's), or "
                             f"{ALL_PARTS}: the parts table of every part the config knows "
                             "(see above)")
    parser.add_argument("--lighting", choices=["good", "poor", "dim", "side"],
                        help="override the scene's lighting preset (--part all: only this one "
                             "instead of good and poor)")
    parser.add_argument("--teach-lighting", choices=["good", "poor", "dim", "side"],
                        help="teach, acquire and train under this lighting preset instead of "
                             "the default scene's good light (a cell taught in the light it "
                             "works in; see above)")
    parser.add_argument("--trials", type=positive_int, default=100)
    parser.add_argument("--mounts", type=positive_int, metavar="N",
                        help="evaluate on N random cameras and mounts (see above)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--model", metavar="FILE", help="use this trained model (skip training)")
    parser.add_argument("--json", metavar="OUT", help="also write the report here")
    parser.add_argument("--log", metavar="FILE", help="per-iteration JSON Lines log")
    parser.add_argument("--states", metavar="FILE", help="write every trial's error trace (JSON)")
    parser.add_argument("--record", metavar="FILE.mcap",
                        help="record the first --record-trials trials (frames, overlays, records, "
                             "wrench) as MCAP for Foxglove and finepos replay")
    parser.add_argument("--record-trials", type=positive_int, default=3, metavar="N",
                        help="how many trials --record keeps (default 3)")
    add_live_option(parser)
    parser.add_argument("--no-grasp", action="store_true", help="skip the grasp after positioning")
    parser.add_argument("--rezero", action="store_true",
                        help="first re-zero the model at the taught pose in the trials' light "
                             "(finepos rezero; gabor or align)")
    parser.add_argument("--rezero-heading-step", type=positive_float, metavar="DEG",
                        help="with --rezero: also the zero by heading, the part turned by "
                             "the arm in steps of at most DEG (finepos rezero --heading-step; "
                             "gabor)")
    parser.add_argument("--randomize", action="store_true",
                        help="randomized cells: camera, light, table, part colour, card and "
                             "clutter drawn (see above)")
    parser.add_argument("--trials-per-cell", type=positive_int, metavar="N",
                        help=f"--randomize: trials that share one drawn, trained cell "
                             f"(default {TRIALS_PER_CELL})")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.add_argument("--workers", type=positive_int, default=1,
                        help="--part all or --randomize: parallel processes (default 1)")
    add_timing_option(parser)
    parser.add_argument("--hil", action="store_true",
                        help="through the real drivers and the device emulators (see above)")
