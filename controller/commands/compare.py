"""Compare two evaluation runs trial by trial: RMS figures and paired 95% intervals (JSON).

Example: finepos compare gabor-states.json align-states.json --budgets 2.5 3.5

Each file is an ``finepos evaluate --states FILE`` trace. Run both evaluations with the same
--part, --lighting, --trials and --seed (any --system, model or config otherwise): they then
met the same placements and start offsets, so the difference is paired. For each loop budget
the report gives each run's RMS x, y, distance from the grasp point (x and y together) and
phi after that many loops, and the first's less the second's with the 2.5-97.5 percentiles
of that difference over the trials resampled together, and a verdict for the first run:
"ahead" (the interval lies below zero), "behind" (above) or "level" (it holds zero).
"""

from __future__ import annotations

import argparse

from controller.commands.common import loop_budget, positive_int
from controller.evaluation.paired import DEFAULT_BUDGETS, DEFAULT_RESAMPLES, compare, load_states
from drivers.core.files import write_json


def run(args) -> int:
    report = compare(load_states(args.first), load_states(args.second),
                     budgets=args.budgets, resamples=args.resamples, seed=args.seed)
    report = {"first": args.first, "second": args.second, **report}
    write_json(args.json, report)
    return 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``finepos compare``."""
    parser.add_argument("first", metavar="FIRST", help="an evaluate --states file")
    parser.add_argument("second", metavar="SECOND",
                        help="another, from the same trials (same --trials and --seed)")
    parser.add_argument("--budgets", type=loop_budget, nargs="+", metavar="LOOPS",
                        default=list(DEFAULT_BUDGETS),
                        help="loop budgets to compare after (default: 1.5 2.5 3.5)")
    parser.add_argument("--resamples", type=positive_int, default=DEFAULT_RESAMPLES,
                        help=f"resamples of the trials (default {DEFAULT_RESAMPLES})")
    parser.add_argument("--seed", type=int, default=0, help="seed of the resampling")
    parser.add_argument("--json", metavar="OUT", help="also write the report here")
