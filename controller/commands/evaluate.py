"""``finepos evaluate``: accuracy of a vision system on random placements (JSON report)."""

from __future__ import annotations

import json
from pathlib import Path

from controller.commands.common import (
    add_command,
    add_config_option,
    config_from_args,
    positive_int,
)
from controller.evaluation.trials import evaluate
from controller.loop.iteration_log import IterationLog
from controller.systems.registry import SYSTEMS
from drivers.core.files import write_json


def cmd_evaluate(args) -> int:
    """Run ``trials.evaluate`` with the options and print the JSON report (also to ``--json``)."""
    config = config_from_args(args)
    log = IterationLog(args.log) if args.log else None
    try:
        report = evaluate(args.system, config, trials=args.trials, seed=args.seed,
                          lighting=args.lighting, model_path=args.model,
                          grasp=not args.no_grasp, log=log, progress=not args.quiet,
                          hil=args.hil)
    finally:
        if log:
            log.close()
    trial_states = report.pop("_trial_states")
    if args.states:
        Path(args.states).write_text(json.dumps(trial_states))
    write_json(args.json, report)
    return 0


def register(subparsers) -> None:
    """Add ``finepos evaluate``."""
    p = add_command(
        subparsers, "evaluate",
        help="evaluate a system on random placements; JSON report",
        description="Example: finepos evaluate --system gabor --lighting poor --trials 100 "
                    "--seed 1 --json out/poor.json\n\nUnless --model is given, first teach, "
                    "acquire and train on the default scene; then test on the scene of "
                    "--config with random part placements and start offsets uniform in "
                    "+/-25 mm, +/-180/kappa deg.\n\nExample: finepos evaluate --hil --model "
                    "state/model-gabor.fpm --trials 20\n\n--hil: hardware in the loop "
                    "on one machine: the same cell is served in this process over the VAL, ATI "
                    "and MJPEG emulators, and every arm, camera and wrench exchange goes through "
                    "the real drivers (placement and ground truth come from the cell).")
    add_config_option(p)
    p.add_argument("--system", default="gabor", choices=sorted(SYSTEMS))
    p.add_argument("--lighting", choices=["good", "poor", "dim", "side"],
                   help="override the scene's lighting preset")
    p.add_argument("--trials", type=positive_int, default=100)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--model", metavar="FILE", help="use this trained model (skip training)")
    p.add_argument("--json", metavar="OUT", help="also write the report here")
    p.add_argument("--log", metavar="FILE", help="per-iteration JSON Lines log")
    p.add_argument("--states", metavar="FILE", help="write every trial's error trace (JSON)")
    p.add_argument("--no-grasp", action="store_true", help="skip the grasp after positioning")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--hil", action="store_true",
                   help="through the real drivers and the device emulators (see above)")
    p.set_defaults(func=cmd_evaluate)
