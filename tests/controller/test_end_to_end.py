"""End to end on the simulated cell: teach, acquire, train, position, grasp; the CLI."""

import dataclasses
import json
import math

import numpy as np
import pytest

from controller.calibration.rezero import REZERO_FRAMES
from controller.cli import main
from controller.config import load_config
from controller.devices import open_devices
from controller.evaluation.metrics import is_safe
from controller.fine_positioner import FinePositioner
from controller.loop.iteration_log import IterationLog, read_log
from controller.loop.positioning import LoopConfig
from controller.recipe import Recipe, with_recipe_stored
from drivers.core.pose import ToolStep, wrap_deg

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("offset", [ToolStep(18.0, -12.0, 0.0, 30.0), ToolStep(-3.0, 2.0, 0.0,
                                                                               -40.0)])
def test_converges_to_a_safe_grasp_within_a_small_budget(trained, tmp_path, offset):
    cfg = load_config(None)
    with open_devices(cfg, seed=7) as devices, IterationLog(tmp_path / "it.jsonl") as log:
        fp = FinePositioner(devices, cfg, log=log, state_dir=trained)
        fp.move_to(fp.state().nominal_pose.moved_in_tool_frame(offset))
        result = fp.position(max_loops=2.5)
        assert result.ok and is_safe(result.states[-1].error), result.states
        ex, ey, ephi = result.states[-1].error
        assert abs(ex) < 0.5 and abs(ey) < 0.5 and abs(ephi) < 2.0
        grasp = fp.grasp()
        assert grasp.success, grasp.reason
        assert devices.cell.holding
    records = read_log(tmp_path / "it.jsonl")
    for r in records:  # the rule: a half loop exactly when the translation exceeds r_fine
        if r["loop_kind"] in ("half", "full"):
            # the translation is the near net's where nn1_rot reads within the near range
            moved = r.get("nn1_near", r["nn1_rot"])
            assert (r["loop_kind"] == "half") == (math.hypot(*moved) > 4.0)
    assert all(r["error"] is not None for r in records)
    full = [r for r in records if r["loop_kind"] == "full"]
    assert full and len(full[0]["features"]) == 36 and len(full[0]["nn2"]) == 2


def test_no_object_looks_from_the_other_side_then_stops_without_a_step(trained):
    """A part out of view: the tool turns 180 deg where it is (the look-around) and, the
    part not found from there either, the loop stops; with the look-around off it stops
    without moving."""
    cfg = load_config(None)
    with open_devices(cfg) as devices:
        fp = FinePositioner(devices, cfg, state_dir=trained)
        devices.cell.place_object(340.0, 100.0, 0.0)  # far outside the camera's view
        fp.move_to(fp.state().nominal_pose)
        before = devices.arm.pose()
        result = fp.position()
        assert result.outcome == "no_object" and result.loops == 1.0
        after = devices.arm.pose()
        assert (after.x_mm, after.y_mm, after.z_mm) == pytest.approx(
            (before.x_mm, before.y_mm, before.z_mm), abs=0.05)
        assert abs(wrap_deg(after.t_deg - before.t_deg, 360.0)) == pytest.approx(180.0, abs=0.05)
        fp.move_to(fp.state().nominal_pose)
        off = FinePositioner(devices, cfg, state_dir=trained)
        model = off.load_model()  # its recipe without the look-around
        off.use_model(dataclasses.replace(model, model=with_recipe_stored(
            model.model, Recipe(loop=LoopConfig(look_around_deg=None)))))
        before = devices.arm.pose()
        result = off.position()
        assert result.outcome == "no_object" and result.loops == 0
        assert devices.arm.pose() == before


