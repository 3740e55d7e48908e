"""Write the results page (docs/results.md) from finepos evaluate --json reports.

Example: finepos docs results --reports docs/results --out docs/results.md

Every ``*.json`` file under ``--reports`` holds one ``finepos evaluate`` report, or a list or
mapping of them (``--part all --json`` writes every row's). Each report becomes one row: the
part, the light, the system, trials and seed, the safe rates within 1.5 and 2.5 loops, the RMS
of x, y and the angle after 2.5 loops, the median time to a held part, and the exact command
that wrote it (the report's ``command``, which starts with ``finepos``). A report without a
``command`` is refused: a row nobody can reproduce does not belong on the page.
``tests/controller/docs/test_results_page.py`` parses every quoted command with the real
argument parser.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from controller.docs.config_reference import write_or_check
from drivers.core.errors import ConfigError

COMMAND = "finepos docs results --reports docs/results --out docs/results.md"
BUDGET = "2.5"  # the loop budget the RMS columns are taken after


def load_reports(folder: str | Path) -> list[tuple[str, dict]]:
    """``(file name, report)`` for every report under ``folder``, in file-name order.

    Raises:
        ConfigError: a file that is not JSON, holds no evaluate report, or a report without
            its ``command``.
    """
    found = []
    for path in sorted(Path(folder).rglob("*.json")):
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise ConfigError(f"{path}: not a JSON report: {exc}") from exc
        reports = list(_reports(data))
        if not reports:
            raise ConfigError(f"{path}: holds no finepos evaluate report")
        for report in reports:
            if not str(report.get("command") or "").startswith("finepos "):
                raise ConfigError(f"{path}: a report without its command (re-run it with a "
                                  "finepos that records the command line)")
            found.append((path.name, report))
    return found


def _reports(data: Any, command: str | None = None) -> Iterator[dict]:
    """The evaluate reports in a file's JSON: one, a list of them, or a mapping of them (the
    rows of ``evaluate --part all``: each without a command of its own takes the one of the
    report holding it)."""
    if isinstance(data, dict) and (("rms" in data and "safe_rate" in data)
                                   or data.get("randomize") is True):
        yield data if data.get("command") or command is None else {**data, "command": command}
    elif isinstance(data, dict):
        for value in data.values():
            yield from _reports(value, data.get("command") or command)
    elif isinstance(data, list):
        for value in data:
            yield from _reports(value, command)


def row(report: dict) -> list[str]:
    """One table row of ``report``."""
    rms = report.get("rms", {}).get(BUDGET) or {}
    safe = report.get("safe_rate", {})
    grasp = report.get("time_to_grasp_s") or {}
    return [str(report.get("object", "")), str(report.get("lighting", "")),
            str(report.get("system", "")), str(report.get("trials", "")),
            str(report.get("seed", "")), _percent(safe.get("1.5")), _percent(safe.get(BUDGET)),
            _number(rms.get("x_mm"), 3), _number(rms.get("y_mm"), 3),
            _number(rms.get("phi_deg"), 2), _number(grasp.get("median"), 2),
            f"`{report['command']}`"]


def randomized_row(report: dict) -> list[str]:
    """One row of the randomized-cell table: the yardstick's figures of ``report``."""
    seen = report.get("visible_0.8") or {}
    rms = seen.get("rms_2.5") or {}
    stops = (report.get("stops_visible_0.85") or {}).get("stops") or {}
    worst = report.get("worst_class") or {}
    targets = report.get("targets") or {}
    return [str(report.get("object", "")), str(report.get("system", "")),
            str(report.get("trials", "")), str(report.get("seed", "")),
            str(len(report.get("cells") or [])), _interval(seen.get("safe_2.5")),
            _number(rms.get("x_mm"), 3), _number(rms.get("y_mm"), 3),
            _number(rms.get("phi_deg"), 2), _interval(stops),
            f"{worst.get('factor', '')} {worst.get('class', '')}: "
            f"{_interval(worst.get('safe_2.5'))}"
            if worst else "",
            f"{sum(bool(v) for v in targets.values())} of {len(targets)}",
            _number((report.get("wall_seconds") or 0) / 60.0, 1), f"`{report['command']}`"]


def _interval(rate: Any) -> str:
    """A Wilson rate ``{"rate", "low", "high"}`` in percent, with its interval."""
    if not rate:
        return ""
    return (f"{100.0 * rate['rate']:.1f} ({100.0 * rate['low']:.1f}-"
            f"{100.0 * rate['high']:.1f})")


