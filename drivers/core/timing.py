"""The cell's timing model, in one place: serial wire time, arm motion time, hand, camera, sensor.

Config section ``timing`` (every figure configurable; ``scene.timing: realistic | ideal`` picks
whether the simulated cell and the emulators take these times at all). Sources, as docs/simulator.md
lists them: the VAL line's 9600 baud 8N1 is confirmed on real PUMA 260s; the ATI controller's
38400 baud comes from a public driver; V+ ``HAND.TIME`` defaults to 0.5 s; VAL ``SPEED`` takes
0.01..327.67 with 100 normal. No public source gives the PUMA 260's joint speeds, accelerations
or settling: those defaults are judgements, to be fitted on a real arm with
``finepos fit-timing`` (``fit_arm_timing`` here).

The motion model: every joint runs a trapezoidal profile (a triangle when it never reaches its
cruise speed), all joints of a move start together, the slowest joint decides, and VAL's
``speed`` (percent, 100 normal) scales the cruise speed and the acceleration alike:

    t = t0 + max_j T(|dq_j|, v * s, a * s) + settle,  s = speed / 100,
    T(d, v, a) = d / v + v / a  when d >= v^2 / a,  else  2 * sqrt(d / a).

Pure functions and frozen dataclasses; imports nothing of finepos beyond ``drivers.core``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

TimingMode = Literal["realistic", "ideal"]
BITS_PER_BYTE_8N1 = 10  # start bit, 8 data bits, stop bit
VAL_SPEED_MIN = 0.01  # VAL SPEED's range (hardware notes), 100 = normal
VAL_SPEED_MAX = 327.67
_POSITIVE = {"min": 0.0, "exclusive_min": True}


@dataclass(frozen=True)
class ArmTiming:
    """Section ``timing.arm``: the PUMA 260 under VAL (judgements unless fitted).

    t0_s: fixed cost of every move (trajectory set-up, the prompt's turnaround);
    joint_speed_deg_s / joint_accel_deg_s2: each joint's cruise speed and acceleration at
    ``speed 100``; settle_s: from the end of the profile to the prompt (servo settling);
    hand_time_s: ``openi`` / ``closei`` wait for the motion, then this (V+ ``HAND.TIME``,
    0.5 s by default); reaction_s: from an input line going high to the arm braking under a
    program's ``REACTI`` (a judgement: one VAL II trajectory cycle, 28 ms).
    """

    t0_s: float = field(default=0.12, metadata={"min": 0.0, "max": 10.0})
    joint_speed_deg_s: float = field(default=60.0, metadata=_POSITIVE)
    joint_accel_deg_s2: float = field(default=240.0, metadata=_POSITIVE)
    settle_s: float = field(default=0.08, metadata={"min": 0.0, "max": 10.0})
    hand_time_s: float = field(default=0.5, metadata={"min": 0.0, "max": 10.0})
    reaction_s: float = field(default=0.028, metadata={"min": 0.0, "max": 1.0})


@dataclass(frozen=True)
class CameraTiming:
    """Section ``timing.camera``: judgements for a typical USB/network camera.

    frame_rate_hz: frames start every 1/rate s; exposure_s: how long each is exposed (the arm
    moving meanwhile blurs it); latency_frames: frame periods from the end of an exposure to
    its delivery.
    """

    frame_rate_hz: float = field(default=30.0, metadata={"min": 0.5, "max": 1000.0})
    exposure_s: float = field(default=0.01, metadata={"min": 0.0, "max": 1.0})
    latency_frames: int = field(default=1, metadata={"min": 0, "max": 10})

    @property
    def delivery_s(self) -> float:
        """From the start of a frame's exposure to its delivery: the exposure, then
        ``latency_frames`` frame periods."""
        return self.exposure_s + self.latency_frames / self.frame_rate_hz

    def __post_init__(self) -> None:
        if self.exposure_s > 1.0 / self.frame_rate_hz:
            raise ValueError(f"exposure_s: {self.exposure_s:g} s is longer than one frame "
                             f"period ({1.0 / self.frame_rate_hz:g} s)")


@dataclass(frozen=True)
class TimingConfig:
    """Config section ``timing``: the figures the realistic cell takes.

    val_baud: the VAL terminal line (9600, confirmed); ati_baud: the ATI F/T controller's line
    (38400, from a public driver); bits_per_byte: 10 for 8N1; wrench_rate_hz: the sensor's
    output rate (a reading is never fresher than one sample); ati_output_s: from a monitor
    condition holding to the sensor's discrete output switching (no public figure for the
    serial controller; a judgement, "a few ms" is typical of threshold outputs); arm / camera:
    see ArmTiming and CameraTiming.
    """

    val_baud: int = field(default=9600, metadata={"min": 50})
    ati_baud: int = field(default=38400, metadata={"min": 50})
    bits_per_byte: int = field(default=BITS_PER_BYTE_8N1, metadata={"min": 7, "max": 12})
    wrench_rate_hz: float = field(default=100.0, metadata={"min": 1.0, "max": 10000.0})
    ati_output_s: float = field(default=0.005, metadata={"min": 0.0, "max": 1.0})
    arm: ArmTiming = ArmTiming()
    camera: CameraTiming = CameraTiming()

    def wire_time_s(self, n_bytes: int, baud: int) -> float:
        """Seconds ``n_bytes`` take on a line at ``baud`` (``bits_per_byte`` each)."""
        return wire_time_s(n_bytes, baud, self.bits_per_byte)


def wire_time_s(n_bytes: int, baud: float, bits_per_byte: int = BITS_PER_BYTE_8N1) -> float:
    """Seconds ``n_bytes`` take on a serial line at ``baud`` (8N1: 10 bits a byte)."""
    if baud <= 0:
        raise ValueError(f"baud must be > 0, got {baud}")
    return n_bytes * bits_per_byte / float(baud)


def speed_factor(speed_percent: float) -> float:
    """VAL ``speed`` (0.01..327.67 percent, 100 normal) as a factor on speed and acceleration."""
    if not VAL_SPEED_MIN <= speed_percent <= VAL_SPEED_MAX:
        raise ValueError(f"speed must be in {VAL_SPEED_MIN}..{VAL_SPEED_MAX} percent, "
                         f"got {speed_percent:g}")
    return speed_percent / 100.0


def profile_time_s(distance_deg: float, speed_deg_s: float, accel_deg_s2: float) -> float:
    """Time of one joint's trapezoidal (or triangular) profile over ``distance_deg``."""
    d = abs(distance_deg)
    if d < 1e-12:
        return 0.0
    if d >= speed_deg_s ** 2 / accel_deg_s2:
        return d / speed_deg_s + speed_deg_s / accel_deg_s2
    return 2.0 * math.sqrt(d / accel_deg_s2)


