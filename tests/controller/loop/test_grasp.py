"""Force guards (pure) and the guarded grasp sequence on fakes."""

import numpy as np
import pytest

from controller.loop.grasp import GraspConfig, guarded_grasp
from controller.loop.guards import Guard, first_tripped, tripped
from drivers.core.pose import ToolStep
from drivers.interfaces import Descent, Wrench
from tests.mocks.fakes import HOME, FakeArm, FakeWrenchSensor

ZERO = Wrench(0, 0, 0, 0, 0, 0)
BY_WIDTH = GraspConfig(check="width")
HOME_Z = HOME.z_mm


def w(fz=0.0, fx=0.0, tz=0.0):
    return Wrench(fx, 0.0, fz, 0.0, 0.0, tz)


@pytest.mark.parametrize("guard,reading,expected", [
    (Guard("fz_n", ">", 5.0, "stop"), w(fz=5.1), True),
    (Guard("fz_n", ">", 5.0, "stop"), w(fz=-9.0), False),
    (Guard("fz_n", "<", -5.0, "stop"), w(fz=-9.0), True),
    (Guard("fz_n", "abs>", 5.0, "stop"), w(fz=-9.0), True),
    (Guard("force_n", ">", 5.0, "stop"), w(fz=3.0, fx=4.1), True),
    (Guard("tz_nm", "abs>", 0.5, "retreat"), w(tz=0.4), False),
])
def test_guard_tripping(guard, reading, expected):
    assert tripped(guard, reading) is expected


def test_first_tripped_respects_order():
    guards = (Guard("force_n", ">", 10.0, "retreat", "excess"),
              Guard("force_n", ">", 1.0, "stop", "contact"))
    assert first_tripped(w(fz=20.0), guards).name == "excess"
    assert first_tripped(w(fz=2.0), guards).name == "contact"
    assert first_tripped(ZERO, guards) is None


class Surface:
    """A wrench sensor whose force rises like a spring below a contact depth along +z."""

    def __init__(self, arm, start_z, contact_depth_mm, k_n_per_mm=4.0):
        self.arm, self.start_z, self.depth, self.k = arm, start_z, contact_depth_mm, k_n_per_mm

    def __call__(self):
        descended = self.start_z - self.arm._pose.z_mm  # tool points down: +dz lowers z
        return w(fz=max(0.0, descended - self.depth) * self.k)


def setup(contact_depth_mm, object_width_mm=30.0):
    arm = FakeArm(object_width_mm=object_width_mm)
    sensor = FakeWrenchSensor()
    sensor._reading = Surface(arm, arm._pose.z_mm, contact_depth_mm)
    for d in (arm, sensor):
        d.connect()
        d.activate()
    return arm, sensor


def test_grasp_succeeds_when_free_descent_reaches_depth():
    arm, sensor = setup(contact_depth_mm=100.0)
    start = arm.pose()
    res = guarded_grasp(arm, sensor, 40.0, 30.0, BY_WIDTH)
    assert res.success and res.depth_mm == pytest.approx(40.0)
    assert arm.pose().z_mm == pytest.approx(start.z_mm - 40.0 + BY_WIDTH.lift_mm)  # lifted


def test_the_descent_goes_free_then_steps_over_the_rim_then_in_one_move():
    # 35 mm through free space to the part's top (35 mm down), 1.2 mm steps down to 41 mm
    # (past the rim), then the rest at once; the guards read after each.
    arm, sensor = setup(contact_depth_mm=100.0)
    res = guarded_grasp(arm, sensor, 50.0, 30.0, BY_WIDTH)
    assert res.success and len(res.forces_n) == 7
    assert [round(HOME_Z - p.z_mm, 6) for p in arm.moves[:7]] == [
        35.0, 36.2, 37.4, 38.6, 39.8, 41.0, 50.0]
    arm, sensor = setup(contact_depth_mm=10.0)  # something 10 mm down: 25 mm too deep at once
    res = guarded_grasp(arm, sensor, 40.0, 30.0, BY_WIDTH)
    assert not res.success and res.retreated and res.forces_n == [pytest.approx(100.0)]


