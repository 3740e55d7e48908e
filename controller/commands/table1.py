"""``finepos table1``: the paper's Table 1 on the simulated cell (three systems x two lightings)."""

from __future__ import annotations

import os
import sys

from controller.commands.common import (
    add_command,
    add_config_file_option,
    config_from_args,
    positive_int,
)
from controller.evaluation.comparison.table1 import LIGHTINGS, TABLE1_SYSTEMS, run_table1
from controller.evaluation.comparison.table1_report import table1_markdown, write_table1


def cmd_table1(args) -> int:
    """Run Table 1, write its files to ``--out`` and print the Markdown table."""
    config = config_from_args(args)
    result = run_table1(config, trials=args.trials, seed=args.seed, workers=args.workers,
                        systems=TABLE1_SYSTEMS, lightings=LIGHTINGS, grasp=not args.no_grasp,
                        progress=not args.quiet)
    paths = write_table1(result, args.out, config.source)
    print(table1_markdown(result, config.source))
    for name, path in paths.items():
        print(f"{name}: {path}", file=sys.stderr)
    return 0


def register(subparsers) -> None:
    """Add ``finepos table1``."""
    p = add_command(
        subparsers, "table1",
        help="the paper's Table 1: gabor, pca and hough in good and poor light",
        description="Example: finepos table1 --trials 100 --seed 1 --out out/table1\n\n"
                    "Acquire the NN1 and NN2 grids once on the default scene in good light, "
                    "train every system on them, then position (and grasp) the same random "
                    "placements with each system in good and in poor light. Writes "
                    "DIR/table1.md, DIR/table1.json (one `finepos evaluate --json` report per "
                    "system and lighting) and DIR/convergence-<lighting>.png.")
    add_config_file_option(p)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--trials", type=positive_int, default=100,
                   help="placements per system and lighting")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--workers", type=positive_int, default=os.cpu_count() or 1,
                   help="parallel processes (default: one per core; 1 runs in this process)")
    p.add_argument("--no-grasp", action="store_true", help="skip the grasp after positioning")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_table1)
