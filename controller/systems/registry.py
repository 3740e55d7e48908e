"""The vision systems the positioning loop can run, in one explicit registry."""

from __future__ import annotations

from controller.systems.align import AlignSystem
from controller.systems.base import VisionSystem
from controller.systems.gabor import GaborSystem
from controller.systems.hough import HoughSystem
from controller.systems.pca import PcaSystem

# The system the commands run unless told otherwise: finepos' own.
DEFAULT_SYSTEM = "gabor"

SYSTEMS: dict[str, type[VisionSystem]] = {
    "gabor": GaborSystem,
    "pca": PcaSystem,
    "hough": HoughSystem,
    "align": AlignSystem,
}
