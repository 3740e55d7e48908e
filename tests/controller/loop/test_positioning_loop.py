"""Loop logic of the positioning controller against a fake arm and a scripted estimator."""

import dataclasses
import itertools
import json
import math

import numpy as np
import pytest

from calibration_free.heading_zero import HeadingZero
from calibration_free.preprocess import mean_frame
from controller.loop.iteration_log import IterationLog, read_log
from controller.loop.positioning import LoopConfig, PositioningLoop
from controller.systems.estimator import TranslationEstimate
from drivers.core.errors import ConfigError, MotionRejectedError
from drivers.core.pose import ToolStep, wrap_deg
from drivers.core.typed_config import from_mapping
from drivers.safety import SafetyLimits
from tests.controller.loop.loop_fixtures import NOMINAL, TruthEstimator, truth_error
from tests.mocks.fakes import FakeArm, FakeCamera

# a settling look that reads exactly ``settle_frames`` frames, however they scatter
FIXED = {"settle_sem_mm": None, "settle_sem_deg": None}


def make(offset: ToolStep, limits=None, **cfg):
    arm = FakeArm(limits, start=NOMINAL.moved_in_tool_frame(offset))
    arm.connect()
    arm.activate()
    cam = FakeCamera()
    cam.connect()
    return arm, cam, LoopConfig(**cfg)


def test_far_start_makes_half_loops_then_full_then_converges(tmp_path):
    arm, cam, cfg = make(ToolStep(20.0, -15.0, 0.0, 20.0))
    est = TruthEstimator(arm, gain=0.7)
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log, lambda: truth_error(arm)).run(est)
    records = read_log(tmp_path / "it.jsonl")
    kinds = [r["loop_kind"] for r in records]
    # 25 mm is seen as 17.5 mm; the remaining 7.5 mm as 5.25 mm, still above r_fine
    assert kinds[0] == "half" and kinds[1] == "half"
    assert kinds[2] == "full" and kinds[-1] == "check"
    assert result.outcome == "converged"
    assert [s.loops for s in result.states][:4] == [0.0, 0.5, 1.0, 2.0]
    ex, ey, ephi = result.states[-1].error
    assert abs(ex) < 0.2 and abs(ey) < 0.2 and abs(ephi) < 1.0
    for r in records[:-1]:
        assert {"time", "run_id", "iteration", "loop_kind", "loops", "u_px", "v_px",
                "commanded", "executed", "pose_after", "timings_ms", "error"} <= r.keys()
    assert records[2]["nn2"] and records[2]["commanded"]["dphi_deg"] != 0
    assert records[0]["commanded"]["dphi_deg"] == 0.0  # half loops do not rotate


def test_near_start_goes_straight_to_full_loop():
    arm, cam, cfg = make(ToolStep(1.0, 1.0, 0.0, 10.0))
    result = PositioningLoop(arm, cam, cfg).run(TruthEstimator(arm))
    assert result.outcome == "converged"
    assert result.states[1].loops == 1.0  # first move was a full loop


def test_r_fine_decides_the_loop_kind():
    arm, cam, cfg = make(ToolStep(3.0, 0.0, 0.0, 10.0), r_fine_mm=2.0)
    est = TruthEstimator(arm)
    result = PositioningLoop(arm, cam, cfg).run(est)
    assert result.states[1].loops == 0.5 and est.rotation_calls >= 1


def test_budget_stops_the_loop_without_exceeding_it():
    arm, cam, cfg = make(ToolStep(20.0, 0.0, 0.0, 30.0), max_loops=1.5)
    result = PositioningLoop(arm, cam, cfg).run(TruthEstimator(arm, gain=0.5))
    assert result.outcome == "budget"
    assert result.loops <= 1.5


@pytest.mark.parametrize("status,look_around", [("no_object", None), ("ambiguous", 180.0)])
def test_no_object_stops_without_moving(status, look_around, tmp_path):
    arm, cam, cfg = make(ToolStep(5.0, 0.0, 0.0, 0.0), look_around_deg=look_around)
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log).run(TruthEstimator(arm, status=status))
    assert result.outcome == status and "scripted" in result.reason
    assert arm.moves == []
    (record,) = read_log(tmp_path / "it.jsonl")
    assert record["status"] == status and record["executed"] is None
    assert record["reason"] == f"scripted {status}"


class HiddenNearEnd(TruthEstimator):
    """Sees no part until the camera has turned by at least ``hidden_until_deg`` from where
    it started (what lay over the end nearer the camera is then over the far end)."""

    def __init__(self, arm, hidden_until_deg=150.0, lost_after_looks=None, **kw):
        super().__init__(arm, **kw)
        self.start_t = arm._pose.t_deg
        self.hidden_until_deg, self.lost_after_looks, self.looks = \
            hidden_until_deg, lost_after_looks, 0

    def estimate_translation(self, image):
        self.looks += 1
        turned = abs(wrap_deg(self.arm._pose.t_deg - self.start_t, 360.0))
        if turned < self.hidden_until_deg or (self.lost_after_looks is not None
                                              and self.looks > self.lost_after_looks):
            return TranslationEstimate("no_object", reason="scripted hidden")
        return super().estimate_translation(image)


