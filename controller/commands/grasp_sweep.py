"""Measure the physical grasp's tolerance on the simulated cell.

Guarded grasps of the simulated part from known offsets of the nominal pose: across the jaws,
along them and in rotation, each from 0 to --max-mm / --max-deg (--grid: also across x
rotation). A point succeeds when the part is held after the lift and seated (turned and tilted
in the jaws at most the limit given at the end of --help); an axis's tolerance is the largest
offset up to which all its points succeeded. Prints the JSON report (points, tolerance); --out
writes grasp_sweep.png.

Example: finepos grasp-sweep --json out/sweep.json --out out/sweep
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from controller.commands.common import (
    add_config_file_option,
    add_recipe_option,
    config_from_args,
)
from controller.devices import open_devices
from controller.loop.grasp import guarded_grasp
from drivers.core.errors import ConfigError
from drivers.core.files import write_json
from drivers.core.pose import ToolStep

SEAT_PHI_DEG = 3.0  # a held part turned more than this in the jaws is not seated
SEAT_TILT_DEG = 3.0
PAPER = {"across_jaws_mm": 2.0, "phi_deg": [5.0, 8.0]}
AXES = (("across_jaws_mm", "dy_mm"), ("along_jaws_mm", "dx_mm"), ("phi_deg", "dphi_deg"))


def grasp_point(devices, part_pose: tuple[float, float, float], grasp_config,
                dx_mm: float, dy_mm: float, dphi_deg: float) -> dict:
    """One guarded grasp from the nominal pose offset by (dx, dy, dphi) in the tool frame
    (the part put back where ``part_pose`` says first); the point's JSON record."""
    cell, arm, sensor = devices.cell, devices.arm, devices.wrench
    arm.open_gripper()
    cell.place_object(*part_pose)
    arm.move_to(cell.nominal_grasp_pose().moved_in_tool_frame(
        ToolStep(dx_mm=dx_mm, dy_mm=dy_mm, dphi_deg=dphi_deg)))
    result = guarded_grasp(arm, sensor, cell.grasp_depth_mm, cell.part.grasp_width_mm,
                           grasp_config, part_weight_n=cell.part.mass_g * 9.81e-3)
    misalignment = cell.grasp_misalignment() if cell.holding else None
    success, reason = result.success and cell.holding, result.reason
    if result.success and not cell.holding:
        reason = "the check passed but the part is not in the jaws"
    if success and (abs(misalignment["phi_deg"]) > SEAT_PHI_DEG
                    or misalignment["tilt_deg"] > SEAT_TILT_DEG):
        success = False
        reason = (f"held but not seated: turned {misalignment['phi_deg']:.1f} deg, tilted "
                  f"{misalignment['tilt_deg']:.1f} deg in the jaws")
    arm.open_gripper()
    return {"dx_mm": dx_mm, "dy_mm": dy_mm, "dphi_deg": dphi_deg, "success": bool(success),
            "reason": reason, "max_force_n": round(result.max_force_n, 3),
            "misalignment": ({k: round(v, 3) for k, v in misalignment.items()}
                             if misalignment is not None else None)}


def tolerance(points: list[dict], key: str) -> float:
    """The largest ``key`` offset up to which every point on that axis (the other offsets
    zero) succeeded; 0 when the first one failed."""
    others = [k for _, k in AXES if k != key]
    axis = sorted((pt for pt in points if all(pt[k] == 0.0 for k in others)),
                  key=lambda pt: abs(pt[key]))
    best = 0.0
    for pt in axis:
        if not pt["success"]:
            break
        best = abs(pt[key])
    return best


def _steps(maximum: float, step: float) -> list[float]:
    count = int(math.floor(maximum / step + 1e-9))
    return [round(i * step, 6) for i in range(count + 1)]


def sweep(devices, grasp_config, part_pose, max_mm: float, step_mm: float, max_deg: float,
          step_deg: float, grid: bool) -> dict:
    """Every point of the sweep and the tolerances (the JSON report)."""
    offsets = [(0.0, dy, 0.0) for dy in _steps(max_mm, step_mm)]
    offsets += [(dx, 0.0, 0.0) for dx in _steps(max_mm, step_mm)[1:]]
    offsets += [(0.0, 0.0, dphi) for dphi in _steps(max_deg, step_deg)[1:]]
    if grid:
        offsets += [(0.0, dy, dphi) for dy in _steps(max_mm, 2 * step_mm)[1:]
                    for dphi in _steps(max_deg, 2 * step_deg)[1:]]
    points = [grasp_point(devices, part_pose, grasp_config, *o) for o in offsets]
    return {"part": devices.cell.part.kind,
            "jaw_opening_mm": devices.cell.part.jaw_opening_mm,
            "grasp_width_mm": devices.cell.part.grasp_width_mm,
            "seat_limits": {"phi_deg": SEAT_PHI_DEG, "tilt_deg": SEAT_TILT_DEG},
            "points": points,
            "tolerance": {name: tolerance(points, key) for name, key in AXES},
            # A tolerance equal to these held to the end of the sweep: it is at least that.
            "swept_to": {"mm": _steps(max_mm, step_mm)[-1], "deg": _steps(max_deg, step_deg)[-1]},
            "paper": PAPER}