def test_a_finger_on_the_parts_top_or_rim_is_caught_one_step_in():
    for contact_mm, forces in ((35.0, [0.0, 4.8]), (38.5, [0.0, 0.0, 0.0, 0.4, 5.2])):
        arm, sensor = setup(contact_depth_mm=contact_mm)
        start = arm.pose()
        res = guarded_grasp(arm, sensor, 50.0, 30.0, BY_WIDTH)
        assert not res.success and res.retreated and "early contact" in res.reason
        assert res.forces_n == pytest.approx(forces)  # pushed <= 1.2 mm, then back
        assert arm.pose() == start


def test_small_steps_feel_the_way_down():
    arm, sensor = setup(contact_depth_mm=100.0)
    res = guarded_grasp(arm, sensor, 40.0, 30.0, GraspConfig(check="width", free_descent_mm=30.0,
                                                              step_mm=1.0, guard_zone_mm=100.0))
    assert res.success and len(res.forces_n) == 1 + 10  # 30 mm at once, then 1 mm steps


def test_early_contact_retreats_to_start():
    arm, sensor = setup(contact_depth_mm=10.0)
    start = arm.pose()
    res = guarded_grasp(arm, sensor, 40.0, 30.0, GraspConfig(check="width", free_descent_mm=0.0,
                                                              step_mm=1.0, guard_zone_mm=100.0))
    assert not res.success and res.retreated and "early contact" in res.reason
    assert res.depth_mm < 20.0
    assert arm.pose() == start and arm.finger_width_mm() == 40.0


def test_contact_in_the_expected_zone_stops_and_grips():
    arm, sensor = setup(contact_depth_mm=38.5)
    res = guarded_grasp(arm, sensor, 40.0, 30.0, BY_WIDTH)
    # 38.6 mm reads 0.4 N, 39.8 mm 5.2 N: within the last 2 mm, a contact that stops there
    assert res.success and "contact" in res.reason and res.depth_mm == pytest.approx(39.8)


def test_empty_grip_fails_the_width_check_and_retreats():
    arm, sensor = setup(contact_depth_mm=100.0, object_width_mm=None)
    start = arm.pose()
    res = guarded_grasp(arm, sensor, 40.0, 30.0, BY_WIDTH)
    assert not res.success and "grip check failed" in res.reason
    assert arm.pose() == start


class Held:
    """A wrench sensor that feels ``weight_n`` along the approach axis once the arm has lifted
    above its lowest point (the part hangs in the jaws)."""

    def __init__(self, arm, weight_n):
        self.arm, self.weight_n, self.lowest = arm, weight_n, arm._pose.z_mm

    def __call__(self):
        self.lowest = min(self.lowest, self.arm._pose.z_mm)
        return w(fz=self.weight_n if self.arm._pose.z_mm > self.lowest + 1.0 else 0.0)


class Noisy:
    """``inner``'s reading plus Gaussian force noise (``sigma_n``) on every component."""

    def __init__(self, inner, sigma_n, seed=0):
        self.inner, self.sigma, self.rng = inner, sigma_n, np.random.default_rng(seed)

    def __call__(self):
        r = self.inner()
        fx, fy, fz = np.array([r.fx_n, r.fy_n, r.fz_n]) + self.rng.normal(0.0, self.sigma, 3)
        return Wrench(fx, fy, fz, r.tx_nm, r.ty_nm, r.tz_nm)


CUBE_N = 0.015 * 9.81