def test_a_part_not_found_is_looked_for_from_its_other_side(tmp_path):
    """No part in the first look: the tool turns by 180 deg, in two commands within the
    arm's 100 deg, counted as one loop; the part is found from there and the loop converges
    (the kappa-4 part needs no turn back)."""
    limits = SafetyLimits(max_step_deg=100.0, on_violation="reject")
    arm, cam, cfg = make(ToolStep(6.0, -2.0, 0.0, 5.0), limits=limits)
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log, lambda: truth_error(arm)).run(
            HiddenNearEnd(arm))
    assert result.outcome == "converged"
    records = read_log(tmp_path / "it.jsonl")
    first = records[0]
    assert first["loop_kind"] == "around" and first["status"] == "no_object"
    assert first["commanded"] == {"dx_mm": 0.0, "dy_mm": 0.0, "dz_mm": 0.0, "dphi_deg": 180.0}
    assert first["executed"]["dphi_deg"] == pytest.approx(180.0)
    assert "another side" in first["look_around"] and first["loops"] == 1.0
    assert [m.t_deg for m in arm.moves[:2]] == pytest.approx(
        [NOMINAL.t_deg + 5.0 + 90.0, wrap_deg(NOMINAL.t_deg + 5.0 + 180.0, 360.0)])
    assert records[1]["loop_kind"] == "half" and result.states[1].loops == 1.0
    ex, ey, _ = result.states[-1].error
    assert abs(ex) < 0.1 and abs(ey) < 0.1


def test_the_look_around_is_made_once_and_only_before_the_first_full_loop(tmp_path):
    limits = SafetyLimits(max_step_deg=100.0, on_violation="reject")
    # not found from either side: one look-around, then no_object
    arm, cam, cfg = make(ToolStep(6.0, 0.0, 0.0, 0.0), limits=limits)
    result = PositioningLoop(arm, cam, cfg).run(HiddenNearEnd(arm, hidden_until_deg=360.0))
    assert result.outcome == "no_object" and result.loops == 1.0 and len(arm.moves) == 2
    # lost after a full loop (one that turned, or one that did not): stops where it is
    for turn in (5.0, 0.0):
        arm, cam, cfg = make(ToolStep(1.0, 0.0, 0.0, turn), limits=limits)
        result = PositioningLoop(arm, cam, cfg).run(
            HiddenNearEnd(arm, hidden_until_deg=0.0, lost_after_looks=1))
        assert result.outcome == "no_object" and len(arm.moves) == 1
    # off, or no budget left for it: stops at once
    for kw in ({"look_around_deg": None}, {"max_loops": 0.5}):
        arm, cam, cfg = make(ToolStep(6.0, 0.0, 0.0, 0.0), limits=limits, **kw)
        result = PositioningLoop(arm, cam, cfg).run(HiddenNearEnd(arm))
        assert result.outcome == "no_object" and arm.moves == []


class HalfHidden(TruthEstimator):
    """Sees ``near`` of the part's taught area until the camera has turned by 150 deg or
    more, ``far`` from there."""

    def __init__(self, arm, near, far=0.8, **kw):
        super().__init__(arm, **kw)
        self.start_t, self.near, self.far = arm._pose.t_deg, near, far

    def estimate_translation(self, image):
        turned = abs(wrap_deg(self.arm._pose.t_deg - self.start_t, 360.0))
        share = self.far if turned >= 150.0 else self.near
        return dataclasses.replace(super().estimate_translation(image), seen_share=share)


@pytest.mark.parametrize("near,looked", [(0.5, True), (0.65, False)])
def test_a_part_mostly_hidden_is_looked_at_from_its_other_side(near, looked, tmp_path):
    """Below ``look_around_below`` (0.6) of the part seen, the first look moves the tool
    over the part by the translation read and turns the camera to the part's other side;
    the next look is a full one."""
    limits = SafetyLimits(max_step_deg=100.0, on_violation="reject")
    arm, cam, cfg = make(ToolStep(6.0, -2.0, 0.0, 5.0), limits=limits,
                         hidden_check_share=None)
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log, lambda: truth_error(arm)).run(
            HalfHidden(arm, near))
    assert result.outcome == "converged"
    first, second = read_log(tmp_path / "it.jsonl")[:2]
    if looked:
        assert first["loop_kind"] == "around" and first["status"] == "ok"
        assert first["look_around"].startswith("50% of the part seen: moving by the 6.3 mm")
        assert first["commanded"]["dphi_deg"] == 180.0
        assert math.hypot(first["executed"]["dx_mm"], first["executed"]["dy_mm"]) == \
            pytest.approx(math.hypot(6.0, 2.0), abs=0.01)
        ex, ey, _ = result.states[1].error
        assert result.states[1].loops == 1.0 and math.hypot(ex, ey) < 0.05
        assert second["loop_kind"] == "full"
    else:
        assert first["loop_kind"] == "half" and "look_around" not in first


