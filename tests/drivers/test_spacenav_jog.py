"""The jog mapping: deadband, scaling, axis mapping and signs, integration over event periods."""

from __future__ import annotations

import pytest

from drivers.core.errors import ConfigError
from drivers.core.pose import ToolStep
from drivers.core.typed_config import from_mapping
from drivers.spacenav import JogConfig, JogIntegrator, MotionEvent, tool_rate
from drivers.spacenav.jog import ToolRate, shaped

CFG = JogConfig(deadband=10, full_scale=110, max_speed_mm_s=10.0, max_speed_deg_s=20.0,
                max_period_ms=200)


def motion(x=0, y=0, z=0, rx=0, ry=0, rz=0, period_ms=0) -> MotionEvent:
    return MotionEvent(x, y, z, rx, ry, rz, period_ms)


def approx_step(step: ToolStep, **expected) -> bool:
    want = ToolStep(**expected)
    return all(getattr(step, k) == pytest.approx(v, abs=1e-9) for k, v in want.as_dict().items())


@pytest.mark.parametrize("value, expected", [
    (0, 0.0), (10, 0.0), (-10, 0.0), (60, 0.5), (-60, -0.5), (110, 1.0), (500, 1.0),
    (-500, -1.0)])
def test_deadband_and_full_scale(value, expected):
    assert shaped(value, CFG) == pytest.approx(expected)


def test_default_mapping_and_signs():
    # cap right -> tool +x; pulled towards the user (-z) -> tool +y; pushed down (-y) ->
    # towards the object (+dz); twisted clockwise seen from above (-ry) -> +dphi.
    rate = tool_rate(motion(x=110, z=-110, y=-110, ry=-110), CFG)
    assert rate == ToolRate(10.0, 10.0, 10.0, 20.0)
    assert tool_rate(motion(rx=300, rz=300), CFG).is_zero, "tilts are not mapped by default"


def test_configured_mapping():
    cfg = JogConfig(deadband=0, full_scale=100, dx_mm="-y", dy_mm="none", dz_mm="z",
                    dphi_deg="rz")
    assert tool_rate(motion(x=50, y=50, z=100, rz=-100), cfg) == ToolRate(-5.0, 0.0, 10.0, -10.0)


def test_integrator_applies_the_previous_deflection_over_the_period():
    jog = JogIntegrator(CFG)
    assert approx_step(jog.on_motion(motion(x=110, period_ms=0)))  # nothing held before
    assert jog.moving
    # the x deflection was held 100 ms: 10 mm/s * 0.1 s
    assert approx_step(jog.on_motion(motion(x=60, period_ms=100)), dx_mm=1.0)
    assert approx_step(jog.on_motion(motion(period_ms=50)), dx_mm=0.25)
    assert not jog.moving
    assert approx_step(jog.on_motion(motion(x=110, period_ms=5000)))  # rest was held


def test_periods_are_clamped():
    jog = JogIntegrator(CFG)
    jog.on_motion(motion(x=110))
    assert approx_step(jog.on_motion(motion(period_ms=3000)), dx_mm=2.0)  # 200 ms at most


def test_hold_keeps_moving_without_counting_time_twice():
    jog = JogIntegrator(CFG)
    jog.on_motion(motion(y=-110))  # towards the object at 10 mm/s
    assert approx_step(jog.hold(0.1), dz_mm=1.0)
    assert approx_step(jog.hold(0.1), dz_mm=1.0)
    assert approx_step(jog.hold(1.0), dz_mm=2.0), "one hold interval is clamped too"
    # the event closing this deflection came 450 ms after it began; 400 ms were applied
    assert approx_step(jog.on_motion(motion(period_ms=450)), dz_mm=0.5)
    assert approx_step(jog.on_motion(motion(period_ms=300)))


def test_stop_forgets_the_deflection():
    jog = JogIntegrator(CFG)
    jog.on_motion(motion(x=110))
    jog.stop()
    assert not jog.moving and approx_step(jog.on_motion(motion(period_ms=100)))


def test_config_loads_strictly():
    path = "controller.teach.jog"
    cfg = from_mapping(JogConfig, {"deadband": 5, "dphi_deg": "rz"}, path)
    assert cfg.deadband == 5 and cfg.dphi_deg == "rz" and cfg.dx_mm == "x"
    with pytest.raises(ConfigError, match=r"^controller\.teach\.jog\.dead_band: unknown key"):
        from_mapping(JogConfig, {"dead_band": 5}, path)
    with pytest.raises(ConfigError, match=r"^controller\.teach\.jog: dx_mm: 'q' is not an axis"):
        from_mapping(JogConfig, {"dx_mm": "q"}, path)
    with pytest.raises(ConfigError, match="must exceed deadband"):
        from_mapping(JogConfig, {"deadband": 400}, path)
