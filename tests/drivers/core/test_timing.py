"""The timing model: wire time, trapezoidal joint profiles scaled by VAL speed, the fit."""

from __future__ import annotations

import math

import pytest

from drivers.core.errors import ConfigError
from drivers.core.timing import (
    ArmTiming,
    TimedMove,
    TimingConfig,
    fit_arm_timing,
    move_time_s,
    profile_fraction,
    profile_time_s,
    speed_factor,
    wire_time_s,
)
from drivers.core.typed_config import from_mapping

ARM = ArmTiming(t0_s=0.1, joint_speed_deg_s=40.0, joint_accel_deg_s2=150.0, settle_s=0.05)


def test_wire_time_is_ten_bits_a_byte():
    assert wire_time_s(262, 9600) == pytest.approx(0.27291, rel=1e-4)
    assert TimingConfig().wire_time_s(96, 9600) == pytest.approx(0.1)


def test_profile_is_triangular_then_trapezoidal():
    # v^2/a = 1 deg: below it a triangle, above it cruise
    assert profile_time_s(0.25, 10.0, 100.0) == pytest.approx(2 * math.sqrt(0.25 / 100.0))
    assert profile_time_s(5.0, 10.0, 100.0) == pytest.approx(5.0 / 10.0 + 10.0 / 100.0)
    assert profile_time_s(1.0, 10.0, 100.0) == pytest.approx(0.2)  # both agree at the switch
    assert profile_time_s(0.0, 10.0, 100.0) == 0.0


def test_longer_moves_take_longer_and_lower_speed_slows_them():
    short = move_time_s((1.0, 0.5, 0, 0, 0, 0), 100.0, ARM)
    long = move_time_s((8.0, 0.5, 0, 0, 0, 0), 100.0, ARM)
    slow = move_time_s((8.0, 0.5, 0, 0, 0, 0), 25.0, ARM)
    fast = move_time_s((8.0, 0.5, 0, 0, 0, 0), 200.0, ARM)
    assert short < long < slow
    assert fast < long
    # the slowest joint decides
    assert move_time_s((8.0, 8.0, 1.0, 0, 0, 0), 100.0, ARM) == pytest.approx(long)


def test_speed_takes_vals_range():
    assert speed_factor(327.67) == pytest.approx(3.2767)
    assert speed_factor(0.01) == pytest.approx(1e-4)
    for bad in (0.0, 327.7, -1.0):
        with pytest.raises(ValueError, match="speed"):
            speed_factor(bad)


def test_profile_fraction_runs_from_zero_to_one():
    assert profile_fraction(0.0, 1.0) == 0.0
    assert profile_fraction(0.5, 1.0) == pytest.approx(0.5)
    assert profile_fraction(2.0, 1.0) == 1.0
    assert profile_fraction(0.2, 1.0) < profile_fraction(0.4, 1.0)


def test_fit_recovers_the_model_it_is_given():
    moves = []
    for speed in (25.0, 50.0, 100.0):
        for d in (0.3, 1.5, 3.0, 7.5):
            delta = (d, 0.4 * d, 0.1, 0.0, 0.0, 0.0)
            moves.append(TimedMove(delta, speed, move_time_s(delta, speed, ARM)))
    fit = fit_arm_timing(moves)
    assert fit.t0_s == pytest.approx(ARM.t0_s + ARM.settle_s, rel=0.02)
    assert fit.joint_speed_deg_s == pytest.approx(ARM.joint_speed_deg_s, rel=0.02)
    assert fit.joint_accel_deg_s2 == pytest.approx(ARM.joint_accel_deg_s2, rel=0.02)
    assert fit.rms_s < 1e-3
    assert fit.cruise_reached > 0


def test_fit_refuses_too_little_data():
    with pytest.raises(ValueError, match="at least 3"):
        fit_arm_timing([TimedMove((1.0,), 100.0, 0.3)])
    with pytest.raises(ValueError, match="move a joint"):
        fit_arm_timing([TimedMove((0.0,), 100.0, 0.3)] * 3)


def test_config_is_strict_with_full_key_paths():
    cfg = from_mapping(TimingConfig, {"val_baud": 19200, "arm": {"t0_s": 0.2}}, "timing")
    assert cfg.val_baud == 19200 and cfg.arm.t0_s == 0.2
    with pytest.raises(ConfigError, match=r"timing\.arm\.joint_speed_deg_s"):
        from_mapping(TimingConfig, {"arm": {"joint_speed_deg_s": 0}}, "timing")
    with pytest.raises(ConfigError, match=r"timing\.camera"):
        from_mapping(TimingConfig, {"camera": {"bogus": 1}}, "timing")
    with pytest.raises(ConfigError, match="exposure_s"):
        from_mapping(TimingConfig, {"camera": {"frame_rate_hz": 100, "exposure_s": 0.02}},
                     "timing")
