"""How well teach-in finds each part's kappa from its images, on the simulated cell.

Example: finepos bench symmetry --part all --seeds 1,2,3 --json out/symmetry.json

For each part, light and seed the simulated cell puts the part on the table, the arm goes to
the part's true pre-grasp pose and teach-in's symmetry search runs there
(``controller.teach.symmetry.find_symmetry``); its kappa is compared with the simulator's
own (the declared kappa, else the mesh's rotational symmetry). Prints one JSON report: a row
per run (kappa found, sure or not, confidence, the shift scores) and, per part, how many runs
found it right, how many were unsure and how many wrong (sure of a wrong kappa: the failure
that must not happen); --json also writes the rows.
"""

from __future__ import annotations

import argparse
import json
import shlex
import time

from controller.commands.common import add_config_file_option
from controller.config import is_simulated, load_config, with_part
from controller.devices import open_devices
from controller.evaluation.trials import with_lighting
from controller.simulated import with_scene_read
from controller.teach.acquisition import transfer
from controller.teach.symmetry import find_symmetry
from drivers.core.errors import ConfigError
from drivers.core.files import atomic_write_text

LIGHTINGS = ("good", "poor")


def run_symmetry_bench(config, parts: list[str], lightings: tuple[str, ...],
                       seeds: list[int]) -> dict:
    """The report (see the module docstring) of ``config``'s simulated cell."""
    rows = []
    t0 = time.perf_counter()
    for kind in parts:
        for light in lightings:
            for seed in seeds:
                run_config = with_lighting(with_part(config, kind), light)
                with open_devices(run_config, seed=seed) as devices:
                    cell = devices.cell
                    taught = cell.nominal_grasp_pose()
                    transfer(devices.arm, taught, run_config.safety)
                    found = find_symmetry(devices.arm, devices.camera, taught,
                                          lambda pose, d=devices, c=run_config:
                                          transfer(d.arm, pose, c.safety))
                    truth = cell.kappa
                outcome = ("unsure" if not found.sure
                           else "right" if found.kappa == truth else "wrong")
                rows.append({"part": kind, "lighting": light, "seed": seed,
                             "true_kappa": truth, "outcome": outcome, **found.as_dict()})
    summary = {}
    for kind in parts:
        mine = [r for r in rows if r["part"] == kind]
        summary[kind] = {"true_kappa": mine[0]["true_kappa"], "runs": len(mine),
                         **{o: sum(r["outcome"] == o for r in mine)
                            for o in ("right", "unsure", "wrong")},
                         "least_confidence_right": min(
                             (r["confidence"] for r in mine if r["outcome"] == "right"),
                             default=None)}
    return {"parts": summary, "lightings": list(lightings), "seeds": seeds,
            "wall_seconds": round(time.perf_counter() - t0, 1), "rows": rows}


def _seeds(text: str) -> list[int]:
    try:
        seeds = [int(s) for s in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seeds like 1,2,3, got {text!r}") from None
    if not seeds or any(s < 0 for s in seeds):
        raise argparse.ArgumentTypeError(f"expected seeds >= 0, got {text!r}")
    return seeds


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_file_option(parser)
    parser.add_argument("--part", metavar="NAME", default="all",
                        help="a part (built-in or declared in --config), or all (default)")
    parser.add_argument("--seeds", type=_seeds, default=[1, 2, 3],
                        help="cell seeds, comma-separated (default 1,2,3)")
    parser.add_argument("--lighting", choices=LIGHTINGS,
                        help="only this lighting preset (default: good and poor)")
    parser.add_argument("--json", metavar="FILE", help="also write the report here")


def run(args: argparse.Namespace) -> int:
    config = with_scene_read(load_config(args.config))
    if not is_simulated(config):
        raise ConfigError("bench symmetry: only on the simulated cell (a device of type sim)")
    parts = list(config.parts) if args.part == "all" else [config.parts.check(args.part)]
    lightings = (args.lighting,) if args.lighting else LIGHTINGS
    report = run_symmetry_bench(config, parts, lightings, args.seeds)
    words = ["finepos", "bench", "symmetry", "--part", args.part,
             "--seeds", ",".join(str(s) for s in args.seeds)]
    words += ["--config", args.config] if args.config else []
    words += ["--lighting", args.lighting] if args.lighting else []
    report["command"] = shlex.join(words)
    if args.json:
        atomic_write_text(args.json, json.dumps(report, indent=2) + "\n")
    print(json.dumps({"command": report["command"], "parts": report["parts"],
                      "wall_seconds": report["wall_seconds"]}, indent=2))
    return 0