def profile_fraction(elapsed_s: float, total_s: float) -> float:
    """Share (0..1) of the path covered ``elapsed_s`` into a symmetric profile of ``total_s``
    (the slowest joint's; the others are synchronised to it). A smooth s-curve stands in for
    the exact trapezoid: position along the move, not the time, depends on it."""
    if total_s <= 0.0 or elapsed_s >= total_s:
        return 1.0
    if elapsed_s <= 0.0:
        return 0.0
    x = elapsed_s / total_s
    return x * x * (3.0 - 2.0 * x)


def profile_elapsed(fraction: float) -> float:
    """The share of a profile's time (0..1) at which ``profile_fraction`` reaches
    ``fraction`` of the path (its inverse)."""
    if fraction <= 0.0:
        return 0.0
    if fraction >= 1.0:
        return 1.0
    low, high = 0.0, 1.0
    for _ in range(40):
        mid = (low + high) / 2.0
        if mid * mid * (3.0 - 2.0 * mid) < fraction:
            low = mid
        else:
            high = mid
    return (low + high) / 2.0


def stop_overtravel(fraction: float, distance: float, profile_s: float, joint_travel_deg: float,
                    accel_deg_s2: float, latency_s: float) -> tuple[float, float]:
    """(path beyond the trip point, seconds from the trip to rest) of a move stopped at once
    ``fraction`` of its way along ``distance`` (any unit) over ``profile_s``: it goes on at its
    speed for ``latency_s``, then brakes at ``accel_deg_s2`` on its largest joint
    (``joint_travel_deg``: that joint's whole travel)."""
    if profile_s <= 0.0 or distance <= 0.0:
        return 0.0, latency_s
    x = profile_elapsed(fraction)
    rate = 6.0 * x * (1.0 - x) / profile_s  # d(fraction)/dt of profile_fraction's s-curve
    brake_s = rate * joint_travel_deg / accel_deg_s2 if accel_deg_s2 > 0 else 0.0
    speed = rate * distance
    return speed * (latency_s + brake_s / 2.0), latency_s + brake_s


