"""The paper's Fig. 5: compare Gabor filter sets (mean and spread).

Acquire the training grids once; per repeat (seeds SEED, SEED+1, ...) train the base system and
acquire a random test set; then per filter set and repeat retrain NN2 on that set's features
and measure the rotation RMS on the test set (open loop) and the whole system on random
placements (closed loop, RMS after 2.5 loops). Writes DIR/filter_search.json, .md and .png
(bars like Fig. 5). Jobs run on --workers local processes, or on a Ray cluster with --ray
ADDRESS (needs pip install 'finepos[ray]' here and finepos on every node). The filter sets
are listed at the end of --help.

Example: finepos filter-search --repeats 10 --trials 20 --out out/fig5
"""

from __future__ import annotations

import argparse
import os
import sys

from controller.commands.common import (
    add_config_file_option,
    add_recipe_option,
    config_from_args,
    positive_int,
)
from controller.evaluation.comparison.filter_report import search_markdown, write_search
from controller.evaluation.comparison.filter_search import run_filter_search
from controller.evaluation.comparison.filter_sets import FILTER_SETS, PAPER_SET, select_sets


def run(args) -> int:
    """Run the filter-set search, write its files to ``--out``, print the Markdown summary."""
    config = config_from_args(args)
    names = [n.strip() for n in args.sets.split(",") if n.strip()] if args.sets else None
    sets = select_sets(names)
    result = run_filter_search(config, sets, repeats=args.repeats, trials=args.trials,
                               seed=args.seed, workers=args.workers, ray_address=args.ray,
                               progress=not args.quiet)
    summary, paths = write_search(result, args.out)
    print(search_markdown(summary))
    for name, path in paths.items():
        print(f"{name}: {path}", file=sys.stderr)
    return 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``finepos filter-search``."""
    parser.epilog = (f"Filter sets (the paper's: {PAPER_SET}):\n  "
                     + "\n  ".join(FILTER_SETS))
    add_config_file_option(parser)
    add_recipe_option(parser)
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    parser.add_argument("--repeats", type=positive_int, default=10, help="repeats per filter set")
    parser.add_argument("--trials", type=positive_int, default=20,
                        help="closed-loop placements per filter set and repeat")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--sets", metavar="NAMES",
                        help="comma-separated filter-set names (default: all, listed above)")
    parser.add_argument("--workers", type=positive_int, default=os.cpu_count() or 1,
                        help="parallel local processes (default: one per core; 1 runs in this "
                             "process)")
    parser.add_argument("--ray", metavar="ADDRESS",
                        help="run the jobs on this Ray cluster instead: auto (the running one), "
                             "local (start one here), ray://HOST:10001")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