@pytest.mark.parametrize("weight_n,success", [
    (CUBE_N, True),   # the cube hangs in the jaws
    (0.0, False),     # the jaws closed on nothing: the wrist feels no weight
])
def test_weight_check_is_the_default_and_beats_the_noise(weight_n, success):
    # A VAL-like gripper: it reports 0 mm however it closed, so the width says nothing; the
    # noise (0.05 N, an ATI count) is a third of the cube's weight, one reading would be a
    # coin toss against half of it; the mean of 16 is not.
    for seed in range(10):
        arm, sensor = setup(contact_depth_mm=100.0, object_width_mm=0.0)
        sensor._reading = Noisy(Held(arm, weight_n), 0.05, seed)
        start = arm.pose()
        res = guarded_grasp(arm, sensor, 40.0, 30.0, GraspConfig(), part_weight_n=CUBE_N)
        assert res.success is success, res.reason
        assert res.held_weight_n == pytest.approx(weight_n, abs=0.05)
        if not success:
            assert "N on the wrist" in res.reason and arm.pose() == start


def test_the_weight_check_needs_a_threshold_and_a_lift():
    arm, sensor = setup(contact_depth_mm=100.0)
    with pytest.raises(ValueError, match="min_held_weight_n"):
        guarded_grasp(arm, sensor, 40.0, 30.0, GraspConfig())
    with pytest.raises(ValueError, match="lift_mm"):
        GraspConfig(lift_mm=0.0)


class Jammed:
    """A finger lands on the part as the jaws close: the wrist feels it pushed up."""

    def __init__(self, arm):
        self.arm = arm

    def __call__(self):
        return w(fz=-8.0 if self.arm.finger_width_mm() < 35.0 else 0.0)


def test_a_finger_jammed_while_closing_fails_the_grasp():
    arm, sensor = setup(contact_depth_mm=100.0)
    sensor._reading = Jammed(arm)
    res = guarded_grasp(arm, sensor, 40.0, 30.0, GraspConfig(min_held_weight_n=0.05))
    assert not res.success and "jammed" in res.reason
    assert res.closing_force_n == pytest.approx(8.0)


@pytest.mark.parametrize("weight_n,min_n,success", [
    (0.15, 0.08, True),    # the part's weight is felt
    (0.0, 0.08, False),    # jaws closed on nothing the width check could see (VAL)
])
def test_held_weight_check(weight_n, min_n, success):
    arm, sensor = setup(contact_depth_mm=100.0)
    sensor._reading = Held(arm, weight_n)
    start = arm.pose()
    res = guarded_grasp(arm, sensor, 40.0, 30.0, GraspConfig(check="both",
                                                            min_held_weight_n=min_n))
    assert res.success is success
    assert res.held_weight_n == pytest.approx(weight_n)
    if not success:
        assert "N on the wrist" in res.reason and arm.pose() == start


def test_the_first_descent_move_makes_the_carried_step():
    arm, sensor = setup(contact_depth_mm=60.0)
    start = arm._pose
    made = []
    carried = ToolStep(0.04, -0.03, 0.0, 0.2)
    res = guarded_grasp(arm, sensor, 40.0, 30.0, BY_WIDTH, carried=carried,
                        on_carried=lambda: made.append(arm._pose))
    assert res.success and res.carried_step == carried
    assert res.as_dict()["carried_step"] == carried.as_dict()
    # one call, after the first move: the step and the free descent in one command
    expected = start.moved_in_tool_frame(ToolStep(0.04, -0.03, 35.0, 0.2))
    assert len(made) == 1
    for f in ("x_mm", "y_mm", "z_mm", "t_deg"):
        assert getattr(made[0], f) == pytest.approx(getattr(expected, f), abs=1e-9)
    # without a carried step the descent moves straight down
    arm, sensor = setup(contact_depth_mm=60.0)
    res = guarded_grasp(arm, sensor, 40.0, 30.0, BY_WIDTH)
    assert res.carried_step is None and res.as_dict()["carried_step"] is None


def test_without_the_lift_the_jaws_close_and_stay_down_unweighed():
    """To centre a part between the jaws: the guarded descent, the closing and its jam
    check, and no lift (the part's weight is neither needed nor checked)."""
    arm, sensor = setup(contact_depth_mm=100.0)
    start = arm.pose()
    res = guarded_grasp(arm, sensor, 40.0, 30.0, GraspConfig(), part_weight_n=CUBE_N,
                        lift=False)
    assert res.success and res.held_weight_n is None
    assert arm.pose().z_mm == pytest.approx(start.z_mm - 40.0)
    assert arm.finger_width_mm() == pytest.approx(30.0)
    arm, sensor = setup(contact_depth_mm=100.0)
    sensor._reading = Jammed(arm)
    res = guarded_grasp(arm, sensor, 40.0, 30.0, GraspConfig(), part_weight_n=CUBE_N,
                        lift=False)
    assert not res.success and "jammed" in res.reason and arm.pose() == start


