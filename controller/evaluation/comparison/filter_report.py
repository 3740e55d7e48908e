"""The filter search as files: DIR/filter_search.json, DIR/filter_search.md and a Fig. 5-style
bar plot DIR/filter_search.png (mean and spread over repeats, the paper's set highlighted).

Spread is the sample standard deviation over repeats. Because every set meets the same seeds,
the paper's set is also compared with the winner pair-wise: the mean over repeats of the
difference in closed-loop angle RMS, with its standard error.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path

import numpy as np

from controller.evaluation.comparison.filter_search import SEARCH_BUDGET, SearchResult, SetRun
from controller.evaluation.comparison.filter_sets import PAPER_SET
from drivers.core.files import atomic_write_text


def _stats(values: list[float]) -> dict:
    a = np.asarray(values, dtype=float)
    return {"mean": float(a.mean()), "std": float(a.std(ddof=1)) if a.size > 1 else 0.0,
            "min": float(a.min()), "max": float(a.max())}


def _metrics(run: SetRun) -> dict[str, float]:
    x, y, phi = run.closed_rms
    return {"closed_phi_rms_deg": phi, "closed_position_rms_mm": math.hypot(x, y),
            "closed_x_rms_mm": x, "closed_y_rms_mm": y,
            "open_loop_phi_rms_deg": run.open_loop_phi_rms_deg, "safe_rate": run.safe_rate,
            "nn2_seconds": run.nn2_seconds}


def summarise_search(result: SearchResult) -> dict:
    """Per-set statistics over repeats, the ranking, the winner and the paper set's place.

    Sets are ranked by mean closed-loop angle RMS after SEARCH_BUDGET loops (lower is better).
    """
    by_set: dict[str, list[SetRun]] = {name: [] for name in result.sets}
    for run in result.runs:
        by_set[run.name].append(run)
    summaries = []
    for name, runs in by_set.items():
        runs = sorted(runs, key=lambda r: r.repeat)
        metrics = [_metrics(r) for r in runs]
        summaries.append({
            "name": name,
            "gabor": asdict(result.sets[name]),
            "feature_count": runs[0].feature_count,
            **{key: _stats([m[key] for m in metrics]) for key in metrics[0]},
            "failures": sum(r.failures for r in runs),
            "repeats": [{"repeat": r.repeat, "seed": r.seed, **m}
                        for r, m in zip(runs, metrics, strict=True)],
        })
    summaries.sort(key=lambda s: s["closed_phi_rms_deg"]["mean"])
    for rank, s in enumerate(summaries, start=1):
        s["rank"] = rank
    winner = summaries[0]
    out = {
        "settings": {"repeats": result.repeats, "trials": result.trials, "seed": result.seed,
                     "budget_loops": SEARCH_BUDGET, "test_images": result.test_images,
                     "workers": result.workers, "wall_seconds": result.wall_seconds,
                     "scene": result.source,
                     "ranking": f"mean closed-loop angle RMS after {SEARCH_BUDGET:g} loops"},
        "winner": winner["name"],
        "sets": summaries,
    }
    paper = next((s for s in summaries if s["name"] == PAPER_SET), None)
    if paper is not None:
        diffs = [p["closed_phi_rms_deg"] - w["closed_phi_rms_deg"]
                 for p, w in zip(paper["repeats"], winner["repeats"], strict=True)]
        stats = _stats(diffs)
        out["paper_set"] = {"name": PAPER_SET, "rank": paper["rank"],
                            "paired_difference_deg": stats["mean"],
                            "paired_difference_se_deg": stats["std"] / math.sqrt(len(diffs))}
    return out


def _ms(stats: dict, digits: int = 2) -> str:
    return f"{stats['mean']:.{digits}f} ± {stats['std']:.{digits}f}"


def _paper_sentence(summary: dict) -> str:
    paper = summary.get("paper_set")
    if paper is None:
        return f"The paper's set ({PAPER_SET}) was not part of this search."
    if paper["rank"] == 1:
        return f"The paper's set ({PAPER_SET}) wins, as in the paper."
    diff, se = paper["paired_difference_deg"], paper["paired_difference_se_deg"]
    clear = diff > 2 * se
    return (f"The paper's set ({PAPER_SET}) ranks {paper['rank']} of {len(summary['sets'])}; "
            f"paired with the winner over the same seeds, its angle RMS is higher by "
            f"{diff:.3f} ± {se:.3f} deg (mean ± standard error of the per-repeat differences): "
            + ("more than twice the standard error, a real if small loss."
               if clear else "within twice the standard error, not a clear loss."))


def search_markdown(summary: dict) -> str:
    """The whole DIR/filter_search.md."""
    st = summary["settings"]
    lines = [
        "# Gabor filter search (the paper's Fig. 5) on the simulated cell",
        "",
        f"{len(summary['sets'])} filter sets, each trained and evaluated {st['repeats']} times "
        f"(seeds {st['seed']}..{st['seed'] + st['repeats'] - 1}, the same for every set). "
        f"Training images acquired once (the 3x3x7 NN1 and NN2 grids on the default scene); "
        f"per repeat, NN2 is retrained on each set's features of the stored ROIs (NN1 and the "
        f"localisation are shared). Closed loop: {st['trials']} random placements per set and "
        f"repeat on the config's scene ({st['scene']}), RMS after {st['budget_loops']:g} loops, "
        f"no grasp. Open loop: NN2's rotation RMS on {st['test_images']} random test images "
        f"per repeat near the nominal pose (NN2's domain). Ranked by {st['ranking']}. "
        f"Values: mean ± standard deviation over repeats. Wall time {st['wall_seconds']:.0f} s "
        f"with {st['workers']} parallel jobs.",
        "",
        f"**Winner: {summary['winner']}.** {_paper_sentence(summary)}",
        "",
        "| rank | filter set | features | closed-loop phi RMS [deg] | closed-loop position RMS "
        "[mm] | open-loop phi RMS [deg] | safe after 2.5 loops | stopped early (trials) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for s in summary["sets"]:
        lines.append(f"| {s['rank']} | {s['name']} | {s['feature_count']} | "
                     f"{_ms(s['closed_phi_rms_deg'])} | {_ms(s['closed_position_rms_mm'], 3)} | "
                     f"{_ms(s['open_loop_phi_rms_deg'])} | {s['safe_rate']['mean'] * 100:.0f}% | "
                     f"{s['failures']} |")
    lines += ["", "Filter set names: `<grid>x<grid>x<orientations>-l<lambda px>-s<sigma px>-"
              "<kind>`; grid centres 12 px apart, centred in the 50x50 ROI; orientations evenly "
              "over 180 deg; alpha 1.", ""]
    return "\n".join(lines)


def plot_search(summary: dict, path: str | Path) -> Path:
    """Bars of mean closed- and open-loop angle RMS per set with their spread (Fig. 5)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sets = summary["sets"]
    names = [s["name"] for s in sets]
    colours = ["tab:orange" if n == PAPER_SET else "tab:blue" for n in names]
    y = np.arange(len(sets))
    fig, axes = plt.subplots(1, 2, figsize=(12, 0.35 * len(sets) + 2), sharey=True,
                             constrained_layout=True)
    for ax, key, title in (
            (axes[0], "closed_phi_rms_deg",
             f"closed loop: angle RMS after {summary['settings']['budget_loops']:g} loops"),
            (axes[1], "open_loop_phi_rms_deg", "open loop: NN2 angle RMS on test images")):
        ax.barh(y, [s[key]["mean"] for s in sets], xerr=[s[key]["std"] for s in sets],
                color=colours, capsize=3)
        ax.set_title(title)
        ax.set_xlabel("RMS [deg] (mean ± std over repeats)")
        ax.grid(True, axis="x", alpha=0.3)
    axes[0].set_yticks(y, names)
    axes[0].invert_yaxis()
    fig.suptitle(f"Gabor filter sets, best first (orange: the paper's set; "
                 f"{summary['settings']['repeats']} repeats)")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def write_search(result: SearchResult, out_dir: str | Path) -> tuple[dict, dict[str, Path]]:
    """Write filter_search.json, .md and .png; returns the summary and the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = summarise_search(result)
    paths = {"json": out / "filter_search.json", "markdown": out / "filter_search.md",
             "plot": out / "filter_search.png"}
    atomic_write_text(paths["json"], json.dumps(summary, indent=2) + "\n")
    atomic_write_text(paths["markdown"], search_markdown(summary))
    plot_search(summary, paths["plot"])
    return summary, paths
