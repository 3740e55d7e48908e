"""The front end every system shares (paper sec. 3): one frame -> the object's centroid.

max(R, G, B) normalised to the training statistics (or the saturation image) -> binarisation at
the training threshold -> the blob that matches the trained part -> its centroid
(``calibration_free.preprocess`` and ``localise``). ``FrontEnd`` holds what training learned
for these steps (``calibration_free.training.prepare_training``); the Gabor bundle and both
baseline models store one, so all three systems see the object in the same place.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration_free.errors import ImageError
from calibration_free.kernels import cut_levels, saturation_image
from calibration_free.localise import (
    AREA_TOLERANCE,
    NO_ELONGATION_LIMIT,
    ColourEdge,
    Localisation,
    Polarity,
    localise,
)
from calibration_free.outline import MIN_CUT_SHARE, cut_share
from calibration_free.part_colour import PartColour
from calibration_free.preprocess import (
    Channel,
    IntensityStats,
    check_rgb,
    max_channel_u8,
    normalise,
)
from calibration_free.roi import above, extract_roi
from drivers.core.errors import ConfigError

# In the saturation channel the Gabor features see only what stands above this fraction of
# the part's threshold (``FrontEnd.feature_floor``, set at training), and no more than up to
# this multiple of it (``FrontEnd.feature_ceiling``): a soft silhouette of the part.
FEATURE_FLOOR = 0.75
FEATURE_CEILING = 1.5
# With a ceiling, the features see the part's blob and this many pixels around it (its edge
# ramp outside the threshold).
FEATURE_MARGIN_PX = 2
# A blob up to this many times the trained elongation is taken for the part where something
# lies against its outline (``FrontEnd.localise``).
CUT_ELONGATION = 1.5


@dataclass(frozen=True)
class FrontEnd:
    """What preprocessing and localisation learned from the training images.

    Attributes:
        frame_height_px, frame_width_px: the training frames' size (other sizes are refused:
            the translation networks map pixel positions).
        intensity: target statistics of the intensity normalisation.
        threshold: binarisation level (normalised grey units, or saturation 0..255).
        polarity: "bright" or "dark": which side of the threshold the object is on.
        expected_area_px: the middle of the object's blob areas in the training images.
        area_tolerance: a blob matches when |area / expected - 1| <= this (spans the
            training images' areas).
        max_elongation: a blob matches only up to this elongation (the part's shape).
        channel: the image the object is binarised in and the ROI is cut from: "max"
            (normalised max(R, G, B), the paper's), "saturation" or "colour" (the part's
            colour against the table's, ``part_colour``).
        nominal_uv_px: where the part appeared at the taught pose (u, v); of several blobs
            that match the part, one clearly nearest this point is taken. None: several
            matching blobs are ambiguous.
        chroma: the part's colour in the training images, as chromaticity (R, G, B over
            their sum, summed over its blob: independent of brightness); of several blobs
            of the part's size and shape (a cluttered image), those of this colour are
            preferred. None: colour is not used (model files written before it was learned).
        chroma_tolerance: the largest chromaticity distance still taken for the part.
        feature_floor: in the saturation channel, the features see the ROI above this
            fraction of ``threshold`` (``feature_roi``); 0: all of it (model files written
            before the floor).
        feature_ceiling: in the saturation channel, the features see the ROI up to this
            multiple of ``threshold`` (everything above it reads the same); 0: no ceiling
            (model files written before it).
        taught_area_px: the part's blob area at the taught pose (the mean over the training
            frames taken there): where the loop settles, a blob much smaller than this is a
            part partly hidden (``seen_share``). None: not known (model files written before
            it).
        taught_outline_px: the blob's outline in a frame at the taught pose, about its
            centre (``calibration_free.outline``): a part partly hidden is centred on the
            outline it shows. None: not known (model files written before it).
        turned_outlines_px: the part's outline turned on the table, as (turn_deg, outline)
            pairs from the NN2 grid's images (``outline.turned_outlines``): from an angle,
            a turned part shows other faces. Empty: not known (model files written before
            them); the taught outline alone is fitted.
        edge_gamma: the camera's output gamma, with which the part's edge is read from the
            frame's colour (``localise.colour_centre``); 0: from the localisation channel's
            grey levels (``localise.subpixel_centre``; model files written before it).
        edge_fill_holes: with ``edge_gamma``, the centre is that of the part's outer outline,
            its holes counted as part (``ColourEdge.fill_holes``); False in model files
            written before it, which read the holes' rims as edges too.
        part_colour: the part's and the table's colours the "colour" channel compares
            (``calibration_free.part_colour``); None for the other channels.
    """

    frame_height_px: int
    frame_width_px: int
    intensity: IntensityStats
    threshold: float
    polarity: Polarity
    expected_area_px: float
    area_tolerance: float = AREA_TOLERANCE
    max_elongation: float = NO_ELONGATION_LIMIT
    channel: Channel = "max"
    nominal_uv_px: tuple[float, float] | None = None
    chroma: tuple[float, float, float] | None = None
    chroma_tolerance: float = 0.0
    feature_floor: float = 0.0
    feature_ceiling: float = 0.0
    taught_area_px: float | None = None
    taught_outline_px: tuple[tuple[float, float], ...] | None = None
    turned_outlines_px: tuple[tuple[float, tuple[tuple[float, float], ...]], ...] = ()
    edge_gamma: float = 0.0
    edge_fill_holes: bool = False
    part_colour: PartColour | None = None

    def __post_init__(self) -> None:
        gamma = self.edge_gamma
        if not isinstance(self.edge_fill_holes, bool):
            raise ConfigError(f"front end: edge_fill_holes must be true or false, got "
                              f"{self.edge_fill_holes!r}")
        try:  # 0: grey levels; any other value is a camera gamma (ColourEdge checks it)
            edge = None if not isinstance(gamma, bool) and gamma == 0 else \
                ColourEdge(gamma, self.edge_fill_holes)
        except ConfigError as exc:
            raise ConfigError(f"front end: edge_gamma must be 0 (grey levels) or a number in "
                              f"1..3, got {gamma!r}") from exc
        object.__setattr__(self, "_edge", edge)
        if self.taught_outline_px is not None:
            object.__setattr__(self, "taught_outline_px",
                               _outline(self.taught_outline_px, "taught_outline_px"))
        turned = self.turned_outlines_px
        try:
            turned = tuple((float(t), o) for t, o in turned)
        except (TypeError, ValueError):
            turned = None
        if turned is None or not all(math.isfinite(t) for t, _ in turned):
            raise ConfigError("front end: turned_outlines_px must be a list of "
                              "[turn_deg, outline] pairs")
        object.__setattr__(self, "turned_outlines_px", tuple(
            (t, _outline(o, "turned_outlines_px")) for t, o in turned))
        taught = self.taught_area_px
        if taught is not None and (isinstance(taught, bool) or not isinstance(
                taught, (int, float)) or not 0.0 < taught < math.inf):
            raise ConfigError(f"front end: taught_area_px must be a number > 0 or none, got "
                              f"{taught!r}")
        if isinstance(self.feature_floor, bool) or not isinstance(
                self.feature_floor, (int, float)) or not 0.0 <= self.feature_floor <= 1.0:
            raise ConfigError(f"front end: feature_floor must be a number in 0..1, got "
                              f"{self.feature_floor!r}")
        ceiling = self.feature_ceiling
        if isinstance(ceiling, bool) or not isinstance(ceiling, (int, float)) or not (
                ceiling == 0.0 or self.feature_floor < ceiling < math.inf):
            raise ConfigError(f"front end: feature_ceiling must be 0 (none) or a finite number "
                              f"above feature_floor ({self.feature_floor!r}), got {ceiling!r}")
        for name in ("frame_height_px", "frame_width_px"):
            size = getattr(self, name)
            if isinstance(size, bool) or not isinstance(size, int) or size < 1:
                raise ConfigError(f"front end: {name} must be a whole number >= 1, got "
                                  f"{size!r}")
        if self.channel not in ("max", "saturation", "colour"):
            raise ConfigError(f"front end: channel must be max, saturation or colour, got "
                              f"{self.channel!r}")
        if (self.channel == "colour") != isinstance(self.part_colour, PartColour):
            raise ConfigError("front end: the colour channel needs the part's colour "
                              "(part_colour), and only it has one")
        if self.polarity not in ("bright", "dark"):
            raise ConfigError(f"front end: polarity must be bright or dark, got "
                              f"{self.polarity!r}")
        if not (math.isfinite(self.threshold) and math.isfinite(self.expected_area_px)
                and self.expected_area_px > 0 and 0 < self.area_tolerance <= 1
                and self.max_elongation >= 1.0):
            raise ConfigError(f"front end: need a finite threshold, expected_area_px > 0, "
                              f"0 < area_tolerance <= 1 and max_elongation >= 1, got "
                              f"{self.threshold!r}, {self.expected_area_px!r}, "
                              f"{self.area_tolerance!r}, {self.max_elongation!r}")
        if self.nominal_uv_px is not None:
            uv = tuple(float(v) for v in self.nominal_uv_px)
            if len(uv) != 2 or not all(math.isfinite(v) for v in uv):
                raise ConfigError(f"front end: nominal_uv_px must be two finite numbers, got "
                                  f"{self.nominal_uv_px!r}")
            object.__setattr__(self, "nominal_uv_px", uv)
        if self.chroma is not None:
            chroma = tuple(float(v) for v in self.chroma)
            if len(chroma) != 3 or not all(0.0 <= v <= 1.0 for v in chroma) or not (
                    0.0 < self.chroma_tolerance <= 1.0):
                raise ConfigError(f"front end: chroma must be three numbers in 0..1 and "
                                  f"0 < chroma_tolerance <= 1, got {self.chroma!r}, "
                                  f"{self.chroma_tolerance!r}")
            object.__setattr__(self, "chroma", chroma)

    def preprocess(self, image: np.ndarray) -> np.ndarray:
        """The image localisation binarises and the ROI is cut from (HxW float32): the
        max-channel image normalised to the training statistics, or the saturation image.

        Args:
            image: an HxWx3 uint8 RGB frame of the training frames' size.

        Raises:
            ImageError: not HxWx3 uint8 of the training frames' size.
        """
        check_rgb(image)
        if image.shape[:2] != (self.frame_height_px, self.frame_width_px):
            raise ImageError(f"image: the model was trained on {self.frame_width_px}x"
                             f"{self.frame_height_px} frames, got {image.shape[1]}x"
                             f"{image.shape[0]}")
        if self.channel == "saturation":
            return saturation_image(np.ascontiguousarray(image))
        if self.part_colour is not None:
            return self.part_colour.image(image)
        return normalise(max_channel_u8(image), self.intensity)

    def feature_roi(self, preprocessed: np.ndarray, loc: Localisation,
                    size_px: int) -> np.ndarray:
        """The ROI the Gabor features are computed on: the ``size_px`` square of the
        preprocessed image centred on the part found in it (``roi.extract_roi``); in the
        saturation channel with everything up to ``feature_floor`` times the part's
        threshold taken off and everything above ``feature_ceiling`` times it cut to that
        level (``roi.above``), the same in training and in the loop; with a ceiling, only
        the part's blob (``loc.part_mask``) and ``FEATURE_MARGIN_PX`` around it stay.

        Saturation is near zero on a grey table in good light, but camera noise in a dark
        frame and a warm lamp raise it over the whole table, and a cast shadow beside the
        part shows as a patch: the features would read that as part of the part's shape.
        Inside the part, saturation varies with the light too: a face turned from a side
        lamp is dark and its saturation noisy, a lit one is clipped in its brightest channel.
        Cut at the ceiling, the inside is flat and the features read the outline, whose
        ramp between floor and ceiling keeps its sub-pixel position; the noise specks in a
        dark cast shadow that reach over the floor would then weigh as much as the part's
        edge, so they are taken off with everything else away from the part.
        """
        roi = extract_roi(preprocessed, loc.u_px, loc.v_px, size_px)
        # ROI pixel (i, j) samples the frame at (u - (size - 1) / 2 + j, v - ...): the nearest
        # frame pixel is (x0 + j, y0 + i)
        return self._cut(roi, loc, math.floor(loc.u_px - (size_px - 1) / 2.0 + 0.5),
                         math.floor(loc.v_px - (size_px - 1) / 2.0 + 0.5))

    def coverage_roi(self, loc: Localisation, size_px: int) -> np.ndarray | None:
        """The part's coverage, the ``size_px`` square centred on it: each pixel's share of
        the part read from the frame's colour (``Localisation.coverage``; 1 inside the
        outline, 0 beyond, within 0..1), as float32; None where the centre was not read
        from colour (no ``edge_gamma``, a grey part, a part partly hidden and drawn in)."""
        if loc.coverage is None:
            return None
        x0, y0, weights = loc.coverage
        window = np.clip(weights, np.float32(0.0), np.float32(1.0))
        # the window's border lies beyond the band (0), which the replicated border repeats
        return extract_roi(window, loc.u_px - x0, loc.v_px - y0, size_px)

    def feature_frame(self, preprocessed: np.ndarray, loc: Localisation) -> np.ndarray:
        """The whole preprocessed frame cut as ``feature_roi`` cuts its window (a copy): what a
        full-frame filter must see to give the same features (``bench perception``'s
        reference path)."""
        return self._cut(preprocessed.copy(), loc, 0, 0)

    def _cut(self, image: np.ndarray, loc: Localisation, x0: int, y0: int) -> np.ndarray:
        """``image`` (a window whose pixel (i, j) lies on frame pixel (y0 + i, x0 + j)) cut to
        what the features see, in place (see ``feature_roi``)."""
        if self.channel != "saturation" or not (self.feature_floor or self.feature_ceiling):
            return image
        low = self.feature_floor * self.threshold
        if not self.feature_ceiling:
            return above(image, low)
        high = self.feature_ceiling * self.threshold
        if loc.part_mask is None:
            return above(image, low, high)
        cut_levels(image, np.float32(low), np.float32(high), loc.part_mask, x0, y0,
                   FEATURE_MARGIN_PX)
        return image

    def localise(self, preprocessed: np.ndarray, image: np.ndarray | None = None
                 ) -> Localisation:
        """The object's centroid in an image from ``preprocess``.

        Args:
            preprocessed: HxW float32, what ``preprocess`` returned for the frame.
            image: the RGB frame itself: with it (and a learned ``chroma``), of several
                candidate blobs those of the part's colour are preferred, and the centre is
                read from its colour (with ``edge_gamma``).

        Returns:
            The Localisation (ok, no_object or ambiguous, with the reason).
        """
        check = None
        if image is not None and self.chroma is not None:
            check = colour_check(image, self.chroma, self.chroma_tolerance)
        found = self._localise_at(preprocessed, image, self.threshold, self.max_elongation,
                                  check)
        if found.status != "no_object":
            return found
        if self.taught_outline_px is not None and self.max_elongation != NO_ELONGATION_LIMIT:
            # A part cut by something lying on it is longer for its width than the part (a
            # cube with a quarter hidden: 1.6 against 1.55 at most in training): a blob of the
            # expected area, up to CUT_ELONGATION times the trained shape's elongation, is the
            # part where its outline has something other than the table beyond it.
            cut = self._localise_at(preprocessed, image, self.threshold,
                                    CUT_ELONGATION * self.max_elongation, check)
            if cut.ok and cut_share(preprocessed, cut.part_mask, cut.u_px, cut.v_px,
                                    self.threshold) >= MIN_CUT_SHARE:
                return cut
        return found

    def _localise_at(self, preprocessed: np.ndarray, image: np.ndarray | None,
                     threshold: float, max_elongation: float, check) -> Localisation:
        """``localise`` with what training learned, at ``threshold`` and up to
        ``max_elongation``."""
        return localise(preprocessed, threshold, self.expected_area_px, polarity=self.polarity,
                        area_tolerance=self.area_tolerance, max_elongation=max_elongation,
                        expected_uv=self.nominal_uv_px, blob_check=check, image=image,
                        edge=self.edge)

    def locate(self, image: np.ndarray) -> tuple[np.ndarray, Localisation]:
        """``preprocess`` then ``localise``: one frame's preprocessed image and the object.

        Args:
            image: an HxWx3 uint8 RGB frame of the training frames' size.

        Returns:
            The preprocessed image (what the ROI is cut from) and the Localisation.

        Raises:
            ImageError: not HxWx3 uint8 of the training frames' size.
        """
        preprocessed = self.preprocess(image)
        return preprocessed, self.localise(preprocessed, image)

    @property
    def edge(self) -> ColourEdge | None:
        """How the part's edge is read from the frame's colour; None: from grey levels."""
        return self._edge

    @property
    def outlines(self) -> tuple[tuple[tuple[float, float], ...], ...]:
        """The outlines a part partly hidden is fitted with (``outline.fit_outline``): the
        taught one first, then the turned ones; empty where none is known."""
        if self.taught_outline_px is None:
            return ()
        return (self.taught_outline_px, *(o for _, o in self.turned_outlines_px))

    def seen_share(self, area_px: float) -> float | None:
        """A blob's area over the part's at the taught pose (None where that is not known):
        near 1 where the loop settles on the whole part, lower where something hides part of
        it."""
        return None if self.taught_area_px is None else area_px / self.taught_area_px

    def to_info(self) -> dict[str, Any]:
        """The JSON a model file stores: keys ``frame_px``, ``intensity``, ``localisation``
        (with ``part_colour`` for the colour channel only).

        Returns:
            A JSON-able dict; ``from_info`` reads it back.
        """
        uv = None if self.nominal_uv_px is None else list(self.nominal_uv_px)
        chroma = None if self.chroma is None else list(self.chroma)
        return {"frame_px": {"height": self.frame_height_px, "width": self.frame_width_px},
                "intensity": {"mean": self.intensity.mean, "std": self.intensity.std},
                "localisation": {"threshold": self.threshold, "polarity": self.polarity,
                                 "expected_area_px": self.expected_area_px,
                                 "area_tolerance": self.area_tolerance,
                                 "max_elongation": self.max_elongation,
                                 "channel": self.channel, "nominal_uv_px": uv,
                                 "chroma": chroma,
                                 "chroma_tolerance": self.chroma_tolerance,
                                 "feature_floor": self.feature_floor,
                                 "feature_ceiling": self.feature_ceiling,
                                 "taught_area_px": self.taught_area_px,
                                 "taught_outline_px": None if self.taught_outline_px is None
                                 else [list(p) for p in self.taught_outline_px],
                                 "turned_outlines_px": [[t, [list(p) for p in o]]
                                                        for t, o in self.turned_outlines_px],
                                 "edge_gamma": self.edge_gamma,
                                 "edge_fill_holes": self.edge_fill_holes,
                                 **({} if self.part_colour is None
                                    else {"part_colour": self.part_colour.to_info()})}}

    @classmethod
    def from_info(cls, info: Mapping[str, Any]) -> FrontEnd:
        """Inverse of ``to_info``. ``localisation.channel``, ``nominal_uv_px``, ``chroma``,
        ``feature_floor``, ``feature_ceiling``, ``taught_area_px``, ``taught_outline_px``,
        ``turned_outlines_px``, ``edge_gamma``, ``edge_fill_holes`` and ``part_colour`` may be
        absent (model files written before they were stored): "max", None, None, 0, 0, None,
        None, none, 0, false and None.

        Args:
            info: a model file's JSON (at least ``frame_px``, ``intensity``,
                ``localisation``).

        Raises:
            KeyError, TypeError, ValueError, ConfigError: missing or bad values (model
                loaders turn these into a BundleError naming the file).
        """
        loc = info["localisation"]
        uv = loc.get("nominal_uv_px")
        chroma = loc.get("chroma")
        taught = loc.get("taught_area_px")
        colour = loc.get("part_colour")
        return cls(int(info["frame_px"]["height"]), int(info["frame_px"]["width"]),
                   IntensityStats(**info["intensity"]), float(loc["threshold"]),
                   loc["polarity"], float(loc["expected_area_px"]),
                   float(loc["area_tolerance"]), float(loc["max_elongation"]),
                   loc.get("channel", "max"), None if uv is None else tuple(uv),
                   None if chroma is None else tuple(chroma),
                   float(loc.get("chroma_tolerance", 0.0)),
                   float(loc.get("feature_floor", 0.0)),
                   float(loc.get("feature_ceiling", 0.0)),
                   None if taught is None else float(taught),
                   loc.get("taught_outline_px"), loc.get("turned_outlines_px", ()),
                   loc.get("edge_gamma", 0.0), loc.get("edge_fill_holes", False),
                   None if colour is None else PartColour.from_info(colour))


def _outline(points: Any, name: str) -> tuple[tuple[float, float], ...]:
    """An outline as a tuple of (u, v) floats; ConfigError naming ``name`` unless 8 or more
    finite pairs."""
    try:
        outline = tuple((float(u), float(v)) for u, v in points)
    except (TypeError, ValueError):
        outline = ()
    if len(outline) < 8 or not all(math.isfinite(u) and math.isfinite(v) for u, v in outline):
        raise ConfigError(f"front end: {name} must hold outlines of 8 or more finite (u, v) "
                          f"pairs")
    return outline


# The colour preference's tolerance: this many times the largest chromaticity distance seen among
# the training images (lighting, noise, the part's own shading), and at least the floor: the
# construction set's colours lie 0.2 or more apart (yellow, wood, red, green, blue).
CHROMA_SPREAD_FACTOR = 2.0
CHROMA_MIN_TOLERANCE = 0.06


def blob_chroma(image: np.ndarray, mask: np.ndarray, box: tuple[int, int, int, int]
                ) -> tuple[float, float, float] | None:
    """The chromaticity (R, G, B over their sum, summed over the blob) of the pixels of
    ``mask`` (the blob within its bounding box ``box`` = x, y, w, h) in the RGB ``image``;
    None for a black blob."""
    x, y, w, h = box
    pixels = image[y:y + h, x:x + w][mask].astype(np.float64)
    total = pixels.sum(axis=0)
    s = float(total.sum())
    if s <= 0.0:
        return None
    return tuple(float(v) for v in total / s)


def colour_check(image: np.ndarray, chroma: tuple[float, float, float], tolerance: float):
    """A ``localise`` blob check: the blob's chromaticity within ``tolerance`` of ``chroma``."""
    ref = np.asarray(chroma)

    def check(mask: np.ndarray, box: tuple[int, int, int, int]) -> bool:
        c = blob_chroma(image, mask, box)
        return c is not None and float(np.linalg.norm(np.asarray(c) - ref)) <= tolerance
    return check


def learn_chroma(images: list[np.ndarray], masks: list[tuple[np.ndarray, tuple]]
                 ) -> tuple[tuple[float, float, float], float] | None:
    """The part's chromaticity and the colour check's tolerance from its blob in training
    images: the median chromaticity, and ``CHROMA_SPREAD_FACTOR`` times the largest distance
    from it (at least ``CHROMA_MIN_TOLERANCE``). ``masks``: per image, the part's blob within
    its bounding box and the box. None when no blob has any colour."""
    found = [c for image, (mask, box) in zip(images, masks, strict=True)
             if (c := blob_chroma(image, mask, box)) is not None]
    if not found:
        return None
    values = np.array(found)
    centre = np.median(values, axis=0)
    centre = centre / centre.sum()
    spread = float(np.linalg.norm(values - centre, axis=1).max())
    tolerance = min(1.0, max(CHROMA_MIN_TOLERANCE, CHROMA_SPREAD_FACTOR * spread))
    return tuple(float(v) for v in centre), tolerance
