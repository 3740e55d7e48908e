"""The simulated devices: SimArm, SimCamera, SimWrenchSensor on one shared SimCell.

They implement ``drivers.interfaces`` exactly like the real drivers, so the controller cannot
tell them apart. The cell belongs to whoever created it: disconnecting a device leaves the cell
open (close the cell, or use it as a context manager, when done).

Arm moves are solved at once (inverse kinematics, then the joints are set). With a
``CellTiming`` (``scene.timing: realistic``, ``sim_backend.cell.timing``) every action takes its
modelled time on the cell clock: a move its joint-interpolated motion time at the set ``speed``
plus settling, the hand its motion wait plus hand time, a frame the wait for the camera's next
exposure plus its latency, a wrench reading the next sample; in process the VAL and ATI lines'
wire time is charged too. ``pose()`` reports what the encoders see: where the servos stopped
(during a timed move, the intermediate pose), not the mechanical repeatability error, which
only the camera and the ground truth see (fed back through relative moves, an i.i.d. error
would random-walk the unobserved tilt: 0.18 deg after 200 moves). On a wall clock (behind the
emulators) a move really lasts that long and the arm passes through intermediate poses, so a
frame exposed meanwhile is motion-blurred. Without a timing (``ideal``) everything is instant.
The wrench sensor reads the cell's contact model: forces the environment exerts on the tool, in
the tool frame (z = approach axis), so pressing down onto the table gives Fz < 0.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drivers.core.errors import DeviceFaultError, FineposError, MotionRejectedError
from drivers.core.pose import Pose, ToolStep
from drivers.core.timing import (
    VAL_SPEED_MAX,
    VAL_SPEED_MIN,
    joint_motion_s,
    profile_elapsed,
    profile_fraction,
    stop_overtravel,
)
from drivers.interfaces import (
    Arm,
    Camera,
    Descent,
    Frame,
    GuardSetup,
    MonitorCondition,
    Wrench,
    WrenchSensor,
)
from drivers.safety import SafetyLimits
from sim_backend.cell import hand_camera
from sim_backend.cell import timing as cell_timing
from sim_backend.cell.sim_cell import SimCell
from sim_backend.cell.timing import CellTiming

# Behind the emulators a timed move passes through intermediate poses this often (s).
_ANIMATION_STEP_S = 0.02
# A motion that a condition may stop (``SimArm.move_until``) looks at it this often along its
# path (mm): at 8 N/mm contact stiffness, 2 N between two looks.
_WATCH_STEP_MM = 0.25
# Without timing (``ideal``: instant, no figure is measured) every 1 mm at a guard speed and
# every 5 mm at full speed, so a program's descent stays quick behind the emulators, whose
# camera stream shares the cell.
_IDEAL_WATCH_STEP_MM = 1.0
_IDEAL_FAST_WATCH_STEP_MM = 5.0
# The VAL lines of one guarded descent on the program path, as the VAL driver's defaults send
# them: two ``do set`` lines of a location (57 characters each), ``ex fpdesc`` (or
# ``ex fpgrip``), the ``*`` prompt and the closing prompt (see ``drivers.val.config``).
_SET_LINE_CHARS = 57
_DESCENT_LINE = "ex fpdesc"
_GRIP_LINE = "ex fpgrip"  # the descent, then the close and the lift in the same run
# The ATI line's bytes of a mean (``SA n``, ``QR`` and its record, ``SA`` set back), of ``SB``
# (the line, its echo, the prompt) and of the monitor condition's line as the ATI driver's
# defaults send it (``MC FZ LT -60 1``).
_ATI_MEAN_BYTES = 2 * cell_timing.ATI_SA_BYTES + cell_timing.ATI_QR_BYTES
_ATI_BIAS_BYTES = 3 + 4 + 1
_ATI_CONDITION_BYTES = 15 + 16 + 1


@dataclass
class ContactWire:
    """The wrist sensor's monitor output wired to the simulated arm's input, in one process:
    ``high()`` holds while the sensor's monitor condition holds on its biased reading."""

    cell: object
    condition: MonitorCondition | None = None
    offset: np.ndarray | None = None

    def high(self) -> bool:
        if self.condition is None:
            return False
        reading = self.cell.wrench() - (self.offset if self.offset is not None else 0.0)
        return self.condition.tripped(Wrench(*(float(v) for v in reading)))