def joint_motion_s(delta_deg: Sequence[float], speed_percent: float, arm: ArmTiming) -> float:
    """The profile time of a joint-interpolated move (no t0, no settle): the slowest joint's."""
    s = speed_factor(speed_percent)
    v, a = arm.joint_speed_deg_s * s, arm.joint_accel_deg_s2 * s
    return max((profile_time_s(d, v, a) for d in delta_deg), default=0.0)


def move_time_s(delta_deg: Sequence[float], speed_percent: float, arm: ArmTiming) -> float:
    """From sending ``do move`` (after its bytes) to the prompt: t0 + profile + settle."""
    return arm.t0_s + joint_motion_s(delta_deg, speed_percent, arm) + arm.settle_s


@dataclass(frozen=True)
class TimedMove:
    """One timed move for the fit: the joints' travel (deg), VAL speed, the measured seconds
    of motion (prompt time minus wire time)."""

    delta_deg: tuple[float, ...]
    speed_percent: float
    seconds: float


@dataclass(frozen=True)
class ArmFit:
    """The fitted motion model: t0_s includes the settle time (a prompt cannot tell them
    apart); rms_s is the fit's residual; cruise_reached counts moves whose slowest joint
    reached its cruise speed (with none, joint_speed_deg_s is not determined by the data)."""

    t0_s: float
    joint_speed_deg_s: float
    joint_accel_deg_s2: float
    rms_s: float
    cruise_reached: int


def _fit_t0(moves: Sequence[TimedMove], v: float, a: float) -> tuple[float, float]:
    """Best t0 (least squares, >= 0) for fixed v, a and the residual RMS."""
    arm = ArmTiming(t0_s=0.0, joint_speed_deg_s=v, joint_accel_deg_s2=a, settle_s=0.0)
    motion = [joint_motion_s(m.delta_deg, m.speed_percent, arm) for m in moves]
    t0 = max(0.0, sum(m.seconds - t for m, t in zip(moves, motion, strict=True)) / len(moves))
    rms = math.sqrt(sum((m.seconds - t0 - t) ** 2 for m, t in zip(moves, motion, strict=True))
                    / len(moves))
    return t0, rms


def fit_arm_timing(moves: Sequence[TimedMove]) -> ArmFit:
    """Least-squares fit of t0, joint speed and acceleration to timed moves.

    t0 is solved in closed form for every (v, a); (v, a) by a coarse log grid, then a shrinking
    pattern search around the best point. Needs at least three moves.

    Raises:
        ValueError: fewer than three moves, or a move without any joint travel.
    """
    if len(moves) < 3:
        raise ValueError(f"the fit needs at least 3 timed moves, got {len(moves)}")
    if any(max((abs(d) for d in m.delta_deg), default=0.0) <= 0.0 for m in moves):
        raise ValueError("every timed move must move a joint")
    best = (math.inf, 0.0, 0.0)
    for i in range(25):
        lv = math.log(1.0) + i * (math.log(2000.0) - math.log(1.0)) / 24
        for j in range(25):
            la = math.log(5.0) + j * (math.log(50000.0) - math.log(5.0)) / 24
            rms = _fit_t0(moves, math.exp(lv), math.exp(la))[1]
            if rms < best[0]:
                best = (rms, lv, la)
    rms, lv, la = best
    step = 0.3
    while step > 1e-5:
        improved = False
        for dv, da in ((step, 0), (-step, 0), (0, step), (0, -step)):
            r = _fit_t0(moves, math.exp(lv + dv), math.exp(la + da))[1]
            if r < rms - 1e-15:
                rms, lv, la, improved = r, lv + dv, la + da, True
        if not improved:
            step /= 2.0
    v, a = math.exp(lv), math.exp(la)
    t0, rms = _fit_t0(moves, v, a)
    cruise = sum(max(abs(d) for d in m.delta_deg)
                 >= (v * m.speed_percent / 100.0) ** 2 / (a * m.speed_percent / 100.0)
                 for m in moves)
    return ArmFit(t0, v, a, rms, cruise)
