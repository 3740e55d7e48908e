"""The zero by the tool's heading: the step the loop reads at the taught pose, part and tool
turned together to each of several headings under the cell's own light: NN2's turn and the
translation.

A lamp fixed in the cell lights the part from another side as the part's heading changes, and
the tool, aligned with the part, sees it so: the faces lit, the shading of the rounded edges
and the cast shadow turn with the heading, and the turn NN2 reads at the taught pose turns
with them (under the poor preset's low side lamp the cube's reading wanders by +-0.35 deg over
its quarter turn, with a step where its front face turns into the light). A zero taken at one
heading (``calibration_free.rezero``) removes the offset there and leaves the rest.
``FinePositioner.rezero`` with a heading step has the arm take the part in its jaws at the
taught pose, turn it and set it down at each heading of a range, go back up to the taught
pose over it and read the step there as the loop reads it (NN2's turn, or a long part's axis
map's where it takes over near the pose): that reading is the zero at that tool heading
(``controller.calibration.heading_zero``). The positioning loop takes the table's value at the
tool's heading off every full look's step.

The translation nets' reading moves with the heading too (0.04 mm RMS for the cube, up to
0.9 mm for the screw where the lamp stands behind its head), but a set-down leaves the part
0.01-0.02 mm off where the jaws took it, along the jaws (the screw: up to 0.06 mm), and over a
range's set-downs that adds up to as much as the reading moves. Where the part has two pairs of
faces at right angles (kappa a multiple of 4: the cube) the jaws close on it once more turned
by a quarter turn after each set-down, which centres it along the jaws as well, and the table
keeps the translation read at each heading against the plain zero (``dx_mm``, ``dy_mm``); the
other parts the arm turns back to the taught heading after each heading and looks there too,
and each heading's reading is kept less the mean of the looks there either side of it
(``controller.calibration.heading_zero``). Tables written before keep the turn only for those.

Headings are the tool's turn about the vertical in the world (``Pose.approach_rotation_deg``),
as the arm reports it; the table holds them unwrapped (increasing, less than a turn apart). At a
heading between two of them the zero is interpolated linearly; up to one step beyond either
end the nearer end's holds; further out nothing is known and nothing is taken off.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibration_free.errors import BundleError

MAX_ROWS = 720
# a zero further off than this is no lamp's offset but a misreading (the part not where it
# was set down): refused when the table is made or loaded. The screw under the poor preset's
# lamp, standing behind its head, reads 0.9 mm along its shank (its cast shadow round it).
MAX_OFFSET_DEG = 5.0
MAX_OFFSET_MM = 1.5


@dataclass(frozen=True)
class HeadingZero:
    """headings_deg: the tool headings read at, increasing, spanning less than 360 deg;
    dphi_deg: per heading, the turn the loop's full look read there (deg); dx_mm, dy_mm: per
    heading, the translation it read there less the taught heading's (mm, tool frame), or
    None where the translation was not read."""

    headings_deg: tuple[float, ...]
    dphi_deg: tuple[float, ...]
    dx_mm: tuple[float, ...] | None = None
    dy_mm: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if (self.dx_mm is None) != (self.dy_mm is None):
            raise BundleError("heading_zero: dx_mm and dy_mm go together")
        try:
            headings = tuple(float(h) for h in self.headings_deg)
            dphi = tuple(float(v) for v in self.dphi_deg)
            shift = None if self.dx_mm is None else \
                (tuple(float(v) for v in self.dx_mm), tuple(float(v) for v in self.dy_mm))
        except (TypeError, ValueError) as exc:
            raise BundleError(f"heading_zero: not numbers ({exc})") from None
        if not 2 <= len(headings) <= MAX_ROWS:
            raise BundleError(f"heading_zero: needs 2 to {MAX_ROWS} headings, got "
                              f"{len(headings)}")
        if len(dphi) != len(headings):
            raise BundleError(f"heading_zero: needs one turn per heading, got {len(dphi)} for "
                              f"{len(headings)}")
        if not all(math.isfinite(v) for v in (*headings, *dphi)):
            raise BundleError("heading_zero: headings and turns must be finite numbers")
        if any(b <= a for a, b in zip(headings, headings[1:], strict=False)) \
                or headings[-1] - headings[0] >= 360.0:
            raise BundleError("heading_zero: headings must increase and span less than 360 "
                              f"deg, got {headings[0]:g}..{headings[-1]:g}")
        for h, v in zip(headings, dphi, strict=True):
            if abs(v) > MAX_OFFSET_DEG:
                raise BundleError(f"heading_zero: at {h:g} deg NN2 read {v:.2f} deg: beyond "
                                  f"{MAX_OFFSET_DEG:g} deg, not a light's offset")
        if shift is not None:
            if any(len(axis) != len(headings) for axis in shift):
                raise BundleError(f"heading_zero: needs one translation per heading, got "
                                  f"{len(shift[0])} and {len(shift[1])} for {len(headings)}")
            for h, dx, dy in zip(headings, *shift, strict=True):
                if not (math.isfinite(dx) and math.isfinite(dy)) \
                        or math.hypot(dx, dy) > MAX_OFFSET_MM:
                    raise BundleError(f"heading_zero: at {h:g} deg the translation read "
                                      f"({dx:.3g}, {dy:.3g}) mm: not finite or beyond "
                                      f"{MAX_OFFSET_MM:g} mm, not a light's offset")
            object.__setattr__(self, "dx_mm", shift[0])
            object.__setattr__(self, "dy_mm", shift[1])
        object.__setattr__(self, "headings_deg", headings)
        object.__setattr__(self, "dphi_deg", dphi)

    @classmethod
    def from_readings(cls, readings: Sequence[Sequence[float]]) -> HeadingZero:
        """From rows of (tool heading deg, turn read deg) or, with the translation, (tool
        heading deg, turn deg, dx mm, dy mm), in any order; each heading is taken within half
        a turn of the first (unwrapped), and the rows sorted by it."""
        if not readings:
            raise BundleError("heading_zero: no readings")
        widths = {len(row) for row in readings}
        if widths not in ({2}, {4}):
            raise BundleError("heading_zero: readings are (heading, turn) or (heading, turn, "
                              "dx, dy), all alike")
        first = float(readings[0][0])
        rows = sorted((first + (float(row[0]) - first + 180.0) % 360.0 - 180.0,
                       *(float(v) for v in row[1:])) for row in readings)
        columns = list(zip(*rows, strict=True))
        return cls(*columns)

    @property
    def step_deg(self) -> float:
        """The widest gap between two neighbouring headings."""
        h = self.headings_deg
        return max(b - a for a, b in zip(h, h[1:], strict=False))

    @property
    def has_translation(self) -> bool:
        return self.dx_mm is not None

    def _within(self, heading_deg: float) -> float | None:
        """The heading as the table's unwrapped headings hold it; None beyond the table's
        ends by more than its step (not read there)."""
        if not math.isfinite(heading_deg):
            return None
        h = self.headings_deg
        mid = 0.5 * (h[0] + h[-1])
        x = mid + (heading_deg - mid + 180.0) % 360.0 - 180.0  # the turn nearest the table
        if x < h[0] - self.step_deg or x > h[-1] + self.step_deg:
            return None
        return x

    def at(self, heading_deg: float) -> float | None:
        """The zero of the turn (deg) at a tool heading; None beyond the table's ends by more
        than its step (not read there)."""
        x = self._within(heading_deg)
        return None if x is None else float(np.interp(x, self.headings_deg, self.dphi_deg))

    def shift_at(self, heading_deg: float) -> tuple[float, float] | None:
        """The zero of the translation (dx, dy mm, tool frame) at a tool heading; None where
        the translation was not read, or beyond the table's ends by more than its step."""
        x = self._within(heading_deg)
        if x is None or self.dx_mm is None:
            return None
        return (float(np.interp(x, self.headings_deg, self.dx_mm)),
                float(np.interp(x, self.headings_deg, self.dy_mm)))

    def to_info(self) -> dict:
        """JSON for the model file."""
        info = {"headings_deg": list(self.headings_deg), "dphi_deg": list(self.dphi_deg)}
        if self.dx_mm is not None:
            info.update(dx_mm=list(self.dx_mm), dy_mm=list(self.dy_mm))
        return info

    @classmethod
    def from_info(cls, info) -> HeadingZero:
        """From ``to_info``'s JSON; BundleError (one line) where it is not that."""
        if not isinstance(info, dict) or not isinstance(info.get("headings_deg"), list) \
                or not isinstance(info.get("dphi_deg"), list) \
                or any(info.get(k) is not None and not isinstance(info[k], list)
                       for k in ("dx_mm", "dy_mm")):
            raise BundleError("heading_zero: expected {headings_deg: [...], dphi_deg: [...]} "
                              "and optionally dx_mm: [...], dy_mm: [...]")
        shift = [None if info.get(k) is None else tuple(info[k]) for k in ("dx_mm", "dy_mm")]
        return cls(tuple(info["headings_deg"]), tuple(info["dphi_deg"]), *shift)
