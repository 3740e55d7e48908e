"""Table 1 as files: DIR/table1.md, DIR/table1.json and one convergence plot per lighting.

The markdown has every system's accuracy at each loop budget the paper's Table 1 quotes, up to
the 6.5-loop run (1.5 and 2.5: Gabor and Hough; 5: PCA; 6.5: Gabor in poor light), loops to a
safe grasp, every outcome and the failure rate (not safe at the end, whatever the loop
reported), the cost figures, the paper's own numbers for reference, and a computed verdict of
the Gabor system against each baseline per lighting.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from controller.evaluation.comparison.table1 import Table1Result
from controller.evaluation.metrics import SAFE_DEG, SAFE_MM, is_safe, state_at
from controller.evaluation.plots import plot_convergence
from controller.loop.checks import STOPPED
from controller.systems.registry import DEFAULT_SYSTEM
from drivers.core.files import atomic_write_text

TABLE_BUDGETS = (1.5, 2.5, 5.0, 6.5)  # loops: every budget the paper's Table 1 quotes, <= 6.5
VERDICT_BUDGET = 2.5

PAPER_TABLE1 = """\
| system | good light | poor light | rotation features | training |
|---|---|---|---|---|
| gabor | (0.5, 0.7, 6.6 deg) after 1.5 loops, (0.1, 0.3, 1.2 deg) after 2.5; safe after 1.5 \
| (0.2, 0.2, 1 deg) after 6.5 loops; safe after 3.5-5.5 | 36 Gabor masks | < 1 min |
| pca | (0.4, 0.7, 0.6 deg) after 5 loops | (3.1, 1.0, 6.1 deg) after 20 loops \
| 3 eigenimages | 3 h |
| hough | (0.5, 0.8 mm, z 1 mm, 1.4 deg) after 2.5 loops | fails | line Hough transform \
| < 1 min |
"""


def rms_at(trials, budget: float) -> tuple[float, float, float]:
    """RMS (x mm, y mm, phi deg) over trials of the state after ``budget`` loops."""
    errors = np.array([state_at(t, budget).error for t in trials], dtype=float)
    return tuple(float(v) for v in np.sqrt(np.mean(errors**2, axis=0)))


def _triple(rms: tuple[float, float, float]) -> str:
    return f"{rms[0]:.2f}, {rms[1]:.2f}, {rms[2]:.2f}"


def _pct(value: float | None) -> str:
    return "-" if value is None else f"{value * 100:.0f}%"


def _loops(value: float | None) -> str:
    return "never" if value is None else f"{value:g}"


def final_safe(trials) -> list[bool]:
    """Per trial: is the pose the run ended in safe to grasp?"""
    return [is_safe(t[-1].error) for t in trials]


def failure_rate(result: Table1Result, system: str, lighting: str) -> float:
    """Share of trials whose final pose is not safe to grasp, whatever the loop reported: a
    run that stopped (no object, ambiguous, rejected), ran out of loops, or converged off
    target all fail."""
    return 1.0 - float(np.mean(final_safe(result.states[(system, lighting)])))


def _accuracy(result: Table1Result) -> list[str]:
    head = " | ".join(f"after {b:g} loops" for b in TABLE_BUDGETS)
    lines = [f"| system | light | {head} | safe after 1.5 / 2.5 | loops to safe: median / p95 "
             "| never safe |",
             "|---|---|" + "---|" * len(TABLE_BUDGETS) + "---|---|---|"]
    for r in result.reports:
        trials = result.states[(r["system"], r["lighting"])]
        cells = " | ".join(_triple(rms_at(trials, b)) for b in TABLE_BUDGETS)
        safe = r["safe_rate"]
        lts = r["loops_to_safe"]
        lines.append(f"| {r['system']} | {r['lighting']} | {cells} | {_pct(safe['1.5'])} / "
                     f"{_pct(safe['2.5'])} | {_loops(lts['median'])} / {_loops(lts['p95'])} | "
                     f"{lts['never_safe']} of {r['trials']} |")
    return lines


def _failures(result: Table1Result) -> list[str]:
    lines = ["| system | light | converged | budget spent | no object | ambiguous | "
             "out of range | inconsistent | occluded | rejected | converged off target | "
             "failure rate | no-object rate | grasp success |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in result.reports:
        key = (r["system"], r["lighting"])
        o = r["outcomes"]
        counts = " | ".join(str(o.get(k, 0)) for k in ("converged", "budget", *STOPPED))
        off_target = sum(outcome == "converged" and not safe for outcome, safe
                         in zip(result.outcomes[key], final_safe(result.states[key]),
                                strict=True))
        lines.append(f"| {r['system']} | {r['lighting']} | {counts} | {off_target} | "
                     f"{_pct(failure_rate(result, *key))} | "
                     f"{_pct(o.get('no_object', 0) / r['trials'])} | "
                     f"{_pct(r['grasp_success_rate'])} |")
    return lines


def _times(result: Table1Result) -> list[str]:
    def seconds(entry) -> str:
        if not entry:
            return "n/a"
        return " / ".join("never" if entry[k] is None else f"{entry[k]:.2f}"
                          for k in ("median", "p95"))

    def interval(ci) -> str:
        if not ci:
            return "n/a"
        return f"{ci['rate'] * 100:.1f}% ({ci['low'] * 100:.1f}-{ci['high'] * 100:.1f}%)"

    lines = ["| system | light | time to safe [s] | time to grasp [s] | safe after 1.5 loops "
             "| grasp success |", "|---|---|---|---|---|---|"]
    for r in result.reports:
        lines.append(f"| {r['system']} | {r['lighting']} | {seconds(r.get('time_to_safe_s'))} | "
                     f"{seconds(r.get('time_to_grasp_s'))} | "
                     f"{interval(r.get('safe_rate_ci', {}).get('1.5'))} | "
                     f"{interval(r.get('grasp_success_ci'))} |")
    return lines


def _cost(result: Table1Result) -> list[str]:
    lines = ["| system | rotation features | training images | acquisition [s] | training [s] "
             "| per loop, good / poor light [ms] |",
             "|---|---|---|---|---|---|"]
    by_system: dict[str, list[dict]] = {}
    for r in result.reports:
        by_system.setdefault(r["system"], []).append(r)
    for system, rs in by_system.items():
        r = rs[0]
        per_loop = " / ".join("-" if x["seconds_per_loop"] is None
                              else f"{x['seconds_per_loop'] * 1e3:.0f}" for x in rs)
        lines.append(f"| {system} | {r['feature_count']} | {result.acquisition['images']} | "
                     f"{result.acquisition['acquire_seconds']:.1f} | {r['train_seconds']:.1f} | "
                     f"{per_loop} |")
    return lines


def _fmt(value: float, unit: str) -> str:
    if unit == "loops":
        return "never" if math.isinf(value) else f"{value:g}"
    return f"{value:.3f}"


def _winner(ours: float, theirs: float, baseline: str) -> str:
    if ours == theirs:
        return "tie"
    return "gabor better" if ours < theirs else f"{baseline} better"


def _paired(name: str, ours: np.ndarray, theirs: np.ndarray, unit: str, baseline: str) -> str:
    """RMS of each side, who is better, and whether that is beyond the trial-to-trial noise:
    the per-trial difference of squared errors (same placements on both sides) must differ
    from zero by more than twice its standard error."""
    rms_ours, rms_theirs = (float(np.sqrt(np.mean(e**2))) for e in (ours, theirs))
    text = f"{name} {_fmt(rms_ours, unit)} vs {_fmt(rms_theirs, unit)} {unit} " \
           f"({_winner(rms_ours, rms_theirs, baseline)}"
    diff = ours**2 - theirs**2
    if diff.size > 1 and rms_ours != rms_theirs:
        se = float(diff.std(ddof=1)) / math.sqrt(diff.size)
        text += ", clear" if abs(diff.mean()) > 2 * se else ", within noise"
    return text + ")"


def _errors_at(trials, budget: float) -> tuple[np.ndarray, np.ndarray]:
    """Per trial: position error (mm) and angle error (deg) after ``budget`` loops."""
    e = np.array([state_at(t, budget).error for t in trials], dtype=float)
    return np.hypot(e[:, 0], e[:, 1]), e[:, 2]


def verdict(result: Table1Result) -> list[str]:
    """One computed line per lighting and baseline: Gabor against it on position and angle RMS
    after 2.5 loops (paired over the same trials), median loops to a safe grasp (never =
    infinite) and failure rate; lower is better everywhere."""
    reports = {(r["system"], r["lighting"]): r for r in result.reports}
    lines = []
    for (system, lighting), r in reports.items():
        gabor = reports.get(("gabor", lighting))
        if system == DEFAULT_SYSTEM or gabor is None:
            continue
        g_pos, g_phi = _errors_at(result.states[("gabor", lighting)], VERDICT_BUDGET)
        b_pos, b_phi = _errors_at(result.states[(system, lighting)], VERDICT_BUDGET)
        medians = [math.inf if rep["loops_to_safe"]["median"] is None
                   else rep["loops_to_safe"]["median"] for rep in (gabor, r)]
        fails = [failure_rate(result, s, lighting) for s in ("gabor", system)]
        parts = [
            _paired(f"position RMS after {VERDICT_BUDGET:g} loops", g_pos, b_pos, "mm", system),
            _paired(f"angle RMS after {VERDICT_BUDGET:g} loops", g_phi, b_phi, "deg", system),
            f"median loops to a safe grasp {_fmt(medians[0], 'loops')} vs "
            f"{_fmt(medians[1], 'loops')} ({_winner(*medians, system)})",
            f"failure rate {_pct(fails[0])} vs {_pct(fails[1])} ({_winner(*fails, system)})"]
        lines.append(f"- {lighting} light, gabor vs {system}: " + "; ".join(parts) + ".")
    return lines


def why(result: Table1Result) -> list[str]:
    """Where Gabor is not clearly better, and why; and what the poor-light gap is made of."""
    lines = []
    ties = [line for line in verdict(result) if "within noise" in line or "tie" in line
            or "better, clear" in line and "gabor better, clear" not in line]
    if ties:
        lines.append("- Where Gabor is not clearly better (see the verdict): in good light every "
                     "system ends near the simulated cell's floor (arm repeatability 0.02 mm / "
                     "0.02 deg, camera noise); PCA and Hough share the Gabor system's "
                     "translation path from the object centre (PCA uses its NN1, Hough's PSOM "
                     "maps the same centres), so what remains to compare is the rotation, "
                     "which they resolve to a few tenths of a degree when the image is clean.")
    if any(r["system"] == "align" for r in result.reports):
        lines.append("- The image-alignment servo (align) localises in the Gabor system's "
                     "channel and registers the part's whole soft silhouette to the taught "
                     "one (a rotation scan, then ECC with an affine warp) and maps the shift "
                     "and turn to the tool step by least squares. Where the light changes the "
                     "part's outline itself (poor light), the registration of the whole "
                     "silhouette moves with it as the blob's centre does.")
    channels = result.channels
    if channels and len(set(channels.values())) > 1:
        listed = ", ".join(f"{s}: {c}" for s, c in channels.items())
        lines.append(f"- Localisation channels ({listed}). In poor light most of the gap comes "
                     "from there, not from the rotation features: the low side lamp puts the "
                     "gripper's shadow across the part, and in max(R,G,B) the shaded faces are "
                     "as dark as the table, so the blob's centre moves by millimetres; "
                     "saturation is unchanged by shade. The paper's two baselines keep its "
                     "max(R,G,B) localisation.")
    return lines


def table1_markdown(result: Table1Result, source: str) -> str:
    """The whole DIR/table1.md."""
    first = result.reports[0]
    systems = list(dict.fromkeys(r["system"] for r in result.reports))
    lightings = list(dict.fromkeys(r["lighting"] for r in result.reports))
    lines = [
        "# Table 1 on the simulated cell",
        "",
        f"{first['trials']} random placements per system and lighting, seed {first['seed']}: "
        f"every system ({', '.join(systems)}) meets the same placements and start offsets "
        f"(uniform in +/-25 mm, +/-180/kappa deg) in every lighting ({', '.join(lightings)}). "
        f"Each system was trained once, on the default scene in good light, from the same "
        f"{result.acquisition['images']} images (the 3x3x7 NN1 and NN2 grids), then evaluated "
        f"in each lighting. Loop budget {result.budget_loops:g} loops (a half loop is a pure "
        f"translation). Safe grasp: position error <= {SAFE_MM:g} mm and |phi| <= "
        f"{SAFE_DEG:g} deg. Object: {first['object']}; config: {source}. Wall time "
        f"{result.wall_seconds:.0f} s with {result.workers} parallel jobs.",
        "",
        "## Accuracy",
        "",
        "RMS error (x mm, y mm, phi deg) of the pose after the loop budget. A trial that "
        "stopped early (no object found, ambiguous, rejected) keeps the error it stopped with: "
        "failures count, they are not dropped.",
        "",
        *_accuracy(result),
        "",
        "## Outcomes and failures",
        "",
        "Failure rate: trials whose final pose is not safe to grasp, whatever the loop "
        "reported: stopped early (no object, ambiguous, rejected), out of loops (budget spent) "
        "or converged off target (the loop saw no further correction to make, but the pose "
        "is not safe). Grasp success: the simulated guarded grasp held the part.",
        "",
        *_failures(result),
        "",
        "## Time and intervals",
        "",
        f"Cell seconds ({first.get('timing') or 'unknown'} timing) from the start of "
        "positioning to the first safe pose and to the part held after the lift (median / "
        "p95), and the rates with their 95% Wilson intervals.",
        "",
        *_times(result),
        "",
        "## Cost",
        "",
        "Training images: distinct images acquired (every system uses the same ones). Per "
        "loop: median wall time of one look-and-move iteration in simulation, measured while "
        f"{result.workers} jobs shared the machine; on the real arm motion adds 1-2 s.",
        "",
        *_cost(result),
        "",
        "## Verdict (computed from the tables above)",
        "",
        "Every system met the same placements, so differences are paired per trial: "
        "\"clear\" when the mean per-trial difference of squared errors is more than twice "
        "its standard error, \"within noise\" otherwise.",
        "",
        *(verdict(result) or ["- (no Gabor run to compare against)"]),
        "",
        "## Why",
        "",
        *(why(result) or ["- Gabor is clearly better everywhere above."]),
        "",
        "## The paper's Table 1 (real cell), for reference",
        "",
        PAPER_TABLE1,
    ]
    return "\n".join(lines)


def write_table1(result: Table1Result, out_dir: str | Path, source: str) -> dict[str, Path]:
    """Write table1.md, table1.json and convergence-<lighting>.png; returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"markdown": out / "table1.md", "json": out / "table1.json"}
    atomic_write_text(paths["markdown"], table1_markdown(result, source))
    atomic_write_text(paths["json"], json.dumps(result.reports, indent=2) + "\n")
    for lighting in dict.fromkeys(r["lighting"] for r in result.reports):
        curves = {system: states for (system, light), states in result.states.items()
                  if light == lighting}
        paths[f"plot_{lighting}"] = plot_convergence(
            curves, out / f"convergence-{lighting}.png",
            title=f"Table 1, {lighting} light: RMS error against loops "
                  f"({result.reports[0]['trials']} trials per system)")
    return paths