def test_a_look_around_takes_no_step_beyond_the_training_range(tmp_path):
    """A blob read beyond the training range (another part in the frame's corner, say) is
    not moved to: the look-around only turns."""
    limits = SafetyLimits(max_step_deg=100.0, on_violation="reject")
    arm, cam, cfg = make(ToolStep(40.0, 0.0, 0.0, 0.0), limits=limits,
                         hidden_check_share=None)
    with IterationLog(tmp_path / "it.jsonl") as log:
        PositioningLoop(arm, cam, cfg, log, reach_mm=25.0).run(HalfHidden(arm, 0.5))
    first = read_log(tmp_path / "it.jsonl")[0]
    assert first["loop_kind"] == "around" and first["look_around"].startswith(
        "50% of the part seen: turning the tool by 180 deg")
    assert first["executed"]["dx_mm"] == 0.0 and first["executed"]["dy_mm"] == 0.0


def test_a_rejected_look_around_stops_the_loop(tmp_path):
    """The arm refuses the look-around's second command (a joint limit, say): the loop
    stops as rejected and logs the look as a stop."""
    limits = SafetyLimits(max_step_deg=100.0, on_violation="reject")
    arm, cam, cfg = make(ToolStep(6.0, 0.0, 0.0, 0.0), limits=limits)
    move_tool = arm.move_tool

    def refuse_second(step):
        if arm.moves:
            raise MotionRejectedError("joint 6 at its limit")
        return move_tool(step)

    arm.move_tool = refuse_second
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log).run(HiddenNearEnd(arm))
    assert result.outcome == "rejected" and "joint 6" in result.reason
    assert len(arm.moves) == 1
    (record,) = read_log(tmp_path / "it.jsonl")
    assert record["loop_kind"] == "stop" and record["rejected"] == "joint 6 at its limit"


def test_a_correction_beyond_the_training_range_is_not_taken(tmp_path):
    # reach 35.4 mm (a 25 mm grid), factor 1.25: 44.2 mm is the longest correction taken
    arm, cam, cfg = make(ToolStep(46.0, 0.0, 0.0, 0.0))
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log, reach_mm=25.0 * 2 ** 0.5).run(
            TruthEstimator(arm))
    assert result.outcome == "out_of_range" and "training range" in result.reason
    assert arm.moves == []
    (record,) = read_log(tmp_path / "it.jsonl")
    assert record["loop_kind"] == "stop" and record["executed"] is None
    arm, cam, cfg = make(ToolStep(40.0, 0.0, 0.0, 0.0))  # within reach: positioned
    result = PositioningLoop(arm, cam, cfg, reach_mm=25.0 * 2 ** 0.5).run(TruthEstimator(arm))
    assert result.outcome == "converged"


def test_safety_rejection_stops_the_loop():
    limits = SafetyLimits(max_step_mm=5.0, on_violation="reject")
    arm, cam, cfg = make(ToolStep(20.0, 0.0, 0.0, 0.0), limits=limits)
    result = PositioningLoop(arm, cam, cfg).run(TruthEstimator(arm))
    assert result.outcome == "rejected" and "max_step_mm" in result.reason
    assert arm.moves == []


def test_a_turn_beyond_max_step_deg_is_sent_in_commands_within_it(tmp_path):
    """A screw turned by 170 deg: one full loop, its turn in two commands of 85 deg (the
    arm's limit is 100 deg a command), its translation with the first."""
    limits = SafetyLimits(max_step_deg=100.0, on_violation="reject")
    arm, cam, cfg = make(ToolStep(1.0, -1.0, 0.0, 170.0), limits=limits)
    start = arm._pose
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log, lambda: truth_error(arm)).run(
            TruthEstimator(arm, kappa=1))
    assert result.outcome == "converged" and result.loops == 1.0
    first = read_log(tmp_path / "it.jsonl")[0]
    assert first["loop_kind"] == "full" and first["clipped"] is False
    assert first["commanded"]["dphi_deg"] == pytest.approx(-170.0)
    assert first["executed"]["dphi_deg"] == pytest.approx(-170.0)
    assert first["executed"]["dx_mm"] == pytest.approx(first["commanded"]["dx_mm"])
    one, two = arm.moves[:2]
    assert wrap_deg(one.t_deg - start.t_deg, 360.0) == pytest.approx(-85.0)
    assert wrap_deg(two.t_deg - one.t_deg, 360.0) == pytest.approx(-85.0)
    assert two.position_mm == pytest.approx(one.position_mm)  # the second only turns
    assert max(abs(e) for e in truth_error(arm)[:2]) < 0.05


def test_a_turn_beyond_max_step_deg_is_taken_in_part_without_turn_in_commands(tmp_path):
    limits = SafetyLimits(max_step_deg=100.0, on_violation="reject")
    arm, cam, cfg = make(ToolStep(1.0, -1.0, 0.0, 170.0), limits=limits,
                         turn_in_commands=False)
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log, lambda: truth_error(arm)).run(
            TruthEstimator(arm, kappa=1))
    assert result.outcome == "converged"
    first = read_log(tmp_path / "it.jsonl")[0]
    assert first["loop_kind"] == "full" and first["clipped"] is False
    assert first["commanded"]["dphi_deg"] == pytest.approx(-100.0)
    assert all(abs(m_phi) <= 100.0 + 1e-9 for m_phi in
               (r["commanded"]["dphi_deg"] for r in read_log(tmp_path / "it.jsonl")))
    assert result.states[1].loops == 1.0 and result.iterations >= 2


