"""A scripted estimator for loop tests: reads the true corrective step off a FakeArm."""

from __future__ import annotations

import math

from controller.systems.estimator import RotationEstimate, TranslationEstimate
from drivers.core.pose import Pose, wrap_deg
from tests.mocks.fakes import FakeArm

NOMINAL = Pose(300.0, 0.0, 150.0, -90.0, 90.0, 0.0)


class TruthEstimator:
    """Sees the exact step back to NOMINAL, scaled by ``gain`` (gain < 1: a cautious net)."""

    name = "truth"
    heading_zero = None

    def __init__(self, arm: FakeArm, gain: float = 1.0, kappa: int = 4,
                 status: str = "ok") -> None:
        self.arm, self.gain, self.kappa, self.status = arm, gain, kappa, status
        self.rotation_calls = 0

    def _step(self):
        return self.arm._pose.tool_step_to(NOMINAL)

    def estimate_translation(self, image):
        if self.status != "ok":
            return TranslationEstimate(self.status, reason=f"scripted {self.status}")
        s = self._step()
        return TranslationEstimate("ok", s.dx_mm * self.gain, s.dy_mm * self.gain, 96.0, 72.0,
                                   record={"nn1": [s.dx_mm, s.dy_mm]})

    def estimate_rotation(self, translation):
        self.rotation_calls += 1
        dphi = wrap_deg(self._step().dphi_deg, 360.0 / self.kappa) * self.gain
        return RotationEstimate(dphi, record={"nn2": [math.sin(4 * dphi), math.cos(4 * dphi)]})


def truth_error(arm: FakeArm):
    s = NOMINAL.tool_step_to(arm._pose)
    return (s.dx_mm, s.dy_mm, wrap_deg(s.dphi_deg, 90.0))