# -- the program path: the descent, the close and the lift in one run ---------------------------
class ProgramArm(FakeArm):
    """A fake arm whose controller runs the grasp program: down to the target, then (asked
    to lift) the close and the lift, stopped where ``input_high()`` holds after the close."""

    def __init__(self, **kwargs) -> None:
        super().__init__(**kwargs)
        self.input_high = lambda: False
        self.runs = []
        self.host_closes = 0

    @property
    def runs_programs(self) -> bool:
        return True

    def _guarded_descent(self, via, target, guard_speed_percent, guard_mm, lift_mm, ready):
        ready()
        self.runs.append(lift_mm)
        self._move_to(target)
        if lift_mm is None:
            return Descent(target, False)
        self._width_mm = self.object_width_mm or 0.0
        if self.input_high():
            return Descent(target, True, closed=True)
        lifted = target.moved_in_tool_frame(ToolStep(dz_mm=-lift_mm))
        self._move_to(lifted)
        return Descent(lifted, False, closed=True, lifted=True)

    def _set_gripper(self, closed: bool) -> float:
        self.host_closes += closed
        return super()._set_gripper(closed)


class MonitoringSensor(FakeWrenchSensor):
    """A fake sensor with a monitor output: ``output_high()`` while its condition holds."""

    condition = None

    def _set_monitor_condition(self, condition) -> None:
        self.condition = condition

    def output_high(self) -> bool:
        return self.condition is not None and self.condition.tripped(self._read())


def program_setup(reading):
    arm, sensor = ProgramArm(object_width_mm=30.0), MonitoringSensor()
    sensor._reading = reading(arm)
    arm.input_high = sensor.output_high
    for d in (arm, sensor):
        d.connect()
        d.activate()
    return arm, sensor


@pytest.mark.parametrize("weight_n,success", [(CUBE_N, True), (0.0, False)])
def test_the_program_path_closes_and_lifts_in_the_descent_run(weight_n, success):
    arm, sensor = program_setup(lambda arm: Held(arm, weight_n))
    start = arm.pose()
    res = guarded_grasp(arm, sensor, 40.0, 30.0, GraspConfig(), part_weight_n=CUBE_N)
    assert res.success is success, res.reason
    assert arm.runs == [GraspConfig().lift_mm] and arm.host_closes == 0
    assert res.held_weight_n == pytest.approx(weight_n)
    if success:
        assert arm.pose().z_mm == pytest.approx(start.z_mm - 40.0 + GraspConfig().lift_mm)
    else:
        assert "N on the wrist" in res.reason and arm.pose() == start


def test_a_jam_that_stops_the_program_before_the_lift_retreats():
    arm, sensor = program_setup(Jammed)
    start = arm.pose()
    res = guarded_grasp(arm, sensor, 40.0, 30.0, GraspConfig(), part_weight_n=CUBE_N)
    assert not res.success and res.retreated and "jammed" in res.reason
    assert res.closing_force_n == pytest.approx(8.0)
    assert arm.pose() == start and arm.finger_width_mm() == 40.0


@pytest.mark.parametrize("config,lift", [(GraspConfig(check="width"), True),
                                         (GraspConfig(), False)])
def test_without_the_weight_check_or_the_lift_the_host_closes(config, lift):
    arm, sensor = program_setup(lambda arm: Held(arm, CUBE_N))
    res = guarded_grasp(arm, sensor, 40.0, 30.0, config, part_weight_n=CUBE_N, lift=lift)
    assert res.success, res.reason
    assert arm.runs == [None] and arm.host_closes == 1