def _factor_tables(reports: list[dict]) -> list[str]:
    """Per randomized report, its results by drawn factor (a collapsed table)."""
    lines = []
    for report in reports:
        lines += ["", f"<details><summary>By drawn factor: {report['object']}, "
                      f"{report['system']}, seed {report['seed']}</summary>", "",
                  "| factor | class | trials | safe 2.5 (%) | x (mm) | y (mm) | angle (deg) |",
                  "|---|---|---|---|---|---|---|"]
        for name, rows in (report.get("by_factor") or {}).items():
            for r in rows:
                rms = r.get("rms_2.5") or {}
                lines.append(f"| {name} | {r['class']} | {r['trials']} | "
                             f"{_interval(r.get('safe_2.5'))} | {_number(rms.get('x_mm'), 3)} | "
                             f"{_number(rms.get('y_mm'), 3)} | "
                             f"{_number(rms.get('phi_deg'), 2)} |")
        lines += ["", "</details>"]
    return lines


def _percent(value: Any) -> str:
    return "" if value is None else f"{100.0 * float(value):.1f}"


def _number(value: Any, digits: int) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    return f"{float(value):.{digits}f}"


def render(reports: list[tuple[str, dict]]) -> str:
    """The whole page (Markdown)."""
    lines = [
        "# Results",
        "",
        f"<!-- Generated by `{COMMAND}`; do not edit. -->",
        "",
        "One row per `finepos evaluate --json` report in `docs/results/`, measured on the",
        "simulated cell. Each row's command reproduces it: run it from the checkout, put the",
        "report it writes (`--json FILE`) into `docs/results/`, and regenerate this page with",
        f"`{COMMAND}`.",
        "",
        f"Safe rates are the share of trials within the grasp tolerance (2 mm, 5 deg) after 1.5 "
        f"and {BUDGET} loops, in percent; RMS after {BUDGET} loops; the time to a held part is "
        "the median in cell seconds (empty where the run did not grasp).",
        "",
    ]
    if not reports:
        lines += ["No reports yet."]
        return "\n".join(lines) + "\n"
    randomized = sorted((r for _, r in reports if r.get("randomize") is True),
                        key=lambda r: (str(r.get("object")), str(r.get("system")),
                                       str(r.get("seed")), str(r.get("command"))))
    reports = [(name, r) for name, r in reports if r.get("randomize") is not True]
    if randomized:
        lines += [
            "## Randomized cells",
            "",
            "`finepos evaluate --randomize`: every cell draws its camera, mount, table and "
            "part colour and is trained under a drawn light; every trial draws its light, a "
            "card over the part and clutter (docs/simulator.md). Safe within 2.5 loops and "
            "the RMS after 2.5 loops are over the trials where at least 80% of the part is "
            "visible; stops (occluded, ambiguous, no object) over those where 85% is; rates in "
            "percent with their 95% Wilson intervals. The weakest class is the drawn factor's "
            "class (10 trials or more) with the lowest safe rate. Targets: safe at least 99%, "
            "RMS at most 0.05 / 0.05 mm and 0.3 deg, no class below 97%, stops at most 2%.",
            "",
            "| part | system | trials | seed | cells | safe 2.5 (%) | x (mm) | y (mm) "
            "| angle (deg) | stops (%) | weakest class (%) | targets met | wall (min) "
            "| command |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        lines += ["| " + " | ".join(randomized_row(r)) + " |" for r in randomized]
        lines += _factor_tables(randomized)
        lines += [""]
    if not reports:
        return "\n".join(lines) + "\n"
    lines += ["## Default cell", "",
        f"| part | light | system | trials | seed | safe 1.5 (%) | safe {BUDGET} (%) | x (mm) "
        "| y (mm) | angle (deg) | held part (s) | command |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    ordered = sorted((r for _, r in reports),
                     key=lambda r: (str(r.get("object")), str(r.get("lighting")),
                                    str(r.get("system")), str(r.get("seed")),
                                    str(r.get("command"))))
    lines += ["| " + " | ".join(row(r)) + " |" for r in ordered]
    return "\n".join(lines) + "\n"


def commands(page: str) -> list[str]:
    """Every ``finepos ...`` command quoted in a results page's rows."""
    found = []
    for line in page.splitlines():
        if line.startswith("| ") and "`finepos " in line:
            found.append(line.rsplit("`finepos ", 1)[1].rsplit("`", 1)[0])
    return ["finepos " + text for text in found]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``finepos docs results`` options."""
    parser.add_argument("--reports", metavar="DIR", default="docs/results",
                        help="folder of finepos evaluate --json reports (default docs/results)")
    parser.add_argument("--out", metavar="FILE", help="write the page here (default: stdout)")
    parser.add_argument("--check", action="store_true",
                        help="with --out: exit 1 when FILE differs from the reports, write "
                             "nothing")


def run(args) -> int:
    """Write (or check) the page; 1 when ``--check`` finds it out of date."""
    return write_or_check(render(load_reports(args.reports)), args.out, args.check, COMMAND)
