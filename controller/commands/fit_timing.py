"""Time moves on a real VAL arm and fit the timing model's t0, joint speed and acceleration.

Moves the tool of the VAL arm in --config by 1, 5, 10 and 25 mm along its x and y axes and back
at speeds 25, 50 and 100, repeated, times each move through the driver, fits the motion model t
= t0 + max_j T(dq_j, v*s, a*s) (trapezoidal joint profiles, s = speed/100) and prints t0_s,
joint_speed_deg_s, joint_accel_deg_s2 and the fit's rms as JSON. --write-config writes --config
with timing.arm set to the fit (t0_s includes the settling; settle_s 0). The arm must stand with
room for 25 mm around it; speed is left at 100.

Example: finepos fit-timing --config cell.yaml --write-config cell-fitted.yaml
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import yaml

from controller.commands.common import config_from_args
from controller.config import config_from_mapping
from drivers.core.errors import ConfigError, FineposError
from drivers.core.files import atomic_write_text, write_json
from drivers.core.pose import ToolStep
from drivers.core.timing import ArmFit, TimedMove, fit_arm_timing, wire_time_s
from drivers.core.typed_config import load_yaml_file

DEFAULT_DISTANCES_MM = (1.0, 5.0, 10.0, 25.0)
DEFAULT_SPEEDS = (25.0, 50.0, 100.0)
_WHERE_SAMPLES = 5


def _numbers(text: str, what: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if not values or not all(0.0 < v < 1e4 for v in values):
        raise ConfigError(f"{what}: expected positive numbers separated by commas, got {text!r}")
    return values


def time_moves(arm, distances_mm, speeds, repeats: int, out=sys.stderr) -> list[TimedMove]:
    """Time ``repeats`` out-and-back moves of every distance along the tool's x and y at every
    speed through a connected, active ``ValArm``; returns the moves with their motion seconds.

    Raises:
        FineposError: the controller's ``where`` prints no joint angles.
    """
    cfg = arm.config
    bits = 1 + cfg.bytesize + (0 if cfg.parity == "N" else 1) + cfg.stopbits
    where_s = []
    for _ in range(_WHERE_SAMPLES):
        t = time.perf_counter()
        reading = arm.where()
        where_s.append(time.perf_counter() - t)
    if reading.joints_deg is None:
        raise FineposError("the controller's where reply has no JT1..JT6 joint angles; the fit "
                           "needs them")
    where_median = statistics.median(where_s)
    # The driver's where exchanges around a move: before it only when configured (otherwise
    # it starts from the last move's target, kept from the warm-up move below on), after it
    # only when configured.
    wheres = int(cfg.where_before_move) + int(cfg.where_after_move)
    home = reading.pose
    arm.move_to(home)  # a kept start pose from here on
    moves: list[TimedMove] = []
    for speed in speeds:
        arm.set_speed(speed)
        for distance in distances_mm:
            for rep in range(repeats):
                step = ToolStep(distance, 0.0, 0.0, 0.0) if rep % 2 == 0 else \
                    ToolStep(0.0, distance, 0.0, 0.0)
                for target in (home.moved_in_tool_frame(step), home):
                    before = arm.where().joints_deg
                    line = cfg.commands.move.format(**target.as_dict())
                    n_bytes = (len(line) + len(cfg.line_ending)) * (2 if cfg.echo else 1) + 3
                    t = time.perf_counter()
                    arm.move_to(target)
                    elapsed = time.perf_counter() - t
                    after = arm.where().joints_deg
                    motion = (elapsed - wheres * where_median
                              - wire_time_s(n_bytes, cfg.baudrate, bits))
                    delta = tuple(b - a for a, b in zip(before, after, strict=True))
                    moves.append(TimedMove(delta, speed, motion))
            if out is not None:
                print(f"speed {speed:g}: {distance:g} mm timed", file=out)
    arm.set_speed(100.0)
    return moves


def fitted_config(base: dict, fit: ArmFit) -> dict:
    """``base`` (a root config mapping) with ``timing.arm`` set to ``fit`` (settle in t0)."""
    data = dict(base)
    timing = dict(data.get("timing") or {})
    arm = dict(timing.get("arm") or {})
    arm.update({"t0_s": round(fit.t0_s, 4), "joint_speed_deg_s": round(fit.joint_speed_deg_s, 3),
                "joint_accel_deg_s2": round(fit.joint_accel_deg_s2, 3), "settle_s": 0.0})
    timing["arm"] = arm
    data["timing"] = timing
    config_from_mapping(data, "<fitted>")  # strict check before writing
    return data


def run(args) -> int:
    """Time the moves, fit, print the fit (JSON), write the config if asked."""
    from drivers.val import ValArm

    config = config_from_args(args)
    if config.arm.type != "val":
        raise ConfigError("arm.type: fit-timing times a real VAL arm; the config's arm is "
                          f"{config.arm.type!r} (use arm: {{type: val, port: ...}})")
    distances = _numbers(args.distances, "--distances")
    speeds = _numbers(args.speeds, "--speeds")
    with ValArm(config.arm.options, config.safety) as arm:
        moves = time_moves(arm, distances, speeds, args.repeats)
    fit = fit_arm_timing(moves)
    report = {"t0_s": fit.t0_s, "joint_speed_deg_s": fit.joint_speed_deg_s,
              "joint_accel_deg_s2": fit.joint_accel_deg_s2, "rms_s": fit.rms_s,
              "moves": len(moves), "cruise_reached": fit.cruise_reached,
              "configured": {"t0_s": config.timing.arm.t0_s + config.timing.arm.settle_s,
                             "joint_speed_deg_s": config.timing.arm.joint_speed_deg_s,
                             "joint_accel_deg_s2": config.timing.arm.joint_accel_deg_s2}}
    if fit.cruise_reached == 0:
        print("warning: no move reached cruise speed: joint_speed_deg_s is not determined "
              "(add longer moves or lower speeds)", file=sys.stderr)
    if args.write_config:
        base = load_yaml_file(args.config)
        text = ("# Written by finepos fit-timing: timing.arm fitted to "
                f"{len(moves)} timed moves (rms {fit.rms_s * 1e3:.1f} ms).\n"
                + yaml.safe_dump(fitted_config(base, fit), sort_keys=False))
        atomic_write_text(Path(args.write_config), text)
        print(f"config written to {args.write_config}", file=sys.stderr)
    write_json(args.json, report)
    return 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``finepos fit-timing``."""
    parser.add_argument("--config", required=True, metavar="FILE",
                        help="config whose arm is the VAL arm to time")
    parser.add_argument("--write-config", metavar="OUT", help="write the config with the fit here")
    parser.add_argument("--distances", default=",".join(f"{d:g}" for d in DEFAULT_DISTANCES_MM),
                        help="move distances in mm (default 1,5,10,25)")
    parser.add_argument("--speeds", default=",".join(f"{s:g}" for s in DEFAULT_SPEEDS),
                        help="VAL speeds in percent (default 25,50,100)")
    parser.add_argument("--repeats", type=int, default=2, choices=range(1, 21), metavar="1..20",
                        help="moves per distance and speed, alternating x and y (default 2)")
    parser.add_argument("--json", metavar="OUT", help="also write the fit here")
