"""The paper's Table 1: gabor, pca and hough, and the image-alignment servo (align), in good
and poor light.

Acquire the NN1 and NN2 grids once on the default scene in good light, train every system on
them, then position (and grasp) the same random placements with each system in good and in poor
light. Writes DIR/table1.md, DIR/table1.json (one `finepos evaluate --json` report per system
and lighting) and DIR/convergence-<lighting>.png. --part NAME: with that part on the table
(default: the scene's).

Example: finepos table1 --trials 100 --seed 1 --out out/table1
"""

from __future__ import annotations

import argparse
import os
import sys

from controller.commands.common import (
    add_config_file_option,
    add_part_option,
    add_recipe_option,
    add_timing_option,
    positive_int,
    run_config_from_args,
)
from controller.evaluation.comparison.table1 import LIGHTINGS, TABLE1_SYSTEMS, run_table1
from controller.evaluation.comparison.table1_report import table1_markdown, write_table1


def run(args) -> int:
    """Run Table 1, write its files to ``--out`` and print the Markdown table."""
    config = run_config_from_args(args)
    result = run_table1(config, trials=args.trials, seed=args.seed, workers=args.workers,
                        systems=TABLE1_SYSTEMS, lightings=LIGHTINGS, grasp=not args.no_grasp,
                        progress=not args.quiet)
    paths = write_table1(result, args.out, config.source)
    print(table1_markdown(result, config.source))
    for name, path in paths.items():
        print(f"{name}: {path}", file=sys.stderr)
    return 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``finepos table1``."""
    add_config_file_option(parser)
    add_recipe_option(parser)
    add_part_option(parser, "the scene's, scene.object.kind")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    parser.add_argument("--trials", type=positive_int, default=100,
                        help="placements per system and lighting")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--workers", type=positive_int, default=os.cpu_count() or 1,
                        help="parallel processes (default: one per core; 1 runs in this process)")
    parser.add_argument("--no-grasp", action="store_true", help="skip the grasp after positioning")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    add_timing_option(parser)