def test_clipped_steps_are_logged_as_executed(tmp_path):
    limits = SafetyLimits(max_step_mm=5.0, on_violation="clip")
    arm, cam, cfg = make(ToolStep(-12.0, 0.0, 0.0, 0.0), limits=limits)
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log).run(TruthEstimator(arm))
    assert result.outcome == "converged"
    first = read_log(tmp_path / "it.jsonl")[0]
    assert first["clipped"] is True
    assert first["executed"]["dx_mm"] == pytest.approx(5.0, abs=1e-6)
    assert first["commanded"]["dx_mm"] == pytest.approx(12.0, abs=1e-6)


def test_log_lines_are_complete_json(tmp_path):
    arm, cam, cfg = make(ToolStep(8.0, 3.0, 0.0, 5.0), save_images=True)
    with IterationLog(tmp_path / "it.jsonl") as log:
        PositioningLoop(arm, cam, cfg, log).run(TruthEstimator(arm))
    lines = (tmp_path / "it.jsonl").read_text().splitlines()
    assert lines and all(json.loads(line)["run_id"] for line in lines)
    assert all((tmp_path / json.loads(line)["image"]).exists() for line in lines)


class NoisyEstimator(TruthEstimator):
    """The true step plus a scripted error per frame (cycled): frame-to-frame camera noise."""

    def __init__(self, arm, errors, **kw):
        super().__init__(arm, **kw)
        self.errors, self.frames = errors, 0

    def estimate_translation(self, image):
        t = super().estimate_translation(image)
        self.error = self.errors[self.frames % len(self.errors)]
        self.frames += 1
        if self.error is None:
            return TranslationEstimate("no_object", reason="scripted miss")
        return dataclasses.replace(t, dx_mm=t.dx_mm + self.error[0], dy_mm=t.dy_mm + self.error[1])

    def estimate_rotation(self, translation):
        r = super().estimate_rotation(translation)
        return dataclasses.replace(r, dphi_deg=r.dphi_deg + self.error[2])


def test_settling_looks_average_their_frames(tmp_path):
    """Readings that scatter +-0.08 mm / +-0.4 deg around the truth: one frame a look moves
    by the scatter and never meets the thresholds; two frames a look cancel it."""
    errors = [(0.08, -0.08, 0.4), (-0.08, 0.08, -0.4)]
    start = ToolStep(0.3, -0.2, 0.0, 1.0)
    arm, cam, cfg = make(start, max_loops=4.0, settle_frames=1)
    alone = PositioningLoop(arm, cam, cfg).run(NoisyEstimator(arm, errors))
    assert alone.outcome == "budget"
    arm, cam, cfg = make(start, max_loops=4.0, settle_frames=2, settle_average="steps",
                         **FIXED)
    est = NoisyEstimator(arm, errors)
    with IterationLog(tmp_path / "it.jsonl") as log:
        settled = PositioningLoop(arm, cam, cfg, log, lambda: truth_error(arm)).run(est)
    assert settled.outcome == "converged" and settled.loops == 1.0
    ex, ey, ephi = settled.states[-1].error
    assert abs(ex) < 1e-6 and abs(ey) < 1e-6 and abs(ephi) < 1e-6
    first, check = read_log(tmp_path / "it.jsonl")
    assert len(first["settle"]) == 2 and est.frames == 4


def test_settling_leaves_out_frames_without_the_part_or_off_the_window(tmp_path):
    errors = [(0.0, 0.0, 0.0), None, (3.0, 0.0, 0.0), (0.0, 0.0, 0.0)]
    arm, cam, cfg = make(ToolStep(0.2, 0.1, 0.0, 0.5), settle_frames=4,
                         settle_average="steps")
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log, lambda: truth_error(arm)).run(
            NoisyEstimator(arm, errors))
    assert result.outcome == "converged"
    first = read_log(tmp_path / "it.jsonl")[0]
    good, missed, off, _ = first["settle"]
    assert missed is None and off[0] == pytest.approx(good[0] + 3.0)
    # the mean of the two good frames, which read the truth
    assert [first["commanded"][k] for k in ("dx_mm", "dy_mm", "dphi_deg")] == \
        pytest.approx(good, abs=1e-9)


def test_only_settling_looks_read_more_frames(tmp_path):
    arm, cam, cfg = make(ToolStep(3.0, 0.0, 0.0, 10.0), settle_frames=4,
                         settle_average="steps")
    est = NoisyEstimator(arm, [(0.0, 0.0, 0.0)], gain=0.9)
    with IterationLog(tmp_path / "it.jsonl") as log:
        PositioningLoop(arm, cam, cfg, log).run(est)
    records = read_log(tmp_path / "it.jsonl")
    # 3 mm / 10 deg, then 0.3 mm / 1 deg: one frame, then four; then the check settles too
    assert "settle" not in records[0] and len(records[1]["settle"]) == 4
    assert est.frames == 1 + 4 * (len(records) - 1)


def _settle_log(tmp_path, errors, **cfg):
    """The first look's record and the result of a loop from 0.2 mm / 0.5 deg off whose
    frames read the truth plus ``errors`` (cycled; their mean step is taken)."""
    arm, cam, config = make(ToolStep(0.2, 0.1, 0.0, 0.5), max_loops=4.0,
                            settle_average="steps", **cfg)
    est = NoisyEstimator(arm, errors)
    path = tmp_path / f"it-{len(list(tmp_path.glob('it-*.jsonl')))}.jsonl"
    with IterationLog(path) as log:
        result = PositioningLoop(arm, cam, config, log, lambda: truth_error(arm)).run(est)
    return read_log(path)[0], result


