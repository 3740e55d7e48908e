"""What a look's overlay shows, taken from the percept the loop already has, and how it is drawn.

``overlay_of`` reads the estimate of one look (no second pass on the frame): the part's centre
and an area-equivalent box of its blob, the ROI square and the Gabor filter centres around it
(the bundle's ``gabor`` config), the taught centre (``front.nominal_uv_px``) and the commanded
step. Systems without a Gabor bundle get the centre, box and step only.

Image coordinates here are the iteration log's: pixel-centre coordinates (pixel column j covers
u in [j - 0.5, j + 0.5]). Foxglove's annotations use edge coordinates (the top-left pixel covers
[0, 1]); ``to_annotations`` adds the half pixel.

The step arrow shows where the commanded step is expected to move the part in the image: along
the line from the part to the taught centre (where the part lies once the pose is reached),
scaled by the commanded step's share of the translation estimate. A calibration-free system
has no other mm-to-pixel map.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import cv2
import numpy as np
from foxglove.messages import (
    CircleAnnotation,
    Color,
    ImageAnnotations,
    Point2,
    PointsAnnotation,
    PointsAnnotationType,
    TextAnnotation,
    Timestamp,
)

from controller.loop.record import IterationRecord
from controller.systems.estimator import TranslationEstimate

Point = tuple[float, float]

# Colours (RGB, 0..1) shared by the Foxglove annotations and the replay's drawing.
COLOURS = {"centre": (1.0, 0.2, 0.2), "box": (1.0, 0.85, 0.0), "roi": (0.2, 0.8, 1.0),
           "gabor": (0.2, 1.0, 0.4), "taught": (1.0, 1.0, 1.0), "step": (1.0, 0.4, 1.0)}


@dataclass(frozen=True)
class Overlay:
    """The geometry drawn over one look's frame (pixel-centre coordinates, px).

    Attributes:
        centre_px: the part's centre (None when it was not found).
        box_px: (u0, v0, u1, v1), the square of the blob's area around the centre.
        roi_px: the side of the Gabor ROI square centred on the part (None without one).
        gabor_px: the Gabor filter centres in the image (3x3 with the default bank).
        taught_px: where the part appeared at the taught pose (None when unknown).
        arrow_px: (start, end) of the commanded step's expected image motion (None without
            a step).
    """

    centre_px: Point | None = None
    box_px: tuple[float, float, float, float] | None = None
    roi_px: float | None = None
    gabor_px: tuple[Point, ...] = ()
    taught_px: Point | None = None
    arrow_px: tuple[Point, Point] | None = None

    def as_dict(self) -> dict[str, Any]:
        """A JSON-able dict (tuples as lists)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Overlay:
        """The inverse of ``as_dict``."""
        def point(p):
            return None if p is None else (float(p[0]), float(p[1]))
        arrow = data.get("arrow_px")
        box = data.get("box_px")
        return cls(point(data.get("centre_px")),
                   tuple(float(v) for v in box) if box is not None else None,
                   data.get("roi_px"), tuple(point(p) for p in data.get("gabor_px") or ()),
                   point(data.get("taught_px")),
                   (point(arrow[0]), point(arrow[1])) if arrow is not None else None)


def _finite(*values) -> bool:
    return all(v is not None and math.isfinite(v) for v in values)


def _bundle_of(estimator: Any) -> Any:
    """The trained bundle behind an estimator that has one (the Gabor system), else None."""
    perception = getattr(estimator, "perception", None)
    return getattr(perception, "bundle", None)


