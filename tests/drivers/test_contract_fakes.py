"""The contract checker holds for the fake devices (and so can be trusted on the real ones)."""

from drivers.contract import check_arm, check_camera, check_wrench
from drivers.safety import SafetyLimits
from tests.mocks.fakes import FakeArm, FakeCamera, FakeWrenchSensor


def test_fake_arm_meets_contract():
    check_arm(lambda: FakeArm(SafetyLimits(max_step_mm=20.0, max_step_deg=30.0)))


def test_fake_camera_meets_contract():
    check_camera(FakeCamera)


def test_fake_wrench_meets_contract():
    check_wrench(FakeWrenchSensor)