def contact_wire(cell) -> ContactWire:
    """The cell's contact wire (one per cell, made on first use)."""
    wire = getattr(cell, "_finepos_contact_wire", None)
    if wire is None:
        wire = ContactWire(cell)
        cell._finepos_contact_wire = wire
    return wire


def _require_open(cell: SimCell, device: str) -> None:
    if not cell.is_open:
        raise DeviceFaultError(f"{device}: the simulated cell is closed")


class SimArm(Arm):
    """The simulated PUMA 260 with its parallel-jaw gripper.

    Args:
        cell: the simulated cell.
        limits: the safety layer (None behind the VAL emulator: the driver applies it).
        timing: the realistic cell's timing (None: ideal, every action instant).
    """

    # As the VAL driver by default (arm.where_before_move: false): a move starts from the pose
    # the last one reached, with no ``where`` exchange before it.
    reuse_reached_pose = True

    def __init__(self, cell: SimCell, limits: SafetyLimits | None = None,
                 timing: CellTiming | None = None) -> None:
        super().__init__(limits)
        self.cell = cell
        self.timing = timing
        self.speed_percent = 100.0

    def _open(self) -> None:
        _require_open(self.cell, "SimArm")

    def _close(self) -> None:
        """Nothing to release: the cell stays open for the other devices."""

    def _read_pose(self) -> Pose:
        # What the encoders see: where the servos stopped (an intermediate pose during a timed
        # move); the mechanical repeatability error is invisible to them, as on a real arm.
        if self.timing is not None:
            self.timing.val_wire(cell_timing.where_bytes())
        return self.cell.arm_pose()

    def _move_to(self, target: Pose) -> Pose:
        timing = self.timing
        if timing is None:
            return self.cell.move_arm(target)
        begin = timing.take_command_start()  # wall clock: the work below counts as motion
        start_q = np.array(self.cell.joint_angles_deg(), dtype=float)
        start = self.cell.arm_pose()
        timing.val_wire(cell_timing.move_bytes(target.as_dict()))
        self.cell.move_arm(target)
        delta = np.array(self.cell.joint_angles_deg(), dtype=float) - start_q
        seconds = timing.move_seconds(delta, self.speed_percent)
        if timing.clock.virtual:
            timing.motion(timing.config.arm.t0_s, "setup")
            timing.motion(seconds - timing.config.arm.t0_s)
            timing.at_rest_s = timing.clock.now()
            return self.cell.arm_pose()
        self._animate(start, target, seconds, begin)
        reached = self.cell.arm_pose()
        timing.clock.advance(begin + seconds - timing.clock.now())  # the end of the settling
        timing.at_rest_s = timing.clock.now()
        # As the VAL driver by default (arm.where_after_move: false): no read-back exchange.
        return reached

    def _animate(self, start: Pose, target: Pose, seconds: float, begin: float) -> None:
        """Real time: pass through intermediate poses along the move, then end at the target;
        waits to absolute deadlines from ``begin`` (when the move started), so the work of
        each step does not lengthen the move."""
        timing = self.timing
        arm, clock = timing.config.arm, timing.clock
        profile_s = max(0.0, seconds - arm.t0_s - arm.settle_s)
        final = self.cell.arm_pose()
        steps = int(profile_s / _ANIMATION_STEP_S)
        if steps >= 2:
            with contextlib.suppress(FineposError):  # back to the start: the move begins there
                self.cell.move_arm(start)

        def wait_until(offset_s: float) -> None:
            clock.advance(begin + offset_s - clock.now())

        wait_until(arm.t0_s)
        if steps >= 2:
            for i in range(1, steps):
                elapsed = i * profile_s / steps
                with contextlib.suppress(FineposError):  # a refused pose on the way: go on
                    self.cell.move_arm(_interpolate(start, target,
                                                    profile_fraction(elapsed, profile_s)))
                wait_until(arm.t0_s + elapsed)
            self.cell.move_arm(final)
        timing.note(arm.t0_s, "setup")
        timing.note(seconds - arm.t0_s)

    # -- program motions -----------------------------------------------------------------
    @property
    def runs_programs(self) -> bool:
        """``arm.options.programs`` (the simulated arm's ``SimArmConfig.programs``)."""
        return bool(getattr(self.cell.arm_config, "programs", False))

    def set_jaws_during_motion(self, closed: bool) -> None:
        """VAL's ``OPEN`` / ``CLOSE``: the jaws move while the next motion runs (no wait)."""
        if closed:
            self.cell.close_gripper()
        else:
            self.cell.open_gripper()

    def move_until(self, target: Pose, stop: Callable[[], bool], speed_factor: float = 1.0,
                   setup: bool = True, settle: bool = True) -> tuple[Pose, bool]:
        """A program's motion (see ``Arm.move_until``): ``stop`` is looked at every
        ``_WATCH_STEP_MM`` of the path; when it turns true the arm goes on for the reaction
        (``timing.arm.reaction_s`` and the sensor's ``ati_output_s``) and brakes at the full
        ``joint_accel_deg_s2`` (a judgement: a reaction stop is not scaled by the speed), then
        settles. Timed: the set-up ``t0_s`` only with ``setup``, the profile at the set speed
        times ``speed_factor``, the settling with ``settle`` or after a stop."""
        self._require_active()
        timing, cell = self.timing, self.cell
        begin = timing.take_command_start() if timing is not None else 0.0
        start = cell.arm_pose()
        start_q = np.array(cell.joint_angles_deg(), dtype=float)
        from sim_backend.cell.sim_cell import _tool_matrix  # the cell's own inverse kinematics

        goal_q = np.degrees(cell._solve(_tool_matrix(target)))
        delta = goal_q - start_q
        speed = min(VAL_SPEED_MAX, max(VAL_SPEED_MIN, self.speed_percent * speed_factor))
        step = start.tool_step_to(target)
        distance = math.hypot(step.dx_mm, step.dy_mm, step.dz_mm)
        if timing is not None:
            watch_mm = _WATCH_STEP_MM
        else:
            watch_mm = _IDEAL_WATCH_STEP_MM if speed_factor < 0.5 else _IDEAL_FAST_WATCH_STEP_MM
        count = max(1, math.ceil(distance / watch_mm))
        arm = timing.config.arm if timing is not None else None
        profile_s = joint_motion_s(delta, speed, arm) if arm is not None else 0.0
        t0 = arm.t0_s if arm is not None and setup else 0.0
        wall = timing is not None and not timing.clock.virtual

        def wait_until(offset_s: float) -> None:
            if wall:
                timing.clock.advance(begin + offset_s - timing.clock.now())

        stopped_at = None
        if stop():
            stopped_at = 0.0
        else:
            for fraction in self._watch_points(count, begin + t0, profile_s, wall):
                with contextlib.suppress(FineposError):  # a refused pose on the way: go on
                    cell.move_arm(_interpolate(start, target, fraction) if fraction < 1.0
                                  else target)
                if fraction < 1.0 and stop():
                    stopped_at = fraction
                    break
        if stopped_at is None:
            elapsed = t0 + profile_s
        else:
            latency = timing.config.arm.reaction_s + timing.config.ati_output_s \
                if timing is not None else 0.0
            # a reaction brakes at the arm's full deceleration, whatever the speed
            accel = arm.joint_accel_deg_s2 if arm is not None else 0.0
            over, rest_s = stop_overtravel(stopped_at, distance, profile_s,
                                           float(np.max(np.abs(delta))), accel, latency)
            final = min(1.0, stopped_at + (over / distance if distance > 0 else 0.0))
            if final > stopped_at:
                with contextlib.suppress(FineposError):
                    cell.move_arm(_interpolate(start, target, final))
            elapsed = t0 + profile_elapsed(stopped_at) * profile_s + rest_s
        if timing is not None:
            if settle or stopped_at is not None:
                elapsed += timing.config.arm.settle_s
            if wall:
                timing.note(t0, "setup")
                timing.note(elapsed - t0)
                wait_until(elapsed)
            else:
                timing.motion(t0, "setup")
                timing.motion(elapsed - t0)
            timing.at_rest_s = timing.clock.now()
        self._reached = cell.arm_pose()
        return self._reached, stopped_at is not None

    def _watch_points(self, count: int, profile_begin: float, profile_s: float,
                      wall: bool):
        """The path fractions at which a watched motion looks at its condition: every
        ``_WATCH_STEP_MM`` (``count`` in all) on the virtual clock; on a wall clock at the
        same points in time, or, when the cell's own work (shared with the camera's renders)
        runs late, where the profile is by then: the arm is never slowed down by it."""
        if not wall or profile_s <= 0.0:
            yield from (i / count for i in range(1, count + 1))
            return
        clock = self.timing.clock
        last = 0.0
        while last < 1.0:
            nearest = profile_begin + profile_elapsed(min(1.0, last + 1.0 / count)) * profile_s
            clock.advance(nearest - clock.now())
            last = max(min(1.0, last + 1.0 / count),
                       profile_fraction(clock.now() - profile_begin, profile_s))
            yield last

    def _guarded_descent(self, via: Pose, target: Pose, guard_speed_percent: float,
                         guard_mm: float, lift_mm: float | None,
                         ready: Callable[[], object]) -> Descent:
        """In process, as the VAL driver's program path: the target lines, ``ready()``, and
        ``ex fpdesc`` (with ``lift_mm``: ``ex fpgrip``) on the VAL line, the jaws opening as the arm
        starts, the first motion with its set-up, the guarded one at the guard speed and the
        rest without, settling where the arm stops (at the target, or on contact); with
        ``lift_mm`` then the close (the hand time) and the lift without a set-up of its own,
        the input still watched; a stop on contact costs a ``where`` (the driver reads where
        the arm stopped)."""
        timing = self.timing
        wire = contact_wire(self.cell)
        if timing is not None:
            timing.val_wire(2 * cell_timing.val_exchange_bytes("x" * _SET_LINE_CHARS))
        ready()
        if timing is not None:
            line = _GRIP_LINE if lift_mm is not None else _DESCENT_LINE
            timing.val_wire(cell_timing.val_exchange_bytes(line, 3))
        if wire.high():
            raise MotionRejectedError("the contact input is high before the descent")
        self.cell.open_gripper()
        guard_end, _ = self.guard_end(via, target, guard_mm)
        segments = ((via, 1.0), (guard_end, guard_speed_percent / 100.0), (target, 1.0))
        contact = False
        for i, (pose, factor) in enumerate(segments):
            pose, contact = self.move_until(pose, wire.high, factor, setup=i == 0,
                                            settle=i == len(segments) - 1)
            if contact:
                break
        closed = lifted = False
        if not contact and lift_mm is not None:
            self._close_in_program()
            closed = True
            lift = target.moved_in_tool_frame(ToolStep(dz_mm=-lift_mm))
            pose, contact = self.move_until(lift, wire.high, 1.0, setup=False, settle=True)
            lifted = not contact
        if contact and timing is not None:
            timing.val_wire(cell_timing.where_bytes())
        return Descent(pose, contact, closed, lifted)

    def _close_in_program(self) -> None:
        """A program's ``CLOSEI``: the jaws close where the arm stands, then the hand time
        (no command of its own on the line)."""
        timing = self.timing
        begin = timing.clock.now() if timing is not None else 0.0
        self.cell.close_gripper()
        if timing is None:
            return
        hand_s = timing.config.arm.hand_time_s
        if timing.clock.virtual:
            timing.motion(hand_s, "hand")
        else:
            timing.note(hand_s, "hand")
            timing.clock.advance(begin + hand_s - timing.clock.now())
        timing.at_rest_s = timing.clock.now()

    def _set_speed(self, percent: float) -> None:
        self.speed_percent = percent
        if self.timing is not None:
            self.timing.val_wire(cell_timing.val_exchange_bytes(f"speed {percent:g}"))

    def _halt(self) -> None:
        """Nothing to stop: in process a move is done when its call returns, and behind the VAL
        emulator the monitor reads the halt only after the move's line was answered."""

    def _set_gripper(self, closed: bool) -> float:
        timing = self.timing
        begin = timing.take_command_start() if timing is not None else 0.0
        width = self.cell.close_gripper() if closed else self.cell.open_gripper()
        if timing is not None:
            timing.val_wire(cell_timing.gripper_bytes(closed))
            hand_s = timing.config.arm.hand_time_s
            if timing.clock.virtual:
                timing.motion(hand_s, "hand")
            else:  # the jaws' own simulation counts as hand time
                timing.note(hand_s, "hand")
                timing.clock.advance(begin + hand_s - timing.clock.now())
            timing.at_rest_s = timing.clock.now()
        return width

    def _finger_width_mm(self) -> float:
        return self.cell.finger_width_mm()