def overlay_of(record: IterationRecord, estimate: TranslationEstimate,
               estimator: Any = None) -> Overlay:
    """The overlay of one look, from its record, its translation estimate and the estimator.

    Args:
        record: the look's iteration record (its ``commanded`` step, if any).
        estimate: the look's translation estimate (centre, blob area in ``record``).
        estimator: the estimator that made it; a Gabor one adds the ROI, the filter centres
            and the taught centre.
    """
    bundle = _bundle_of(estimator)
    taught = None
    if bundle is not None and getattr(bundle.front, "nominal_uv_px", None) is not None:
        taught = tuple(float(v) for v in bundle.front.nominal_uv_px)
    u, v = estimate.u_px, estimate.v_px
    if estimate.status != "ok" or not _finite(u, v):
        return Overlay(taught_px=taught)
    centre = (float(u), float(v))
    area = estimate.record.get("area_px")
    box = None
    if area is not None and _finite(area) and area > 0:
        half = math.sqrt(float(area)) / 2.0
        box = (u - half, v - half, u + half, v + half)
    roi, gabor = None, ()
    if bundle is not None:
        roi = float(bundle.gabor.roi_px)
        gabor = tuple((u - roi / 2.0 + p, v - roi / 2.0 + q)
                      for q in bundle.gabor.centres_px for p in bundle.gabor.centres_px)
    arrow = None
    step = record.commanded
    if step is not None and taught is not None and _finite(estimate.dx_mm, estimate.dy_mm):
        nn1 = np.array((estimate.dx_mm, estimate.dy_mm))
        norm2 = float(nn1 @ nn1)
        share = float(nn1 @ (step.dx_mm, step.dy_mm)) / norm2 if norm2 > 1e-12 else 0.0
        arrow = (centre, (u + share * (taught[0] - u), v + share * (taught[1] - v)))
    return Overlay(centre, box, roi, gabor, taught, arrow)


# -- Foxglove ImageAnnotations ---------------------------------------------------------------
def _colour(name: str, alpha: float = 1.0) -> Color:
    r, g, b = COLOURS[name]
    return Color(r=r, g=g, b=b, a=alpha)


def _pt(p: Point) -> Point2:
    return Point2(x=float(p[0]) + 0.5, y=float(p[1]) + 0.5)  # pixel-centre -> edge coordinates


def _square(cx: float, cy: float, side: float) -> list[Point]:
    h = side / 2.0
    return [(cx - h, cy - h), (cx + h, cy - h), (cx + h, cy + h), (cx - h, cy + h)]


def to_annotations(overlay: Overlay, stamp: Timestamp, texts: list[str] = ()) \
        -> ImageAnnotations:
    """The overlay as a ``foxglove.ImageAnnotations`` message stamped ``stamp``.

    The centre is the first circle; ``texts`` are stacked at the image's top left.
    """
    circles, points = [], []
    transparent = Color(r=0.0, g=0.0, b=0.0, a=0.0)

    def polyline(kind: PointsAnnotationType, corners: list[Point], colour: str,
                 thickness: float, fill: Color = transparent) -> None:
        points.append(PointsAnnotation(timestamp=stamp, type=kind,
                                       points=[_pt(p) for p in corners],
                                       outline_color=_colour(colour), fill_color=fill,
                                       thickness=thickness))

    if overlay.centre_px is not None:
        circles.append(CircleAnnotation(timestamp=stamp, position=_pt(overlay.centre_px),
                                        diameter=4.0, thickness=1.5,
                                        fill_color=_colour("centre"),
                                        outline_color=_colour("centre")))
    if overlay.box_px is not None:
        u0, v0, u1, v1 = overlay.box_px
        polyline(PointsAnnotationType.LineLoop, [(u0, v0), (u1, v0), (u1, v1), (u0, v1)],
                 "box", 1.0)
    if overlay.roi_px is not None and overlay.centre_px is not None:
        polyline(PointsAnnotationType.LineLoop, _square(*overlay.centre_px, overlay.roi_px),
                 "roi", 1.0)
    if overlay.gabor_px:
        polyline(PointsAnnotationType.Points, list(overlay.gabor_px), "gabor", 3.0,
                 _colour("gabor"))
    if overlay.taught_px is not None:
        circles.append(CircleAnnotation(timestamp=stamp, position=_pt(overlay.taught_px),
                                        diameter=8.0, thickness=1.0, fill_color=transparent,
                                        outline_color=_colour("taught")))
    if overlay.arrow_px is not None:
        (u0, v0), (u1, v1) = overlay.arrow_px
        length = math.hypot(u1 - u0, v1 - v0)
        segments = [(u0, v0), (u1, v1)]
        if length > 1e-6:
            bu, bv = (u0 - u1) / length * 4.0, (v0 - v1) / length * 4.0
            for turn in (0.5, -0.5):
                c, s = math.cos(turn), math.sin(turn)
                segments += [(u1, v1), (u1 + c * bu - s * bv, v1 + s * bu + c * bv)]
        polyline(PointsAnnotationType.LineList, segments, "step", 1.5)
    return ImageAnnotations(
        circles=circles, points=points,
        texts=[TextAnnotation(timestamp=stamp, position=Point2(x=2.0, y=10.0 + 10.0 * i),
                              text=text, font_size=9.0, text_color=_colour("taught"),
                              background_color=Color(r=0.0, g=0.0, b=0.0, a=0.6))
               for i, text in enumerate(texts)])