def test_cli_position_and_evaluate(trained, tmp_path, capsys):
    assert main(["position", "--state-dir", str(trained), "--offset", "10,-6,15",
                 "--log", str(tmp_path / "p.jsonl"), "--grasp"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["outcome"] == "converged" and out["grasp"]["success"]
    report_path = tmp_path / "eval.json"
    assert main(["evaluate", "--trials", "3", "--seed", "2", "--quiet", "--model",
                 str(trained / "model-gabor.fpm"), "--json", str(report_path)]) == 0
    report = json.loads(report_path.read_text())
    assert report["system"] == "gabor" and report["trials"] == 3 and report["object"] == "cube"
    assert set(report["rms"]) >= {"0.5", "1.0", "1.5", "2.5"}
    assert set(report["rms"]["2.5"]) == {"x_mm", "y_mm", "phi_deg"}
    assert set(report["safe_rate"]) >= {"1.0", "1.5", "2.5"}
    assert {"median", "p95"} <= set(report["loops_to_safe"])
    for key in ("grasp_success_rate", "train_images", "train_seconds", "seconds_per_loop"):
        assert key in report
    assert report["safe_rate"]["2.5"] == 1.0


def test_cli_reports_bad_input_clearly(tmp_path, capsys):
    assert main(["position", "--state-dir", str(tmp_path), "--offset", "1,2"]) == 2
    err = capsys.readouterr().err
    assert "error:" in err and ("cell state" in err or "--offset" in err)


@pytest.mark.parametrize("argv,message", [
    (["evaluate", "--trials", "0"], "--trials: must be >= 1"),
    (["demo", "--trials", "-2"], "--trials: must be >= 1"),
    (["table1", "--trials", "x", "--out", "o"], "--trials: expected a whole number"),
    (["filter-search", "--repeats", "0", "--out", "o"], "--repeats: must be >= 1"),
    (["position", "--max-loops", "-1"], "--max-loops: must be a finite number >= 0.5"),
    (["position", "--max-loops", "nan"], "--max-loops: must be a finite number >= 0.5"),
])
def test_counts_and_budgets_are_checked_before_anything_runs(argv, message, capsys):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2 and message in capsys.readouterr().err


def test_cli_rezero_takes_the_servos_template_again(trained, tmp_path, capsys):
    """`finepos rezero --system align` moves the image-alignment servo's zero the same way:
    its template taken again at the taught pose; then it reads zero there; a system that does
    not re-zero is refused in one line."""
    import shutil

    state = tmp_path / "state"
    shutil.copytree(trained, state)
    assert main(["train", "--system", "align", "--state-dir", str(state)]) == 0
    capsys.readouterr()
    poor = tmp_path / "poor.yaml"
    poor.write_text("scene:\n  lighting:\n    preset: poor\n")
    gabor = (state / "model-gabor.fpm").read_bytes()
    args = ["rezero", "--system", "align", "--state-dir", str(state), "--config", str(poor)]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    align = state / out["model"].rsplit("/", 1)[-1]
    assert out["system"] == "align" and align.name.startswith("model-align") and align.exists()
    assert 0.05 < math.hypot(*out["read_mm"]) < 1.0, out
    assert out["frames_used"] == REZERO_FRAMES, out
    assert main(args) == 0
    again = json.loads(capsys.readouterr().out)
    assert math.hypot(*again["read_mm"]) < 0.05, again
    assert (state / "model-gabor.fpm").read_bytes() == gabor  # the other model untouched
    with pytest.raises(SystemExit):
        main(["rezero", "--system", "pca", "--state-dir", str(state)])
    assert "invalid choice: 'pca'" in capsys.readouterr().err


def test_cli_rezero_moves_the_zero_to_the_new_light_and_refuses_a_moved_part(trained,
                                                                              tmp_path,
                                                                              capsys):
    """Trained in good light with the edge read in grey levels, the cube's nets read a few
    tenths of a millimetre at the taught pose under the poor-light preset; `finepos rezero`
    there makes them read zero, and with the part moved 4 mm it changes nothing."""
    import shutil

    state = tmp_path / "state"
    shutil.copytree(trained, state)
    grey = "perception:\n  edge_coverage: grey\n"
    (tmp_path / "grey.yaml").write_text(grey)
    # without bounds on the settling look's noise: means of its three frames
    fixed = tmp_path / "fixed.yaml"
    fixed.write_text(grey + "loop:\n  settle_sem_mm: null\n  settle_sem_deg: null\n")
    assert main(["train", "--state-dir", str(state), "--recipe", str(fixed)]) == 0
    capsys.readouterr()
    poor = tmp_path / "poor.yaml"
    poor.write_text("scene:\n  lighting:\n    preset: poor\n")
    model = state / "model-gabor.fpm"
    assert main(["rezero", "--state-dir", str(state), "--config", str(poor)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["part"] == "cube" and out["model"] == str(model)
    assert out["frames_used"] == REZERO_FRAMES and out["average"] == 3
    assert max(out["frame_scatter"][:2]) > 0.02, out  # the dim frame's noise
    assert 0.1 < math.hypot(*out["shift_mm"]["nn1"]) < 1.0, out
    assert main(["rezero", "--state-dir", str(state), "--config", str(poor)]) == 0
    again = json.loads(capsys.readouterr().out)
    assert math.hypot(*again["shift_mm"]["nn1"]) < 0.05, again  # it reads zero there now
    # with the default bounds on the settling look's noise the zero is read on means of as
    # many frames as that look reads in this light, two of them at least
    assert main(["train", "--state-dir", str(state), "--recipe",
                 str(tmp_path / "grey.yaml")]) == 0
    capsys.readouterr()
    assert main(["rezero", "--state-dir", str(state), "--config", str(poor)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert 3 < out["average"] <= 16, out
    # whole means, two at least
    assert out["frames"] == out["average"] * max(2, math.ceil(REZERO_FRAMES / out["average"])), \
        out
    written = model.read_bytes()
    moved = tmp_path / "moved.yaml"
    moved.write_text("scene:\n  lighting:\n    preset: poor\n  object:\n"
                     "    x_mm: 304.0\n")
    assert main(["rezero", "--state-dir", str(state), "--config", str(moved)]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert "the part is not where it was taught" in err[-1]
    assert model.read_bytes() == written


@pytest.mark.parametrize("scatter, bounds, warned", [
    ((0.2, 0.05, 0.2), {}, True),          # x: 0.2 / 4 = 0.05 mm left after 16 frames
    ((0.05, 0.05, 0.6), {}, True),         # the turn: 0.15 deg left
    ((0.1, 0.05, 0.4), {}, False),         # 16 frames bring both within 0.025 mm, 0.1 deg
    ((0.2, 0.05, 0.6), {"settle_sem_mm": None, "settle_sem_deg": None}, False),  # no bounds
])
def test_rezero_warns_where_the_settling_look_cannot_average_the_noise_away(
        scatter, bounds, warned, caplog):
    from controller.loop.positioning import LoopConfig
    from controller.systems.gabor import warn_if_too_noisy

    with caplog.at_level("WARNING", logger="controller.systems.gabor"):
        warn_if_too_noisy(LoopConfig(**bounds), scatter)
    assert ("lower the camera's gain" in caplog.text) is warned
    if warned:
        assert len(caplog.records) == 1 and "16 frames" in caplog.text


def test_cli_rezero_by_heading_turns_the_part_and_puts_it_back(trained, tmp_path, capsys,
                                                              caplog):
    """`finepos rezero --heading-step`: the arm grasps the cube, turns it, sets it down,
    centres it with the jaws a quarter turn on and looks at each heading; the model keeps the
    zero by heading, the turn and the translation, and the part lies back at its taught
    heading, in the middle of the taught pose's jaws (it lay 0.25 mm along them off it), the
    arm at the taught pose; a plain rezero drops the table; bad options are refused in one
    line before the arm moves. Under the poor light's lamp the camera, exposed for the dark
    room, clips the cube's lit face: the report says how much, and a warning says what to
    do."""
    import shutil

    from calibration_free.bundle import ModelBundle

    state = tmp_path / "state"
    shutil.copytree(trained, state)
    poor = tmp_path / "poor.yaml"
    poor.write_text("scene:\n  lighting:\n    preset: poor\n")
    cfg = load_config(poor)
    with open_devices(cfg, seed=2) as devices:
        fp = FinePositioner(devices, cfg, state_dir=state)
        cell = devices.cell
        along = cell.nominal_grasp_pose().rotation()[:, 0]  # the jaws' direction
        x, y, phi = cell.object_pose()
        cell.place_object(x + 0.25 * along[0], y + 0.25 * along[1], phi)
        before = cell.object_pose()
        # turns of 120 deg: more than the safety layer's 100 deg a move, made in two
        _, report = fp.rezero(6, heading_step_deg=120.0, heading_range_deg=(-120.0, 120.0))
        after = cell.object_pose()
        assert math.hypot(after[0] - before[0], after[1] - before[1]) < 0.4
        assert abs(wrap_deg(after[2] - before[2], 90.0)) < 0.3
        assert cell.arm_pose() == pytest.approx(fp.state().nominal_pose)
        assert math.hypot(after[0] - x, after[1] - y) < 0.06
        # the plain zero was read with the part 0.25 mm off; the translation by heading is
        # read against it with the part centred, so the loop brings the jaws over the part's
        # middle, where the plain zero alone would leave them 0.25 mm off
        table = report["heading_zero"]
        middle = table["headings_deg"].index(min(table["headings_deg"], key=abs))
        assert 0.17 < math.hypot(table["dx_mm"][middle], table["dy_mm"][middle]) < 0.33
        fp.move_to(fp.state().nominal_pose.moved_in_tool_frame(ToolStep(1.0, -1.0, 0.0, 3.0)))
        result = fp.position(max_loops=3.5)
        assert math.hypot(*result.states[-1].error[:2]) < 0.1, result.states[-1]
    assert report["clipped_share"] > 0.05
    assert "bring its exposure down" in caplog.text
    table = report["heading_zero"]
    assert list(np.diff(table["headings_deg"])) == pytest.approx([120, 120], abs=0.5)
    assert len(table["dx_mm"]) == len(table["dy_mm"]) == 3
    # the lamp's effect and the 0.25 mm the centring moved the part from where it was zeroed
    assert max(map(abs, table["dx_mm"] + table["dy_mm"])) < 0.45
    assert ModelBundle.load(state / "model-gabor.fpm").heading_zero.to_info() == table
    args = ["rezero", "--state-dir", str(state), "--config", str(poor), "--frames", "6"]
    assert main(args) == 0
    assert json.loads(capsys.readouterr().out)["heading_zero"] is None
    assert ModelBundle.load(state / "model-gabor.fpm").heading_zero is None
    written = (state / "model-gabor.fpm").read_bytes()
    for bad, message in ((["--heading-range", "0", "10"], "--heading-range: only with"),
                         (["--heading-step", "5", "--heading-range", "10", "0"],
                          "heading range must run from a lower"),
                         (["--heading-step", "5", "--system", "align"], "keeps one zero")):
        assert main(args + bad) == 2, bad
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
    assert (state / "model-gabor.fpm").read_bytes() == written


def test_position_then_grasp_makes_the_converged_step_with_the_first_descent(trained, caplog):
    """With a grasp to follow, the loop leaves its converged step to the grasp's first move;
    the run gets that loop and the state after it. Where the arm moved in between, the
    step is not carried."""
    cfg = load_config(None)
    offset = ToolStep(6.0, -4.0, 0.0, 12.0)
    with open_devices(cfg, seed=3) as devices:
        fp = FinePositioner(devices, cfg, state_dir=trained)
        fp.move_to(fp.state().nominal_pose.moved_in_tool_frame(offset))
        result = fp.position(then_grasp=True)
        assert result.outcome == "converged" and result.carried is not None, result.reason
        loops, states = result.loops, len(result.states)
        left_at = devices.arm.pose()
        grasp = fp.grasp()
        assert grasp.success and devices.cell.holding, grasp.reason
        assert grasp.carried_step == dataclasses.replace(result.carried, dz_mm=0.0)
        assert result.loops == loops + 1.0 and len(result.states) == states + 1
        assert "made by the grasp's first move" in result.reason
        assert is_safe(result.states[-1].error)
        assert devices.arm.pose() != left_at
        # the arm moved after the loop: the grasp descends straight
        devices.arm.open_gripper()
        devices.cell.place_object(*devices.cell.object_pose())
        fp.move_to(fp.state().nominal_pose.moved_in_tool_frame(offset))
        result = fp.position(then_grasp=True)
        assert result.carried is not None, result.reason
        fp.move_to(fp.state().nominal_pose)
        with caplog.at_level("WARNING"):
            grasp = fp.grasp()
        assert grasp.carried_step is None and "not carried" in caplog.text
        assert result.reason.endswith("not made (the arm moved before the grasp)")


@pytest.mark.slow
def test_rezero_by_heading_reads_a_part_the_jaws_cannot_centre_between_looks_back(
        tmp_path, caplog):
    """The nut (kappa 6): after each heading the arm turns it back to the taught heading and
    looks there too; its zero by heading keeps the translation as well as the turn, read
    against those looks, and the nut lies back at its taught heading, the arm at the taught
    pose."""
    from controller.config import config_from_mapping, with_part

    cfg = with_part(config_from_mapping({"controller": {"acquisition": {
        "nn1": {"shape": [3, 3, 3]}, "nn2": {"shape": [3, 3, 3]}}}}), "nut")
    with open_devices(cfg, seed=3) as devices:
        fp = FinePositioner(devices, cfg, state_dir=tmp_path / "state")
        fp.teach_auto()
        fp.acquire("nn1", progress=False)
        fp.acquire("nn2", progress=False)
        fp.train()
        cell = devices.cell
        before = cell.object_pose()
        with caplog.at_level("INFO", logger="controller.calibration.heading_zero"):
            _, report = fp.rezero(6, heading_step_deg=30.0)
        after = cell.object_pose()
        assert math.hypot(after[0] - before[0], after[1] - before[1]) < 0.4
        assert abs(wrap_deg(after[2] - before[2], 60.0)) < 0.3
        assert cell.arm_pose() == pytest.approx(fp.state().nominal_pose)
    table = report["heading_zero"]
    assert list(np.diff(table["headings_deg"])) == pytest.approx([30, 30], abs=0.5)
    assert len(table["dx_mm"]) == len(table["dy_mm"]) == 3
    assert max(map(abs, table["dx_mm"] + table["dy_mm"])) < 0.3  # good light: little
    # there and back for each of the two headings off the taught one
    set_downs = [r.getMessage() for r in caplog.records
                 if r.getMessage().startswith("rezero: set-down")]
    assert [m.split("turned ")[1] for m in set_downs] == [
        "-30 deg from its taught heading", "0 deg from its taught heading",
        "30 deg from its taught heading", "0 deg from its taught heading"]
    assert "after the last" in caplog.text
