"""Self-check: has the camera or the part changed since teach-in?

Example: finepos check --config deploy/finepos.yaml --part cube

Move to the taught pose and look (the part where it was taught, e.g. a reference part in its
fixture): the trained model must read a near-zero correction (at most --max-mm and --max-deg)
and the view must match the acquisition's image at that pose (similarity at least
--min-similarity; defaults at the end of --help). Prints what it measured (JSON). Exit status 1
when the check fires: the camera (knocked, another lens) or the part has changed and the cell
needs a new teach-in (teach, acquire, train) before it positions again; 2 when nothing is
taught or trained yet, or a file it reads is damaged: the teach-in, the model or an acquired
set (nn1, nn2: each stored one is read whole, before the arm moves), named in the error line.
"""

from __future__ import annotations

import argparse

from controller.calibration.self_check import (
    MAX_CORRECTION_DEG,
    MAX_CORRECTION_MM,
    MIN_SIMILARITY,
    CheckLimits,
    self_check,
)
from controller.commands.common import (
    PART_HELP,
    add_config_option,
    add_system_option,
    config_from_args,
    part_name,
    positive_float,
)
from controller.config import cell_part, with_part
from controller.devices import open_devices
from controller.fine_positioner import FinePositioner
from controller.teach.state_folder import StateFolder
from drivers.core.files import write_json


def run(args) -> int:
    """Run the self-check, print what it measured (JSON); 1 when it fires."""
    config = config_from_args(args)
    if args.part is not None:
        config = with_part(config, args.part)
    folder = StateFolder(args.state_dir or config.controller.paths.state_dir, cell_part(config),
                         config.parts)
    kind = folder.resolve(args.part, cell_part(config))
    taught = folder.taught()
    # A part not taught, with another one taught: check against that one, so the check fires.
    state_dir = taught.get(kind) or (next(iter(taught.values())) if len(taught) == 1
                                     else folder.part_dir(kind))
    limits = CheckLimits(args.max_mm, args.max_deg, args.min_similarity)
    with open_devices(config, seed=args.seed) as devices:
        fp = FinePositioner(devices, config, state_dir=state_dir)
        state = fp.state()
        expected = args.part or (devices.cell.object_kind if devices.cell is not None
                                 else config.controller.part)
        result = self_check(fp, args.system, limits)
        if state.object_kind != expected:
            result.reasons.insert(0, f"the cell was taught on the {state.object_kind}, not the "
                                     f"{expected}")
            result.fired = True
            result.message = ("the part has changed since teach-in: " + "; ".join(result.reasons)
                              + ". The cell needs a new teach-in (teach, acquire, train).")
    report = {"check": "fired" if result.fired else "passed", "system": args.system,
              "state_dir": str(fp.state_dir), **result.as_dict()}
    write_json(args.json, report)
    return 1 if result.fired else 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``finepos check``."""
    parser.epilog = (f"Defaults: --max-mm {MAX_CORRECTION_MM:g}, --max-deg "
                     f"{MAX_CORRECTION_DEG:g}, --min-similarity {MIN_SIMILARITY:g}.")
    add_config_option(parser)
    parser.add_argument("--part", metavar="NAME", type=part_name,
                        help=f"the part the cell should be set up for: {PART_HELP} (default: "
                             "controller.part, or the simulated table's); taught on another part "
                             "fires the check")
    add_system_option(parser)
    parser.add_argument("--max-mm", type=positive_float, default=MAX_CORRECTION_MM,
                        help="largest correction (mm) the model may read at the taught pose")
    parser.add_argument("--max-deg", type=positive_float, default=MAX_CORRECTION_DEG,
                        help="largest rotation (deg) the model may read at the taught pose")
    parser.add_argument("--min-similarity", type=positive_float, default=MIN_SIMILARITY,
                        help="least similarity (0..1) to the acquisition's image at the "
                             "taught pose")
    parser.add_argument("--seed", type=int, default=0,
                        help="simulated cell only: seeds its noise and repeatability (a restart)")
    parser.add_argument("--json", metavar="OUT", help="also write the report here")