# -- drawing (replay, live view) -------------------------------------------------------------
def _bgr(name: str) -> tuple[int, int, int]:
    r, g, b = COLOURS[name]
    return int(b * 255), int(g * 255), int(r * 255)


def draw(image_rgb: np.ndarray, overlay: Overlay, texts: list[str] = (), scale: int = 4) \
        -> np.ndarray:
    """The frame scaled up by ``scale`` with the overlay and ``texts`` drawn on it (BGR uint8).

    A point at pixel-centre coordinate u lands at pixel ``(u + 0.5) * scale - 0.5`` of the
    result, the centre of the scaled pixel block.
    """
    out = cv2.resize(cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR), None, fx=scale, fy=scale,
                     interpolation=cv2.INTER_NEAREST)
    shift = 4  # cv2 sub-pixel bits

    def px(p: Point) -> tuple[int, int]:
        return (round(((p[0] + 0.5) * scale - 0.5) * (1 << shift)),
                round(((p[1] + 0.5) * scale - 0.5) * (1 << shift)))

    def rect(u0, v0, u1, v1, colour) -> None:
        cv2.rectangle(out, px((u0, v0)), px((u1, v1)), colour, 1, cv2.LINE_AA, shift)

    if overlay.roi_px is not None and overlay.centre_px is not None:
        (u0, v0), _, (u1, v1), _ = _square(*overlay.centre_px, overlay.roi_px)
        rect(u0, v0, u1, v1, _bgr("roi"))
    if overlay.box_px is not None:
        rect(*overlay.box_px, _bgr("box"))
    for p in overlay.gabor_px:
        cv2.circle(out, px(p), 2 << shift, _bgr("gabor"), -1, cv2.LINE_AA, shift)
    if overlay.taught_px is not None:
        cv2.drawMarker(out, tuple(v >> shift for v in px(overlay.taught_px)), _bgr("taught"),
                       cv2.MARKER_CROSS, 4 * scale, 1, cv2.LINE_AA)
    if overlay.arrow_px is not None:
        cv2.arrowedLine(out, px(overlay.arrow_px[0]), px(overlay.arrow_px[1]), _bgr("step"), 2,
                        cv2.LINE_AA, shift, 0.2)
    if overlay.centre_px is not None:
        cv2.circle(out, px(overlay.centre_px), 3 << shift, _bgr("centre"), -1, cv2.LINE_AA,
                   shift)
    for i, text in enumerate(texts):
        (w, h), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.45, 1)
        y = 16 + 18 * i
        cv2.rectangle(out, (3, y - h - 3), (9 + w, y + base), (0, 0, 0), -1)
        cv2.putText(out, text, (6, y), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1,
                    cv2.LINE_AA)
    return out


def look_texts(record: dict[str, Any]) -> list[str]:
    """The lines written on a look's tile: loop kind and count, step and (where known) the
    true error, from an iteration record (``IterationRecord.as_dict``)."""
    lines = [f"look {record.get('iteration')} {record.get('loop_kind')} "
             f"loops {record.get('loops', 0):g} {record.get('status')}"]
    step = record.get("commanded")
    if step:
        lines.append(f"step {step['dx_mm']:+.2f} {step['dy_mm']:+.2f} mm "
                     f"{step['dphi_deg']:+.1f} deg")
    error = record.get("error")
    if error:
        lines.append(f"true error {error['x_mm']:+.2f} {error['y_mm']:+.2f} mm "
                     f"{error['phi_deg']:+.1f} deg")
    return lines