def _interpolate(start: Pose, target: Pose, fraction: float) -> Pose:
    """The pose ``fraction`` of the way from ``start`` to ``target`` (translation linear,
    rotation about the tool axis linear; the tool keeps pointing as at the target)."""
    step = start.tool_step_to(target)
    scaled = type(step)(*(v * fraction for v in step.as_dict().values()))
    return start.moved_in_tool_frame(scaled)


class SimCamera(Camera):
    """The hand camera: 192x144 RGB frames rendered from the cell.

    With a timing, frames start every 1 / ``timing.camera.frame_rate_hz`` s, are exposed for
    ``exposure_s`` and delivered ``latency_frames`` frame periods after their exposure ended.
    On the virtual clock ``grab`` waits for the next exposure to start, then for the exposure
    and the latency (nothing moves meanwhile: the caller is the only actor). On a wall clock
    (the MJPEG emulator grabbing at its frame rate) a frame is rendered at the start and the end
    of its exposure and the two are blended when the arm moved in between (motion blur), and
    each grab returns the frame exposed ``latency_frames`` grabs earlier.
    """

    width_px = hand_camera.WIDTH_PX
    height_px = hand_camera.HEIGHT_PX

    def __init__(self, cell: SimCell, timing: CellTiming | None = None) -> None:
        super().__init__()
        self.cell = cell
        self.timing = timing
        self._delivered: list[Frame] = []
        self.blurred_frames = 0

    def _open(self) -> None:
        _require_open(self.cell, "SimCamera")

    def _close(self) -> None:
        """Nothing to release."""

    def _grab(self) -> Frame:
        timing = self.timing
        if timing is None:
            return Frame(self.cell.render(), time.monotonic())
        cam = timing.config.camera
        period = 1.0 / cam.frame_rate_hz
        clock = timing.clock
        if clock.virtual:
            now = clock.now()
            wait = (-now) % period
            timing.wait(wait + cam.delivery_s, "camera")
            return Frame(self.cell.render(), clock.now())
        frame = Frame(self._expose(cam.exposure_s), clock.now())
        self._delivered.append(frame)
        if len(self._delivered) <= cam.latency_frames:
            return self._delivered[0]
        return self._delivered.pop(0)

    def _expose(self, exposure_s: float) -> np.ndarray:
        """Render over one exposure on the wall clock: blended when the arm moved meanwhile."""
        before = self.cell.true_tool_pose()
        first = self.cell.render()
        if exposure_s <= 0:
            return first
        self.timing.clock.advance(exposure_s)
        if self.cell.true_tool_pose() == before:
            return first
        self.blurred_frames += 1
        second = self.cell.render()
        blend = (first.astype(np.uint16) + second.astype(np.uint16) + 1) // 2
        return blend.astype(np.uint8)


