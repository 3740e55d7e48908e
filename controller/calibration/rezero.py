"""Re-zero a part's model at the taught pose in the cell's light (``rezero``).

The system says whether it re-zeroes and whether it keeps a zero by heading
(``VisionSystem.rezeroes``, ``zero_by_heading``); the zero by heading is read by
``controller.calibration.heading_zero``.
"""

from __future__ import annotations

import dataclasses
import logging

from controller.calibration.heading_zero import default_range, headings, read_heading_zero
from controller.systems.base import TrainedModel
from controller.systems.registry import SYSTEMS
from drivers.core.errors import FineposError

logger = logging.getLogger(__name__)

# The systems ``rezero`` moves the zero of, and those that also keep a zero by heading.
REZERO_SYSTEMS = tuple(name for name, system in SYSTEMS.items() if system.rezeroes)
HEADING_ZERO_SYSTEMS = tuple(name for name, system in SYSTEMS.items()
                             if system.zero_by_heading)
# Frames ``rezero`` takes at the taught pose (training pinned the nets on 4 + 4): read three
# at a time, eight means; fewer leave more of the dark frame's noise in the zero
# (docs/decisions/0011-rezero-in-the-cells-light.md). 0.8 s at 30 frames a second. Where the
# loop's settling look reads more frames at a time in that light (``LoopConfig.settle_count``)
# it takes more, so that two whole such means fit.
REZERO_FRAMES = 24


def rezero(fp, frames: int, system: str, heading_step_deg: float | None = None,
           heading_range_deg: tuple[float, float] | None = None
           ) -> tuple[TrainedModel, dict]:
    """Re-zero the part's model of ``system`` in the cell's light: move to the taught
    pose, take ``frames`` frames (more where the means below need them: at least two, all
    whole), move the model's zero there (Gabor: shift the translation nets,
    ``calibration_free.rezero``, read on the frames' means as the loop's settling look
    reads where ``settle_average`` is ``frames``: as many at a time as it reads where
    single frames scatter as these do, ``LoopConfig.settle_count``; the image-alignment
    servo: take its template again, ``calibration_free.baselines.align.rezero``), store
    the model (atomically). The part must lie where it was taught.

    With ``heading_step_deg`` (a system with ``zero_by_heading``: Gabor) the full look's
    step is then also read with the part turned to each heading of ``heading_range_deg`` (the
    part's turn from its taught heading; default ``heading_zero.default_range``: one symmetry
    period centred on it) in steps of at most that (``controller.calibration.heading_zero``:
    the arm turns the part itself, and centres the cube between its jaws; the other parts it
    reads between looks back at the taught heading), and the model keeps it as its zero by
    heading: NN2's turn and the translation. The loop takes it off each full look's step. A
    re-zero without it drops the model's zero by heading.

    Returns:
        The model and what moved (the report's ``shift_mm``: each Gabor net's reading
        before, mm; ``read_mm`` / ``read_deg``: the servo's; ``frame_scatter``: how far
        single frames' steps scatter there, standard deviations mm, mm, deg, Gabor;
        ``average``: the frames a mean is read on; ``heading_zero``: the zero by heading,
        or null).

    Raises:
        FineposError: no model of ``system`` stored, a system that does not re-zero,
            ``frames`` below 1, or a heading step for the servo.
        TrainingError: the part is not seen whole there, or not where it was taught, or a
            grasp to turn it failed (the model file is left as it was).
    """
    if isinstance(frames, bool) or not isinstance(frames, int) or frames < 1:
        raise FineposError(f"rezero: frames must be a whole number >= 1, got {frames!r}")
    impl = SYSTEMS[system]
    if not impl.rezeroes:
        raise FineposError(f"rezero: the {system} system does not re-zero (only "
                           f"{' and '.join(REZERO_SYSTEMS)})")
    if heading_step_deg is not None and not impl.zero_by_heading:
        raise FineposError(f"rezero: a zero by heading is the "
                           f"{' and '.join(HEADING_ZERO_SYSTEMS)} system's; the {system} "
                           "system keeps one zero")
    model = fp.load_model(system=system)
    if heading_step_deg is not None:  # refused before the arm moves
        turns = headings(heading_step_deg, heading_range_deg
                         or default_range(model.model.kappa, heading_step_deg))
    fp.move_to(fp.state().nominal_pose)
    images = [fp.devices.camera.grab().image for _ in range(frames)]
    done = impl.rezero(model, images, fp.loop_config(model),
                       lambda: fp.devices.camera.grab().image)
    moved, report = done.model, done.report
    if heading_step_deg is not None:
        estimator = impl.estimator(dataclasses.replace(model, model=moved))
        table = read_heading_zero(fp, estimator, turns, done.frames, done.average)
        moved = impl.with_heading_zero(moved, table)
        report["heading_zero"] = table.to_info()
    model = dataclasses.replace(model, model=moved)
    impl.save(model, fp.model_path(system))
    logger.info("re-zeroed %s: %s", fp.model_path(system), report)
    return model, report