def test_a_noisy_settling_look_reads_frames_until_its_mean_is_known(tmp_path):
    """Frames scattering +-0.08 mm in x: the look reads on past its three frames until the
    standard error of the mean step is within 0.025 mm (sd 0.08: 11 frames), no further."""
    errors = [(0.08, 0.0, 0.0), (-0.08, 0.0, 0.0)]
    first, result = _settle_log(tmp_path, errors, settle_frames=3, settle_max_frames=16,
                                settle_sem_mm=0.025, settle_sem_deg=0.1)
    n = len(first["settle"])
    xs = np.array([s[0] for s in first["settle"]])
    assert 3 < n < 16
    sem = xs.std(ddof=1) / np.sqrt(n)
    assert first["settle_sem"][0] == pytest.approx(sem) and sem <= 0.025
    previous = xs[:-1].std(ddof=1) / np.sqrt(n - 1)
    assert previous > 0.025  # it stopped at the first frame that brought it within
    assert result.outcome == "converged"
    assert max(abs(e) for e in result.states[-1].error) < 1e-6  # +-0.08 in even numbers


def test_a_quiet_settling_look_reads_only_its_frames(tmp_path):
    errors = [(0.004, -0.003, 0.02), (-0.004, 0.003, -0.02)]
    first, _ = _settle_log(tmp_path, errors, settle_frames=3, settle_max_frames=16)
    assert len(first["settle"]) == 3
    assert max(first["settle_sem"][:2]) <= 0.025 and first["settle_sem"][2] <= 0.1


@pytest.mark.parametrize("axis, bound", [(1, {"settle_sem_mm": 0.025}),
                                         (2, {"settle_sem_deg": 0.1})])
def test_each_axis_bound_keeps_a_settling_look_reading(axis, bound, tmp_path):
    """y scattering +-0.3 mm, or the turn +-1.5 deg: that axis' bound alone keeps the look
    reading to its cap; with only the other axis bounded it reads its three frames."""
    big = [0.0, 0.0, 0.0]
    big[axis] = 0.3 if axis == 1 else 1.5
    errors = [tuple(big), tuple(-v for v in big)]
    other = {"settle_sem_mm": None, "settle_sem_deg": None}
    first, _ = _settle_log(tmp_path, errors, settle_frames=3, settle_max_frames=9,
                           **{**other, **bound})
    assert len(first["settle"]) == 9
    first, _ = _settle_log(tmp_path, errors, settle_frames=3, settle_max_frames=9,
                           **{**other, **{k: (0.025 if "mm" in k else 0.1)
                                          for k in other if k not in bound}})
    assert len(first["settle"]) == 3


def test_frames_without_the_part_count_towards_the_cap(tmp_path):
    """Only the first frame shows the part: the look cannot know its mean and stops at
    settle_max_frames, moving by the one frame it has."""
    first, result = _settle_log(tmp_path, [(0.0, 0.0, 0.0)] + [None] * 20, settle_frames=3,
                                settle_max_frames=6, settle_sem_mm=0.025)
    assert len(first["settle"]) == 6 and first["settle"][1:] == [None] * 5
    assert first["settle_sem"] is None


def test_settle_max_frames_below_settle_frames_is_refused():
    with pytest.raises(ConfigError, match=r"controller\.loop: settle_max_frames: 2 is below "
                                          r"settle_frames \(3\)"):
        from_mapping(LoopConfig, {"settle_frames": 3, "settle_max_frames": 2},
                     "controller.loop")


class SpeckleEstimator(TruthEstimator):
    """Reads the true step, 0.2 mm too far in x in a frame whose noise lifts its first pixel
    above 105 (noise pixels that join the part's blob: a bias one way, as in a dim frame's
    shadows), and no part in a frame whose first pixel is 50."""

    def estimate_translation(self, image):
        if image[0, 0, 0] == 50:
            return TranslationEstimate("no_object", reason="scripted miss")
        t = super().estimate_translation(image)
        return dataclasses.replace(t, dx_mm=t.dx_mm + (0.2 if image[0, 0, 0] > 105 else 0.0))


def _cycling_camera(levels):
    frames = itertools.cycle([np.full((144, 192, 3), v, np.uint8) for v in levels])
    cam = FakeCamera(lambda: next(frames))
    cam.connect()
    return cam


@pytest.mark.parametrize("average", ["frames", "steps"])
def test_a_settling_look_reads_its_mean_frame(average, tmp_path):
    """Frames at 110, 90 and 100 (noise): one in three reads 0.2 mm off; their mean frame
    (100) reads the truth, the mean of their steps keeps a third of the bias."""
    arm, _, cfg = make(ToolStep(0.2, 0.1, 0.0, 0.5), max_loops=4.0, settle_frames=3,
                       settle_average=average, **FIXED)
    cam = _cycling_camera([100, 110, 90])
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log, lambda: truth_error(arm)).run(
            SpeckleEstimator(arm))
    first = read_log(tmp_path / "it.jsonl")[0]
    assert [s[0] - first["settle"][0][0] for s in first["settle"]] == \
        pytest.approx([0.0, 0.2, 0.0])
    if average == "frames":
        assert result.outcome == "converged"
        assert first["settle_mean_frame"] == pytest.approx(first["settle"][0])
        assert max(abs(e) for e in result.states[-1].error) < 1e-6
    else:
        assert "settle_mean_frame" not in first
        assert first["commanded"]["dx_mm"] == pytest.approx(first["settle"][0][0] + 0.2 / 3)