class SimWrenchSensor(WrenchSensor):
    """The wrist force-torque sensor: the cell's contact model, minus the bias."""

    def __init__(self, cell: SimCell, timing: CellTiming | None = None) -> None:
        super().__init__()
        self.cell = cell
        self.timing = timing
        self._offset = np.zeros(6)
        self._mean_rng = np.random.default_rng(0)  # noise of read_mean's averages

    def _open(self) -> None:
        _require_open(self.cell, "SimWrenchSensor")

    def _close(self) -> None:
        """Nothing to release."""

    def _read(self) -> Wrench:
        timing = self.timing
        if timing is not None:
            # The next sample, then (in process) one query and record on the ATI line; the
            # ATI emulator's line paces itself.
            period = 1.0 / timing.config.wrench_rate_hz
            timing.wait((-timing.clock.now()) % period, "sensor")
            timing.wire(cell_timing.ATI_QR_BYTES, timing.config.ati_baud)
        return Wrench(*(float(v) for v in self.cell.wrench() - self._offset))

    def _read_mean(self, samples: int) -> Wrench:
        """As the ATI controller's moving average (``SA n``, one ``QR``, ``SA`` set back): the
        mean of ``samples`` samples taken since the arm came to rest, waiting for the rest of
        them only."""
        timing = self.timing
        if timing is not None:
            timing.wait(self._mean_ready_s(samples, timing.clock.now()) - timing.clock.now(),
                        "sensor")
            timing.wire(_ATI_MEAN_BYTES, timing.config.ati_baud)
        return self._mean(samples)

    def _mean_ready_s(self, samples: int, now_s: float) -> float:
        """When the mean of ``samples`` samples since the arm came to rest can be asked for,
        from ``now_s`` on: the last of them taken, at a sample's time."""
        period = 1.0 / self.timing.config.wrench_rate_hz
        ready = max(now_s, self.timing.at_rest_s + samples * period)
        return ready + (-ready) % period

    def _prepare_contact_guard(self, condition: MonitorCondition,
                               samples: int | None) -> GuardSetup:
        """On the virtual clock, as the ATI driver's thread on the sensor's own line: the
        bias, the condition and the mean take their time from now on (``SB`` and the
        condition's line, the wait for the mean's samples, its lines), alongside what the
        caller does meanwhile (the arm's line); ``wait`` waits for what is left of it. The arm
        stands still until then, so the readings are taken now."""
        timing = self.timing
        if timing is None or not timing.clock.virtual:
            return super()._prepare_contact_guard(condition, samples)
        config = timing.config
        now = timing.clock.now()
        done = now + config.wire_time_s(_ATI_BIAS_BYTES + _ATI_CONDITION_BYTES, config.ati_baud)
        mean = None
        if samples is not None:
            done = self._mean_ready_s(samples, done) + config.wire_time_s(_ATI_MEAN_BYTES,
                                                                          config.ati_baud)
        self._bias()
        self._set_monitor_condition(condition)
        if samples is not None:
            mean = self._mean(samples)
        return GuardSetup(lambda: mean, on_wait=lambda: timing.wait(
            done - timing.clock.now(), "sensor"))

    def _mean(self, samples: int) -> Wrench:
        # the load at rest plus the mean of ``samples`` noise draws (the contact model once)
        sigma = self.cell.arm_config.wrench_noise_n / math.sqrt(samples)
        noise = self._mean_rng.normal(0.0, 1.0, 6) * np.array([sigma] * 3 + [sigma / 10] * 3)
        return Wrench(*(float(v) for v in self.cell.wrench(noisy=False) + noise - self._offset))

    def _bias(self) -> None:
        self._offset = self.cell.wrench()
        contact_wire(self.cell).offset = self._offset

    def _set_monitor_condition(self, condition: MonitorCondition | None) -> None:
        wire = contact_wire(self.cell)
        wire.condition, wire.offset = condition, self._offset
