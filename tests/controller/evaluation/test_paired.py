"""Two runs on the same trials compared trial by trial (``finepos compare``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from controller.cli import main
from controller.evaluation.paired import compare, load_states
from controller.loop.positioning import LoopState
from drivers.core.errors import FineposError


def _run(finals: np.ndarray, starts: np.ndarray) -> list[list[LoopState]]:
    """Trials that start at ``starts`` and end (after 1.5 loops) at ``finals``."""
    return [[LoopState(0.0, tuple(s)), LoopState(0.5, (1.0, 1.0, 5.0)),
             LoopState(1.5, tuple(f))] for s, f in zip(starts, finals, strict=True)]


@pytest.fixture
def trials():
    rng = np.random.default_rng(4)
    starts = rng.uniform(-25, 25, (120, 3))
    noise = rng.normal(0.0, 1.0, (120, 3)) * [0.05, 0.05, 0.3]
    return starts, noise


def test_a_run_against_itself_is_level(trials):
    starts, noise = trials
    run = _run(noise, starts)
    report = compare(run, run, budgets=(1.5,), resamples=500)
    for figure in report["budgets"]["1.5"]["first_less_second"].values():
        assert figure["difference"] == 0.0 and figure["verdict"] == "level"


def test_smaller_errors_are_ahead_and_the_axes_are_told_apart(trials):
    starts, noise = trials
    # the first run: x halved, y doubled, phi the same; the second: the noise as it is
    first = _run(noise * [0.5, 2.0, 1.0], starts)
    second = _run(noise, starts)
    report = compare(first, second, budgets=(1.5,), resamples=1000)
    figures = report["budgets"]["1.5"]
    diff = figures["first_less_second"]
    assert diff["x_mm"]["verdict"] == "ahead" and diff["x_mm"]["high"] < 0
    assert diff["y_mm"]["verdict"] == "behind" and diff["y_mm"]["low"] > 0
    assert diff["phi_deg"]["verdict"] == "level"
    assert diff["phi_deg"]["low"] <= 0.0 <= diff["phi_deg"]["high"]
    rms = np.sqrt(np.mean(noise**2, axis=0))
    assert figures["second"]["x_mm"] == pytest.approx(rms[0])
    assert figures["first"]["y_mm"] == pytest.approx(2 * rms[1])
    assert figures["second"]["distance_mm"] == pytest.approx(np.hypot(rms[0], rms[1]))
    assert diff["x_mm"]["difference"] == pytest.approx(-0.5 * rms[0])


def test_the_budget_picks_the_state(trials):
    starts, noise = trials
    report = compare(_run(noise, starts), _run(noise * 3, starts), budgets=(0.5, 1.5),
                     resamples=200)
    # after half a loop both runs are at (1, 1, 5): level; after 1.5 the first is ahead
    assert report["budgets"]["0.5"]["first"]["x_mm"] == pytest.approx(1.0)
    assert report["budgets"]["0.5"]["first_less_second"]["x_mm"]["verdict"] == "level"
    assert report["budgets"]["1.5"]["first_less_second"]["x_mm"]["verdict"] == "ahead"


def test_other_trials_are_refused(trials):
    starts, noise = trials
    run = _run(noise, starts)
    with pytest.raises(FineposError, match="hold 120 and 119 trials"):
        compare(run, run[:-1])
    moved = starts.copy()
    moved[7, 0] += 3.0
    with pytest.raises(FineposError, match="trial 7 starts 3.00 / 0.00 mm"):
        compare(run, _run(noise, moved))


@pytest.mark.parametrize(("text", "message"), [
    ("xx", "not JSON"),
    ("[]", "expected a list of trials"),
    ("[5]", "trial 0 is not a list"),
    ("[[[0, null]]]", "trial 0 has a state that is not"),
    ("[[[0, [1, 2]]]]", "trial 0 has a state that is not"),
    ("[[[0, [1, 2, NaN]]]]", "trial 0 has a state that is not"),
    ('[[["0", [1, 2, 3]]]]', "trial 0 has a state that is not"),
])
def test_a_bad_states_file_is_named_in_one_line(tmp_path, text, message):
    path = tmp_path / "states.json"
    path.write_text(text)
    with pytest.raises(FineposError, match=message) as info:
        load_states(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_the_command_prints_and_writes_the_report(tmp_path, trials, capsys):
    starts, noise = trials
    for name, scale in (("a.json", 0.5), ("b.json", 1.0)):
        (tmp_path / name).write_text(json.dumps(
            [[[s.loops, list(s.error)] for s in t] for t in _run(noise * scale, starts)]))
    out = tmp_path / "report.json"
    rc = main(["compare", str(tmp_path / "a.json"), str(tmp_path / "b.json"), "--budgets", "1.5",
               "--resamples", "300", "--json", str(out)])
    assert rc == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == json.loads(out.read_text())
    assert printed["trials"] == 120 and list(printed["budgets"]) == ["1.5"]
    assert printed["budgets"]["1.5"]["first_less_second"]["distance_mm"]["verdict"] == "ahead"


def test_the_command_stops_in_one_line_on_a_missing_file(tmp_path, capsys):
    rc = main(["compare", str(tmp_path / "none.json"), str(tmp_path / "none.json")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "none.json: cannot read" in err and len(err.splitlines()) == 1
