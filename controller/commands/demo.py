"""The whole job on the simulated cell: teach, acquire, train, evaluate.

Auto-teach, acquire the NN1 and NN2 grids, train, then position and grasp 50 random placements
in good and in poor light; writes a table, a convergence plot, the logs and a replay of the
first trial in each light (replay-<light>.mcap, .mp4, .png). --part NAME: the whole job with
that part on the table (default: the scene's).

Example: finepos demo --out out/demo
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from controller.commands.common import (
    add_config_option,
    add_part_option,
    add_recipe_option,
    add_timing_option,
    positive_int,
    run_config_from_args,
)
from controller.evaluation.metrics import summarise, wilson
from controller.evaluation.plots import plot_convergence
from controller.evaluation.trials import run_trials, train_on_default_scene, with_lighting
from controller.loop.iteration_log import IterationLog
from controller.recording.replay import read_looks, write_sheet, write_video
from controller.recording.writer import RunRecorder
from drivers.core.files import atomic_write_text

LIGHTINGS = ("good", "poor")


def table_markdown(reports: dict[str, dict]) -> str:
    """Markdown: RMS error and safe rate per lighting and loop budget, then one line per lighting.

    The per-lighting lines give loops to a safe grasp (median, p95), grasp success and the
    median time per loop.

    Args:
        reports: per lighting, a ``metrics.summarise`` report with ``grasp_success_rate`` (0..1)
            and ``seconds_per_loop`` added.
    """
    budgets = ("0.5", "1.0", "1.5", "2.5", "3.5", "6.5")
    lines = ["| lighting | loops | x RMS [mm] | y RMS [mm] | phi RMS [deg] | safe |",
             "|---|---|---|---|---|---|"]
    for lighting, r in reports.items():
        for b in budgets:
            rms = r["rms"][b]
            safe = r["safe_rate"].get(b)
            safe_txt = f"{safe * 100:.0f}%" if safe is not None else ""
            lines.append(f"| {lighting} | {b} | {rms['x_mm']:.3f} | {rms['y_mm']:.3f} | "
                         f"{rms['phi_deg']:.2f} | {safe_txt} |")
    lines.append("")
    def loops(value) -> str:
        return "never" if value is None else f"{value:g}"

    def seconds(entry) -> str:
        if entry is None:
            return "n/a"
        return "/".join("never" if entry[k] is None else f"{entry[k]:.2f} s"
                        for k in ("median", "p95"))

    for lighting, r in reports.items():
        lts = r["loops_to_safe"]
        ci = r["grasp_success_ci"]
        lines.append(f"- {lighting} light: loops to a safe grasp median {loops(lts['median'])}, "
                     f"p95 {loops(lts['p95'])}; grasp success "
                     f"{r['grasp_success_rate'] * 100:.0f}% (95% CI {ci['low'] * 100:.0f}-"
                     f"{ci['high'] * 100:.0f}%); time to safe (median/p95) "
                     f"{seconds(r.get('time_to_safe_s'))}, to grasp "
                     f"{seconds(r.get('time_to_grasp_s'))} (cell seconds, {r['timing']} "
                     f"timing); {r['seconds_per_loop'] * 1e3:.1f} ms wall time per loop")
    return "\n".join(lines) + "\n"


def write_replay(recording: Path) -> tuple[Path, Path]:
    """The recording's video and contact sheet, next to it (same name, .mp4 and .png)."""
    looks = read_looks(recording)
    return (write_video(looks, recording.with_suffix(".mp4")),
            write_sheet(looks, recording.with_suffix(".png")))


def run(args) -> int:
    """Teach, acquire, train and evaluate gabor in good and poor light; write all to ``--out``."""
    config = run_config_from_args(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="finepos-demo-") as tmp:
        print("teach-in (auto), acquisition of the nn1 and nn2 sets, training ...",
              file=sys.stderr)
        model, acq = train_on_default_scene("gabor", config, Path(tmp) / "train", args.seed)
        model.model.save(out / "model-gabor.fpm")
        reports, curves, replays = {}, {}, []
        with IterationLog(out / "iterations.jsonl") as log:
            for i, lighting in enumerate(LIGHTINGS):
                recording = out / f"replay-{lighting}.mcap"
                with RunRecorder(recording, max_runs=1) as recorder:  # the first trial
                    run = run_trials("gabor", model, with_lighting(config, lighting),
                                     args.trials, args.seed + i,
                                     work_dir=Path(tmp) / lighting, log=log,
                                     recorder=recorder)
                replays.append(write_replay(recording))
                r = summarise(run["states"], run["state_times"], run["grasp_times"])
                r["grasp_success_rate"] = sum(run["grasps"]) / len(run["grasps"])
                r["grasp_success_ci"] = wilson(sum(run["grasps"]), len(run["grasps"]))
                r["timing"] = run["timing"]
                times = sorted(run["seconds_per_iteration"])
                r["seconds_per_loop"] = times[len(times) // 2]
                reports[lighting] = r
                curves[f"{lighting} light"] = run["states"]
    summary = {"train_images": model.train_images, "train_seconds": model.train_seconds,
               "acquire_seconds": acq["acquire_seconds"], "trials": args.trials,
               "seconds_total": time.perf_counter() - t0, "results": reports}
    atomic_write_text(out / "report.json", json.dumps(summary, indent=2) + "\n")
    table = table_markdown(reports)
    atomic_write_text(out / "table.md", table)
    plot = plot_convergence(curves, out / "convergence.png")
    print(table)
    print(f"report: {out / 'report.json'}\ntable:  {out / 'table.md'}\nplot:   {plot}\n"
          f"log:    {out / 'iterations.jsonl'}\nmodel:  {out / 'model-gabor.fpm'}\n"
          + "".join(f"replay: {video} {sheet}\n" for video, sheet in replays)
          + f"total {summary['seconds_total']:.0f} s")
    return 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``finepos demo``."""
    add_config_option(parser)
    add_recipe_option(parser)
    add_part_option(parser, "the scene's, scene.object.kind")
    parser.add_argument("--out", default="out/demo", help="output folder")
    parser.add_argument("--trials", type=positive_int, default=50, help="placements per lighting")
    parser.add_argument("--seed", type=int, default=1)
    add_timing_option(parser)