def write_map(report: dict, path: Path) -> None:
    """A PNG: per axis, each point's largest force coloured by its outcome, the measured
    tolerance and the paper's; with a grid, the across x rotation map too."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    points = report["points"]
    grid = [pt for pt in points if pt["dy_mm"] and pt["dphi_deg"]]
    fig, axes = plt.subplots(1, 4 if grid else 3, figsize=(16 if grid else 12, 3.6))
    paper = {"across_jaws_mm": (2.0, 2.0), "along_jaws_mm": None, "phi_deg": (5.0, 8.0)}
    for ax, (name, key) in zip(axes, AXES, strict=False):
        others = [k for _, k in AXES if k != key]
        axis = [pt for pt in points if all(pt[k] == 0.0 for k in others)]
        for ok, colour in ((True, "tab:green"), (False, "tab:red")):
            sel = [pt for pt in axis if pt["success"] is ok]
            ax.scatter([pt[key] for pt in sel], [pt["max_force_n"] for pt in sel], c=colour,
                       s=18, label="held, seated" if ok else "failed")
        ax.axvline(report["tolerance"][name], color="k", lw=1, label="measured tolerance")
        if paper[name] is not None:
            lo, hi = paper[name]
            ax.axvspan(lo - 0.05, hi + 0.05, color="tab:blue", alpha=0.2, label="paper")
        ax.set_xlabel(key.replace("_", " "))
        ax.set_ylabel("largest force during the grasp (N)")
        limit = report["swept_to"]["deg" if key == "dphi_deg" else "mm"]
        at_least = ">= " if report["tolerance"][name] >= limit else ""
        ax.set_title(f"{name.replace('_', ' ')}: {at_least}{report['tolerance'][name]:g}")
    axes[0].legend(fontsize=7)
    if grid:
        ax = axes[3]
        xs = sorted({pt["dy_mm"] for pt in grid})
        ys = sorted({pt["dphi_deg"] for pt in grid})
        image = np.full((len(ys), len(xs)), np.nan)
        for pt in grid:
            image[ys.index(pt["dphi_deg"]), xs.index(pt["dy_mm"])] = 1.0 if pt["success"] else 0.0
        ax.imshow(image, origin="lower", cmap="RdYlGn", vmin=0, vmax=1, aspect="auto",
                  extent=(xs[0], xs[-1], ys[0], ys[-1]))
        ax.set_xlabel("dy mm (across the jaws)")
        ax.set_ylabel("dphi deg")
        ax.set_title("across x rotation (green: held, seated)")
    fig.suptitle(f"grasp tolerance: {report['part']}, jaws open {report['jaw_opening_mm']:g} mm")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def run(args) -> int:
    """``finepos grasp-sweep``: see the module docstring."""
    for name in ("max_mm", "step_mm", "max_deg", "step_deg"):
        value = getattr(args, name)
        if not (value > 0 and math.isfinite(value)):
            raise ConfigError(f"--{name.replace('_', '-')}: must be a positive number, "
                              f"got {value}")
    if args.max_mm < 6.0 or args.max_deg < 20.0:
        print("note: the issue's sweep goes to at least 6 mm and 20 deg", file=sys.stderr)
    config = config_from_args(args)
    with open_devices(config, seed=args.seed) as devices:
        if devices.cell is None:
            raise ConfigError("arm.type: grasp-sweep needs the simulated cell (type: sim)")
        obj = config.scene.object
        report = sweep(devices, config.controller.grasp, (obj.x_mm, obj.y_mm, obj.phi_deg),
                       args.max_mm, args.step_mm, args.max_deg, args.step_deg, args.grid)
    write_json(args.json, report)
    if args.out:
        png = Path(args.out) / "grasp_sweep.png"
        write_map(report, png)
        print(f"map: {png}", file=sys.stderr)
    return 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``finepos grasp-sweep``."""
    parser.epilog = f"Seated: turned and tilted at most {SEAT_PHI_DEG:g} deg in the jaws."
    add_config_file_option(parser)
    add_recipe_option(parser)
    parser.add_argument("--json", metavar="OUT", required=True, help="write the JSON report here")
    parser.add_argument("--out", metavar="DIR", help="write the PNG map grasp_sweep.png here")
    parser.add_argument("--max-mm", type=float, default=6.0, help="largest offset (mm; default 6)")
    parser.add_argument("--step-mm", type=float, default=0.25,
                        help="offset step (mm; default 0.25)")
    parser.add_argument("--max-deg", type=float, default=20.0,
                        help="largest rotation (deg; default 20)")
    parser.add_argument("--step-deg", type=float, default=1.0,
                        help="rotation step (deg; default 1)")
    parser.add_argument("--grid", action="store_true", help="also sweep across x rotation together")
    parser.add_argument("--seed", type=int, default=0,
                        help="the cell's seed (repeatability errors, sensor noise)")
