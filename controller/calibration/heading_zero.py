"""Reading the zero by heading on the cell (``calibration_free.heading_zero``).

From the taught pose, with the part where it was taught: for each heading of the range the
arm grasps the part (``controller.loop.grasp``, the guards and checks of every grasp), turns
it about the approach axis while it is lifted, sets it down where it was, lets go and goes
back up to the taught pose turned with it, so that the tool stands over the part as at the
taught pose; the camera sees the part as taught, lit from another side. There NN2 is read as
the loop reads it (the full look's turn, on the means of ``average`` frames): that reading is
the zero at the tool's heading. At the end the part is turned back to its taught heading and
the arm stands at the taught pose, as before.

Every set-down leaves the part a little off where the jaws took it: the arm's repeatability,
and the part settling as the jaws let go (on the simulated cell 0.01-0.02 mm, mostly along
the jaws, and a few thousandths of a degree a set-down). NN2 is read at the taught heading
before the first grasp and again once the part is back there: the difference, shared out over
the set-downs, is taken off each heading's reading in proportion to the set-downs before it,
as a surveyor closes a traverse.

The translation's shifts would add up the same way, to as much as the lamp moves the
translation nets' reading. For a part with two pairs of faces at right angles (kappa a
multiple of 4: the cube) the arm centres it instead: after each set-down it goes back down
turned by a quarter turn and closes the jaws on the other pair of faces (the grasp's descent
and guards, no lift), which pushes the part to the middle along the jaws of the set-down, as
the set-down's grasp did across them; it does the same at the taught heading before the first
reading and after the last (those two are logged: what the centring moved the part by). What
each heading reads, against the plain re-zero's zero (the part where it was taught), is its
zero of the translation. The part then lies where the arm's repeatability puts it (on the
simulated cell within 0.01-0.03 mm of the jaws' middle), whatever the set-downs before; each
centring scatters by that much, so a reference taken from the two centrings at the taught
heading would put their common error into every heading's zero
(docs/decisions/0012-rezero-by-heading.md).

The other parts (the nut, the ledge, the screw) the jaws centre across themselves only, and
their set-downs do not slide them evenly (the screw: none at most, 0.06 mm along its shank
at some): shared out evenly, the slides left up to 0.23 mm in the screw's table in good light.
So after each heading the arm turns the part back to the taught heading and looks there too:
that look says how far the set-downs have moved the part (and turned it), and each heading's
reading is taken less the mean of the looks at the taught heading either side of it. What is
left is half the difference of the set-down there and the one back, and the looks' own
scatter. The translation is read against the plain zero, not against the first of those
looks: a look's reading moves with the camera's gain from one look to the next, and the
first look's would be in every heading's zero (the screw in poor light: 0.07 mm). The turn,
which the set-downs move by a few thousandths of a degree, is closed out evenly as the cube's:
read between the looks it took on their scatter (the nut's angle in poor light 1.20 -> 1.49
deg).

Each heading costs a grasp, a turn, a set-down and a look: about 9 cell seconds with the
realistic timing; centring the cube adds two turns, a guarded descent and a closing, about 10
more (the cube in 5 deg steps: 6.2 min, 2.9 min without the centring); turning the other
parts back doubles their cost (the screw in 15 deg steps: 24 headings, 48 set-downs).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence

import numpy as np

from calibration_free.errors import TrainingError
from calibration_free.heading_zero import HeadingZero
from calibration_free.preprocess import frame_means
from controller.loop.grasp import guarded_grasp
from controller.systems.estimator import full_step
from drivers.core.pose import Pose, ToolStep, wrap_deg
from drivers.safety import split_step

logger = logging.getLogger(__name__)

MAX_HEADINGS = 360


def centres(kappa: int) -> bool:
    """Whether the arm can centre the part by closing the jaws on it turned by a quarter
    turn (two pairs of faces at right angles); the others are read between looks at the
    taught heading (module docstring)."""
    return kappa % 4 == 0


def default_range(kappa: int, step_deg: float) -> tuple[float, float]:
    """One symmetry period centred on the taught heading; for a part without symmetry (one
    period is the whole turn) the turn less one step, so that no heading is read twice."""
    period = 360.0 / kappa
    if kappa > 1:
        return -period / 2.0, period / 2.0
    return -180.0, 180.0 - min(step_deg, 180.0)


def headings(step_deg: float, range_deg: tuple[float, float]) -> list[float]:
    """The heading changes (deg, the part's turn in the world) from ``range_deg[0]`` to
    ``range_deg[1]`` in steps of at most ``step_deg``, both ends included.

    Raises:
        TrainingError: a step that is not positive, a range that is empty, reversed or a whole
            turn or more, or more than MAX_HEADINGS headings.
    """
    lo, hi = (float(v) for v in range_deg)
    if not (math.isfinite(step_deg) and step_deg > 0.0):
        raise TrainingError(f"rezero: the heading step must be > 0 deg, got {step_deg!r}")
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi and hi - lo < 360.0):
        raise TrainingError(f"rezero: the heading range must run from a lower to a higher "
                            f"heading less than a turn apart, got {lo:g}..{hi:g} deg")
    n = math.ceil((hi - lo) / step_deg - 1e-9)
    if n + 1 > MAX_HEADINGS:
        raise TrainingError(f"rezero: {n + 1} headings of {step_deg:g} deg over {lo:g}.."
                            f"{hi:g} deg; at most {MAX_HEADINGS}")
    return [lo + (hi - lo) * i / n for i in range(n + 1)]


def _turn_sign(taught: Pose) -> float:
    """+1 where a positive tool turn (about the approach axis) turns the tool's heading the
    positive way in the world, -1 where it turns it the other way (the approach axis points
    down)."""
    turned = taught.moved_in_tool_frame(ToolStep(dphi_deg=10.0))
    return 1.0 if wrap_deg(turned.approach_rotation_deg - taught.approach_rotation_deg,
                           360.0) > 0 else -1.0


def read_heading_zero(fp, estimator, turns: Sequence[float], frames: int,
                      average: int) -> HeadingZero:
    """The zero by heading at ``turns`` (the part's turns from its taught heading, deg, in
    order: ``headings``; see the module docstring): the turn and the translation, the part
    centred where it can be (``centres``); ``fp``: the ``FinePositioner``, its arm at the taught
    pose and the part where it was taught; ``estimator``: the re-zeroed model's, without a
    zero by heading.

    Raises:
        TrainingError: a grasp that fails (the arm has backed off to where it started it; the
            part may lie turned), or the part not seen at a heading.
        FineposError: the arm or another device failed.
    """
    cell = _Turner(fp, estimator, frames, average)
    if centres(cell.kappa):
        return _centred(cell, turns)
    return _bracketed(cell, turns)


class _Turner:
    """The arm's side of a re-zero by heading: it turns the part on the table by grasping,
    turning and setting it down (``set_down_at``, counted in ``set_downs``), centres a part
    with faces at right angles between the jaws (``centre``) and reads the full look's step
    over the part (``read``)."""

    def __init__(self, fp, estimator, frames: int, average: int):
        self.fp, self.estimator, self.frames, self.average = fp, estimator, frames, average
        state = fp.state()
        self.arm, self.grasp_cfg = fp.devices.arm, fp.config.controller.grasp
        self.state, self.taught = state, state.nominal_pose
        self.sign = _turn_sign(self.taught)
        part = fp.config.parts.part(state.object_kind)
        self.kappa, self.weight_n = state.kappa, part.weight_n
        self.current = 0.0  # the part's turn from its taught heading
        self.set_downs = 0

    def over(self, turn: float) -> Pose:
        """The taught pose turned with the part turned by ``turn``."""
        return self.taught.moved_in_tool_frame(ToolStep(dphi_deg=self.sign * turn))

    def heading(self) -> float:
        """The tool's heading (deg)."""
        return self.arm.pose().approach_rotation_deg

    def read(self, turn: float) -> ToolStep:
        """The step the full look reads here, the part turned by ``turn``."""
        return _step_read(self.fp, self.estimator, self.frames, self.average, turn)

    def _grasp(self, what: str, lift: bool = True) -> None:
        result = guarded_grasp(self.arm, self.fp.devices.wrench, self.state.grasp_depth_mm,
                               self.state.object_width_mm, self.grasp_cfg, self.weight_n,
                               lift=lift)
        if not result.success:
            raise TrainingError(f"rezero: the grasp {what} failed ({result.reason})")

    def set_down_at(self, turn: float) -> bool:
        """Turn the part to ``turn`` from its taught heading and stand over it; False (no
        motion) where it lies turned so already."""
        if turn == self.current:
            return False
        self._grasp(f"to turn the part to {turn:g} deg")
        # turned in moves within the safety layer's limit (``safety.max_step_deg``)
        total = self.sign * (turn - self.current)
        for piece in split_step(ToolStep(dphi_deg=total), self.fp.config.safety):
            self.arm.move_tool(piece)
        self.arm.move_tool(ToolStep(dz_mm=self.grasp_cfg.lift_mm))
        self.arm.open_gripper()
        self.current = turn
        self.set_downs += 1
        logger.info("rezero: set-down %d, the part turned %g deg from its taught heading",
                    self.set_downs, turn)
        self.fp.move_to(self.over(turn))
        return True

    def centre(self, turn: float) -> None:
        """Close the jaws on the part's other pair of faces (the tool a quarter turn on) and
        back to over it at ``turn``."""
        across = self.over(turn).moved_in_tool_frame(ToolStep(dphi_deg=90.0))
        self.fp.move_to(across)
        self._grasp(f"to centre the part at {turn:g} deg", lift=False)
        self.arm.open_gripper()
        self.fp.move_to(across)
        self.fp.move_to(self.over(turn))


def _centred(cell: _Turner, turns: Sequence[float]) -> HeadingZero:
    """The zero by heading of a part the jaws centre (the cube, module docstring): each
    heading's translation as read, against the plain zero (the part centred, as taught)."""
    cell.centre(0.0)
    before = cell.read(0.0)  # centred where it was taught
    readings = []  # (heading, turn read, dx, dy, set-downs before the reading)
    for turn in turns:
        if cell.set_down_at(turn):
            cell.centre(turn)
        read = cell.read(turn)
        readings.append((cell.heading(), read.dphi_deg, read.dx_mm, read.dy_mm,
                         cell.set_downs))
    if cell.set_down_at(0.0):
        cell.centre(0.0)
    after = cell.read(0.0)
    logger.info("rezero: centred at the taught heading the translation read (%.3f, %.3f)"
                " mm before and (%.3f, %.3f) mm after", before.dx_mm, before.dy_mm,
                after.dx_mm, after.dy_mm)
    return _closed(readings, before, after, cell.set_downs)


def _bracketed(cell: _Turner, turns: Sequence[float]) -> HeadingZero:
    """The zero by heading of a part the jaws cannot centre (module docstring): back to the
    taught heading after each heading, where the reading says how far the set-downs have
    moved the part along the jaws; each heading's translation less the mean of the two
    taken there either side of it, the first of them before the first set-down (against the
    plain zero: the part as taught reads nothing there). The turn, which the set-downs move
    little, has its drift closed out evenly between the first and the last look, as the
    cube's: the looks' own scatter in NN2's reading is larger (the nut in poor light: 1.49
    deg with each heading's turn read between them, 1.20 closed out evenly)."""
    before = cell.read(0.0)
    readings = []  # (heading, turn read, dx, dy, set-downs before the reading)
    back = before  # the reading at the taught heading before this heading's set-down
    for turn in turns:
        cell.set_down_at(turn)
        heading, read, count = cell.heading(), cell.read(turn), cell.set_downs
        after = cell.read(0.0) if cell.set_down_at(0.0) else read
        # where the set-downs have left the part, against the plain zero
        dx, dy = 0.5 * (back.dx_mm + after.dx_mm), 0.5 * (back.dy_mm + after.dy_mm)
        readings.append((heading, read.dphi_deg, read.dx_mm - dx, read.dy_mm - dy, count))
        back = after
    logger.info("rezero: at the taught heading the part read %.3f deg, (%.3f, %.3f) mm before "
                "the first set-down and %.3f deg, (%.3f, %.3f) mm after the last",
                before.dphi_deg, before.dx_mm, before.dy_mm, back.dphi_deg, back.dx_mm,
                back.dy_mm)
    return _closed(readings, before, back, cell.set_downs)


def _closed(readings, before: ToolStep, after: ToolStep, set_downs: int) -> HeadingZero:
    """The table from ``readings`` ((heading, turn read, dx, dy, set-downs before the
    reading)), each turn less its set-downs' share of the turn's drift between the looks at
    the taught heading ``before`` the first set-down and ``after`` the last, shared out
    evenly over the ``set_downs``, as a surveyor closes a traverse."""
    drift = (after.dphi_deg - before.dphi_deg) / max(set_downs, 1)  # a set-down's
    logger.info("rezero: %d set-downs turned the part by %.3f deg each", set_downs, drift)
    rows = [(heading, dphi - count * drift, dx, dy)
            for heading, dphi, dx, dy, count in readings]
    for row in rows:
        logger.info("rezero: at heading %.1f deg the taught pose reads %s", row[0],
                    ", ".join(f"{v:.3f}" for v in row[1:]))
    return HeadingZero.from_readings(rows)


def _step_read(fp, estimator, frames: int, average: int, turn: float) -> ToolStep:
    """The step the loop's full look reads at the arm's pose (mm, deg), the part turned by
    ``turn`` from its taught heading: on the means of ``average`` frames, averaged over
    ``frames`` frames."""
    grabbed = [fp.devices.camera.grab().image for _ in range(frames)]
    means = frame_means(grabbed, average)
    steps = [step for step in (full_step(estimator, image) for image in means)
             if step is not None]
    if 2 * len(steps) < len(means):
        raise TrainingError(f"rezero: the part is not seen at the taught pose turned by "
                            f"{turn:g} deg")
    return ToolStep(float(np.mean([s.dx_mm for s in steps])),
                    float(np.mean([s.dy_mm for s in steps])), 0.0,
                    float(np.mean([s.dphi_deg for s in steps])))