def test_a_mean_frame_without_the_part_falls_back_to_the_mean_step(tmp_path):
    # frames at 40 and 60 each show the part; their mean frame (50) is scripted to show none
    arm, _, cfg = make(ToolStep(0.2, 0.1, 0.0, 0.5), settle_frames=2)
    cam = _cycling_camera([40, 60])
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log, lambda: truth_error(arm)).run(
            SpeckleEstimator(arm))
    first = read_log(tmp_path / "it.jsonl")[0]
    assert first["settle_mean_frame"] is None and None not in first["settle"]
    assert [first["commanded"][k] for k in ("dx_mm", "dy_mm", "dphi_deg")] == \
        pytest.approx(first["settle"][0], abs=1e-9)
    assert result.outcome == "converged"


def test_mean_frame_rounds_the_pixelwise_mean():
    frames = [np.full((2, 2, 3), v, np.uint8) for v in (0, 255, 255)]
    assert np.all(mean_frame(frames) == 170) and mean_frame(frames).dtype == np.uint8
    assert np.all(mean_frame([np.full((2, 2, 3), v, np.uint8) for v in (1, 2)]) == 2)


class BlindNearEstimator(TruthEstimator):
    """Reads the turn right far from the taught heading and ``bias`` deg off within ``near``
    deg of it (a part half hidden: the rest of its outline fits another heading)."""

    def __init__(self, arm, bias: float, near: float = 10.0, **kw) -> None:
        super().__init__(arm, **kw)
        self.bias, self.near = bias, near

    def estimate_rotation(self, translation):
        r = super().estimate_rotation(translation)
        if abs(r.dphi_deg) < self.near:
            return dataclasses.replace(r, dphi_deg=r.dphi_deg + self.bias)
        return r


def test_a_turn_reading_that_contradicts_the_last_turn_stops_the_loop(tmp_path):
    arm, cam, cfg = make(ToolStep(1.0, 0.0, 0.0, 30.0))
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log, lambda: truth_error(arm)).run(
            BlindNearEstimator(arm, bias=-20.0))
    assert result.outcome == "inconsistent" and "-20.0 deg" in result.reason
    # the first full loop turned right; the second reading was not taken
    assert len(arm.moves) == 1 and result.loops == 1.0
    assert result.states[-1].error == pytest.approx((0.0, 0.0, 0.0), abs=1e-6)
    first, stop = read_log(tmp_path / "it.jsonl")
    assert stop["loop_kind"] == "stop" and stop["executed"] is None
    assert stop["turn_expected_deg"] == pytest.approx(0.0, abs=1e-9)
    assert stop["commanded"]["dphi_deg"] == pytest.approx(-20.0, abs=1e-6)


def test_the_turn_check_allows_a_share_of_the_turn_and_can_be_off():
    # a cautious rotation reading (gain 0.7) leaves 30% of each turn for the next look:
    # within the 40% share, so the loop converges
    arm, cam, cfg = make(ToolStep(1.0, 0.0, 0.0, 40.0), max_loops=12.0)
    assert PositioningLoop(arm, cam, cfg).run(TruthEstimator(arm, gain=0.7)).outcome == \
        "converged"
    # small misreadings near the pose stay within the 10 deg floor
    arm, cam, cfg = make(ToolStep(1.0, 0.0, 0.0, 30.0), max_loops=3.0)
    assert PositioningLoop(arm, cam, cfg).run(
        BlindNearEstimator(arm, bias=8.0, near=1.0)).outcome == "budget"
    # without the check the loop follows the misreading
    arm, cam, cfg = make(ToolStep(1.0, 0.0, 0.0, 30.0), max_loops=3.0, turn_check_deg=None)
    result = PositioningLoop(arm, cam, cfg, ground_truth=lambda: truth_error(arm)).run(
        BlindNearEstimator(arm, bias=-20.0))
    assert result.outcome == "budget" and len(arm.moves) == 3


def test_the_turn_check_expects_the_rest_of_a_turn_taken_in_part():
    # 170 deg with a 100 deg turn limit: the next look reads the remaining 70 deg, as expected
    limits = SafetyLimits(max_step_deg=100.0, on_violation="reject")
    arm, cam, cfg = make(ToolStep(1.0, -1.0, 0.0, 170.0), limits=limits,
                         turn_in_commands=False)
    assert PositioningLoop(arm, cam, cfg).run(TruthEstimator(arm, kappa=1)).outcome == \
        "converged"


class HiddenPartEstimator(TruthEstimator):
    """Reads the way back to NOMINAL, but sees only ``share`` of the part's taught area."""

    def __init__(self, arm, share, **kw):
        super().__init__(arm, **kw)
        self.share = share

    def estimate_translation(self, image):
        return dataclasses.replace(super().estimate_translation(image), seen_share=self.share)


@pytest.mark.parametrize("share, outcome", [(0.7, "occluded"), (0.9, "converged"),
                                            (None, "converged")])
def test_a_part_seen_much_smaller_than_taught_ends_the_loop_as_occluded(share, outcome,
                                                                        tmp_path):
    arm, cam, cfg = make(ToolStep(10.0, -8.0, 0.0, 20.0))
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log).run(HiddenPartEstimator(arm, share))
    assert result.outcome == outcome and result.ok == (outcome == "converged")
    if outcome == "occluded":
        assert "70%" in result.reason and "hides" in result.reason
        stop = read_log(tmp_path / "it.jsonl")[-1]
        assert stop["loop_kind"] == "stop" and stop["executed"] is None
    # far from the pose the blob's size says nothing: the loop moved there as usual
    assert len(arm.moves) >= 2


def test_the_hidden_check_also_ends_a_spent_budget_near_the_pose_and_can_be_off():
    # the budget ends with the loop near the pose: a grasp would follow a "budget" outcome
    arm, cam, cfg = make(ToolStep(1.0, 0.0, 0.0, 30.0), max_loops=1.0)
    assert PositioningLoop(arm, cam, cfg).run(
        HiddenPartEstimator(arm, 0.7, gain=0.5)).outcome == "occluded"
    arm, cam, cfg = make(ToolStep(1.0, 0.0, 0.0, 30.0), max_loops=1.0)
    assert PositioningLoop(arm, cam, cfg).run(
        HiddenPartEstimator(arm, 0.9, gain=0.5)).outcome == "budget"
    arm, cam, cfg = make(ToolStep(1.0, 0.0, 0.0, 0.0), hidden_check_share=None)
    assert PositioningLoop(arm, cam, cfg).run(
        HiddenPartEstimator(arm, 0.5)).outcome == "converged"


@pytest.mark.parametrize("final_step", [True, False])
def test_the_converged_look_makes_its_step_unless_told_not_to(final_step, tmp_path):
    # gain 0.5 reads half of what is left: the look that finds the step below the thresholds
    # still sees as much again to go
    arm, cam, cfg = make(ToolStep(0.3, -0.2, 0.0, 2.0), converge_mm=0.05, converge_deg=0.3,
                         settle_frames=1, final_step=final_step)
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log, lambda: truth_error(arm)).run(
            TruthEstimator(arm, gain=0.5))
    records = read_log(tmp_path / "it.jsonl")
    last = records[-1]
    assert result.outcome == "converged" and last["loop_kind"] == "check"
    before = records[-2]["error"]
    if final_step:
        assert last["executed"] == last["commanded"] and last["pose_after"] is not None
        assert result.loops == records[-2]["loops"] + 1.0 == result.states[-1].loops
        assert "made" in result.reason
        # the step read half of the error, and made it halves it
        after = result.states[-1].error
        assert abs(after[2]) == pytest.approx(abs(before["phi_deg"]) / 2, abs=1e-6)
        assert math.hypot(*after[:2]) == pytest.approx(
            math.hypot(before["x_mm"], before["y_mm"]) / 2, abs=1e-6)
    else:
        assert last["executed"] is None and len(arm.moves) == len(records) - 1
        assert result.loops == records[-2]["loops"]
        assert result.states[-1].error == pytest.approx(tuple(before.values()))


def test_the_converged_look_makes_no_step_beyond_the_budget():
    arm, cam, cfg = make(ToolStep(0.3, -0.2, 0.0, 2.0), settle_frames=1, max_loops=2.0)
    result = PositioningLoop(arm, cam, cfg).run(TruthEstimator(arm, gain=0.5))
    moves = len(arm.moves)
    assert result.outcome == "converged" and result.loops == 2.0
    assert moves == len(result.states) - 1 and "made" not in result.reason


def test_a_grasp_to_follow_gets_the_converged_step_instead_of_a_move(tmp_path):
    arm, cam, cfg = make(ToolStep(0.3, -0.2, 0.0, 2.0), settle_frames=1)
    with IterationLog(tmp_path / "it.jsonl") as log:
        result = PositioningLoop(arm, cam, cfg, log, lambda: truth_error(arm)).run(
            TruthEstimator(arm, gain=0.5), carry_final_step=True)
    records = read_log(tmp_path / "it.jsonl")
    last = records[-1]
    assert result.outcome == "converged" and "carried to the grasp" in result.reason
    assert last["loop_kind"] == "check" and last["final_step"] == "carried"
    assert last["executed"] is None and len(arm.moves) == len(records) - 1
    assert result.carried is not None and result.carried.as_dict() == last["commanded"]
    assert result.loops == records[-2]["loops"] == result.states[-1].loops
    # nothing to carry where the loop makes no step: the budget spent on the last look
    arm, cam, cfg = make(ToolStep(0.3, -0.2, 0.0, 2.0), settle_frames=1, max_loops=2.0)
    result = PositioningLoop(arm, cam, cfg).run(TruthEstimator(arm, gain=0.5),
                                                carry_final_step=True)
    assert result.outcome == "converged" and result.carried is None


class LampEstimator(TruthEstimator):
    """The true step, its turn (and, where the lamp's table has one, its translation) read off
    by an offset that follows the tool's heading, as a lamp at the side makes it;
    ``heading_zero``: the model's zero by heading (None: none)."""

    def __init__(self, arm, lamp: HeadingZero, heading_zero: HeadingZero | None, **kw):
        super().__init__(arm, **kw)
        self.lamp, self.heading_zero = lamp, heading_zero

    def estimate_translation(self, image):
        t = super().estimate_translation(image)
        shift = self.lamp.shift_at(self.arm._pose.approach_rotation_deg)
        if shift is None:
            return t
        return dataclasses.replace(t, dx_mm=t.dx_mm + shift[0], dy_mm=t.dy_mm + shift[1])

    def estimate_rotation(self, translation):
        r = super().estimate_rotation(translation)
        return dataclasses.replace(r, dphi_deg=r.dphi_deg + self.lamp.at(
            self.arm._pose.approach_rotation_deg))


LAMP_START = ToolStep(6.0, -4.0, 0.0, 12.0)


def lamp_run(lamp: HeadingZero, zero: HeadingZero | None, log_path=None):
    """The loop from LAMP_START, reading the lamp's offsets and taking ``zero`` off; returns
    the result and, with ``log_path``, the iteration log's records."""
    arm, cam, cfg = make(LAMP_START, max_loops=4.0)
    log = None if log_path is None else IterationLog(log_path)
    try:
        result = PositioningLoop(arm, cam, cfg, log, lambda: truth_error(arm)).run(
            LampEstimator(arm, lamp, zero))
    finally:
        if log is not None:
            log.close()
    records = [] if log_path is None else \
        [json.loads(line) for line in log_path.read_text().splitlines()]
    return result, records


def full_looks_on_the_pose(lamp: HeadingZero, log_path, within_mm: float, key: str) -> list:
    """The loop with the lamp's own table as the zero converges within ``within_mm`` and
    0.05 deg; returns its records that logged ``key``."""
    zeroed, records = lamp_run(lamp, lamp, log_path)
    assert zeroed.outcome == "converged"
    ex, ey, ephi = zeroed.states[-1].error
    assert math.hypot(ex, ey) < within_mm and abs(ephi) < 0.05
    full = [r for r in records if r.get(key) is not None]
    assert full, f"no full look logged {key}"
    return full


def test_the_zero_by_heading_is_taken_off_each_full_look(tmp_path):
    """Where NN2 reads a turn that follows the tool's heading, the loop ends turned by it;
    with the model's zero by heading it ends on the pose, and the log keeps the zero."""
    headings = tuple(float(h) for h in range(-180, 180, 10))
    lamp = HeadingZero(headings, tuple(0.6 * math.sin(math.radians(2 * h)) + 0.3
                                       for h in headings))
    plain, _ = lamp_run(lamp, None)
    assert abs(plain.states[-1].error[2]) > 0.2
    full = full_looks_on_the_pose(lamp, tmp_path / "it.jsonl", 0.01, "heading_zero")
    assert full[-1]["heading_zero"] == pytest.approx(lamp.at(full[-1]["heading_deg"]))
    assert full[-1]["heading_zero_mm"] is None  # a table of the turn only


def test_the_translation_by_heading_is_taken_off_each_full_look(tmp_path):
    """Where the translation read follows the tool's heading too (a cube under a side lamp),
    the loop ends off by it with the turn's zero alone, and on the pose with the table's
    translation; the log keeps both."""
    headings = tuple(float(h) for h in range(-180, 180, 10))
    turns = tuple(0.6 * math.sin(math.radians(2 * h)) for h in headings)
    dx = tuple(0.08 * math.cos(math.radians(4 * h)) + 0.04 for h in headings)
    dy = tuple(-0.05 * math.sin(math.radians(4 * h)) for h in headings)
    lamp = HeadingZero(headings, turns, dx, dy)
    turn_only, _ = lamp_run(lamp, HeadingZero(headings, turns))
    ex, ey, ephi = turn_only.states[-1].error
    assert math.hypot(ex, ey) > 0.02 and abs(ephi) < 0.05
    full = full_looks_on_the_pose(lamp, tmp_path / "it.jsonl", 0.005, "heading_zero_mm")
    assert full[-1]["heading_zero_mm"] == pytest.approx(
        list(lamp.shift_at(full[-1]["heading_deg"])))


@pytest.mark.parametrize("scatter, count", [
    (None, 3),                       # not known: settle_frames
    ((0.012, 0.007, 0.046), 3),      # good light's single frames: three are enough
    ((0.079, 0.049, 0.25), 10),      # the poor lamp's: x wants (0.079 / 0.025)^2 = 10
    ((0.01, 0.01, 0.35), 13),        # the turn alone: (0.35 / 0.1)^2 = 12.25
    ((0.2, 0.0, 0.0), 16),           # capped at settle_max_frames
])
def test_settle_count_is_the_frames_the_rule_takes(scatter, count):
    cfg = LoopConfig(settle_frames=3, settle_max_frames=16, settle_sem_mm=0.025,
                     settle_sem_deg=0.1)
    assert cfg.settle_count(scatter) == count


def test_settle_count_without_bounds_is_settle_frames():
    cfg = LoopConfig(settle_frames=4, settle_max_frames=16, **FIXED)
    assert cfg.settle_count((1.0, 1.0, 10.0)) == 4
