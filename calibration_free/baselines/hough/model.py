"""The trained Hough system (paper sections 2.3 and 4.3) and its perception of one frame.

normalise -> localise (the object's blob and centroid) -> filled silhouette -> edges in a band
around its outline (``edges``) -> Hough transform about the centroid, back-transform, peaks,
lines refined on their own points (``hough``) -> validation by the constellation model
(``constellation``); no valid constellation is ``no_object`` with the reason. The rotation is
the outline's angle through the learned angle map (``angle_map``); the translation is the PSOM
completion of (object centroid u, v; rotation) to (dx, dy) (``psom``).

File: ``model_file`` with kind "hough"; arrays ``psom.weights``, ``psom.nodes{k}``,
``psom.scale``, ``angle_map.coefficients``; everything else in the JSON metadata.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar

import numpy as np

from calibration_free.baselines.hough import edges
from calibration_free.baselines.hough import transform as hough
from calibration_free.baselines.hough.angle_map import AngleMap
from calibration_free.baselines.hough.constellation import (
    Constellation,
    ConstellationModel,
    find_constellation,
)
from calibration_free.baselines.hough.psom import PSOM
from calibration_free.baselines.hough.transform import HoughLine
from calibration_free.front_end import FrontEnd
from calibration_free.localise import Localisation, Status
from calibration_free.model_file import TaughtModel
from drivers.core.errors import ConfigError
from drivers.core.typed_config import from_mapping, to_mapping

KIND = "hough"
FORMAT_VERSION = 1
# PSOM embedding: (u_px, v_px, dphi_deg) inputs, (dx_mm, dy_mm) outputs.
PSOM_INPUTS = (0, 1, 2)
PSOM_OUTPUTS = (3, 4)


@dataclass(frozen=True)
class HoughConfig:
    """Config of the Hough system.

    Attributes:
        blur_sigma_px: Gaussian smoothing before the edge filter.
        edge_high, edge_low: Canny hysteresis thresholds as fractions of the median gradient
            on the training images' outlines.
        band_px: edges farther than this from the silhouette's outline are masked.
        theta_step_deg, d_step_px: accumulator bins.
        max_lines: Hough peaks considered for the constellation.
        min_line_fraction: a line needs this fraction of the part's side (sqrt of its blob
            area) in edge points.
        peak_window_deg, peak_window_px: peaks closer than this are one peak.
        width_margin, angle_margin_deg: how much the learned constellation tolerances exceed
            what the training images showed.
        line_vote_fraction: a constellation's line needs this fraction of the edge points of
            the median line in the training constellations.
        angle_harmonics: Fourier harmonics of the angle map.
    """

    blur_sigma_px: float = field(default=1.0, metadata={"min": 0.0, "exclusive_min": True})
    edge_high: float = field(default=0.5, metadata={"min": 0.0, "exclusive_min": True})
    edge_low: float = field(default=0.25, metadata={"min": 0.0, "exclusive_min": True})
    band_px: int = field(default=3, metadata={"min": 1})
    theta_step_deg: float = field(default=1.0, metadata={"min": 0.0, "exclusive_min": True})
    d_step_px: float = field(default=1.0, metadata={"min": 0.0, "exclusive_min": True})
    max_lines: int = field(default=8, metadata={"min": 2})
    min_line_fraction: float = field(default=0.2, metadata={"min": 0.0})
    peak_window_deg: float = field(default=4.0, metadata={"min": 0.0})
    peak_window_px: float = field(default=3.0, metadata={"min": 0.0})
    width_margin: float = field(default=0.15, metadata={"min": 0.0, "max": 0.9})
    angle_margin_deg: float = field(default=5.0, metadata={"min": 0.0})
    line_vote_fraction: float = field(default=0.35, metadata={"min": 0.0, "max": 1.0})
    angle_harmonics: int = field(default=2, metadata={"min": 1})

    def __post_init__(self) -> None:
        if self.edge_low > self.edge_high:
            raise ConfigError(f"hough.edge_low: must be <= edge_high ({self.edge_high}), got "
                              f"{self.edge_low}")
        n = 180.0 / self.theta_step_deg
        if abs(n - round(n)) > 1e-9 or n < 2:
            raise ConfigError(f"hough.theta_step_deg: 180 must be a whole multiple of it, got "
                              f"{self.theta_step_deg}")


@dataclass(frozen=True)
class EdgeSettings:
    """The edge and line thresholds the training images set (absolute units)."""

    low: float
    high: float
    min_line_votes: float


@dataclass(frozen=True)
class Outline:
    """The lines of the outline around one object, and how many edge points they came from."""

    lines: list[HoughLine]
    points: int
    peak_to_sidelobe: float


def find_outline(normalised: np.ndarray, front: FrontEnd, loc: Localisation,
                 config: HoughConfig, settings: EdgeSettings, outline_lines: int) -> Outline:
    """Edges around the located object's outline, and the Hough lines through them.

    ``outline_lines`` (the lines a full outline has) is how many peaks the peak-to-sidelobe
    ratio is measured over.

    Raises:
        ImageError: bad image, or ``loc`` is not ok.
    """
    filled = edges.silhouette(normalised, front.threshold, front.polarity, loc.u_px, loc.v_px)
    edge = edges.edge_map(normalised, config.blur_sigma_px, settings.low, settings.high)
    points = edges.outline_points(edge, filled, config.band_px)
    if points.shape[0] < 2:
        return Outline([], int(points.shape[0]), 0.0)
    origin = (loc.u_px, loc.v_px)
    reach = float(np.hypot(*(points - origin).T).max()) + 1.0
    space = hough.accumulate(points, origin_px=origin, d_max_px=reach,
                             theta_step_deg=config.theta_step_deg, d_step_px=config.d_step_px)
    sharp, owner = hough.back_transform(points, space)
    window = (config.peak_window_deg, config.peak_window_px)
    peaks = hough.find_peaks(sharp, max_peaks=config.max_lines, window_deg=window[0],
                             window_px=window[1])
    lines = hough.fit_lines(points, owner, sharp, peaks, *window,
                            min_votes=settings.min_line_votes)
    return Outline(lines, int(points.shape[0]),
                   hough.peak_to_sidelobe(sharp, peaks[:outline_lines], *window))


@dataclass(frozen=True)
class HoughPercept:
    """What the Hough system saw in one frame.

    Attributes:
        status: "ok", or "no_object" / "ambiguous" (localisation failed, or the Hough peaks
            did not validate; then the estimates are None and reason says why).
        reason: why the status is not ok ("" when ok).
        localisation: the blob localisation.
        outline: the Hough lines found (None if the object was not located).
        constellation: the validated lines (None unless ok).
        dphi_deg: the corrective rotation (None unless ok).
        dxdy_mm: the corrective translation from the PSOM (None unless ok).
        psom_s: the PSOM's best-match parameters (None unless ok).
    """

    status: Status
    reason: str
    localisation: Localisation
    outline: Outline | None = None
    constellation: Constellation | None = None
    dphi_deg: float | None = None
    dxdy_mm: tuple[float, float] | None = None
    psom_s: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class HoughModel(TaughtModel):
    """A trained Hough system for one part.

    Attributes:
        object_kind, kappa, nominal_pose: what it was taught on.
        front: the shared preprocessing and localisation.
        config: the Hough system's settings.
        edge_settings: learned edge thresholds and the least votes of a line.
        constellation: the learned model of the expected peak constellation.
        angle_map: outline angle -> dphi.
        psom: (u_px, v_px, dphi_deg) -> (dx_mm, dy_mm), embedding order as PSOM_INPUTS /
            PSOM_OUTPUTS.
        training: JSON-able training metadata.
    """

    file_kind: ClassVar[str] = KIND
    file_version: ClassVar[int] = FORMAT_VERSION

    config: HoughConfig
    edge_settings: EdgeSettings
    constellation: ConstellationModel
    angle_map: AngleMap
    psom: PSOM

    def __post_init__(self) -> None:
        if not (self.constellation.kappa == self.angle_map.kappa == self.kappa):
            raise ConfigError(f"hough model: kappa {self.kappa}, constellation "
                              f"{self.constellation.kappa} and angle map "
                              f"{self.angle_map.kappa} differ")
        if self.psom.inputs != PSOM_INPUTS or self.psom.weights.shape[-1] != 5:
            raise ConfigError("hough model: the PSOM must embed (u, v, dphi, dx, dy) with "
                              "(u, v, dphi) as inputs")

    @property
    def feature_count(self) -> int:
        """Lines of a full constellation (what the rotation is read from)."""
        return 2 * self.constellation.pairs

    def perceive(self, image: np.ndarray) -> HoughPercept:
        """Locate, find and validate the outline, and map it to the corrective step.

        Raises:
            ImageError: the frame is not HxWx3 uint8 of the training frames' size.
        """
        normalised, loc = self.front.locate(image)
        if not loc.ok:
            return HoughPercept(loc.status, loc.reason, loc)
        outline = find_outline(normalised, self.front, loc, self.config, self.edge_settings,
                               self.feature_count)
        found, reason = find_constellation(outline.lines, self.constellation,
                                           (loc.u_px, loc.v_px))
        if found is None:
            return HoughPercept("no_object", f"Hough peaks rejected: {reason}", loc, outline)
        dphi = self.angle_map(found.angle_deg)
        s, w = self.psom.complete(np.array([loc.u_px, loc.v_px, dphi]))
        return HoughPercept("ok", "", loc, outline, found, dphi,
                            (float(w[PSOM_OUTPUTS[0]]), float(w[PSOM_OUTPUTS[1]])), s)

    def system_info(self) -> dict[str, Any]:
        """The Hough system's own JSON: config, edge settings, constellation model, the angle
        map's and the PSOM's shapes.

        Returns:
            A JSON-able dict, merged into the file's JSON by ``to_info``.
        """
        return {"hough": to_mapping(self.config), "edge_settings": asdict(self.edge_settings),
                "constellation": asdict(self.constellation),
                "angle_map": {"harmonics": self.angle_map.harmonics},
                "psom": {"inputs": list(self.psom.inputs), "axes": len(self.psom.nodes)}}

    def arrays(self) -> dict[str, np.ndarray]:
        """The PSOM and the angle map as named arrays.

        Returns:
            ``psom.weights``, ``psom.scale``, ``angle_map.coefficients``, ``psom.nodes{k}``.
        """
        return {"psom.weights": self.psom.weights, "psom.scale": self.psom.scale,
                "angle_map.coefficients": self.angle_map.coefficients,
                **{f"psom.nodes{k}": n for k, n in enumerate(self.psom.nodes)}}

    @classmethod
    def from_file(cls, info: dict[str, Any], arrays: dict[str, np.ndarray],
                  taught: dict[str, Any]) -> HoughModel:
        """A Hough model from a model file's contents (see ``TaughtModel.from_file``)."""
        return cls(**taught, config=from_mapping(HoughConfig, info["hough"], "hough"),
                   edge_settings=EdgeSettings(**info["edge_settings"]),
                   constellation=ConstellationModel(**info["constellation"]),
                   angle_map=AngleMap(taught["kappa"], int(info["angle_map"]["harmonics"]),
                                      arrays["angle_map.coefficients"]),
                   psom=PSOM(tuple(arrays[f"psom.nodes{k}"]
                                   for k in range(info["psom"]["axes"])),
                             arrays["psom.weights"], tuple(info["psom"]["inputs"]),
                             arrays["psom.scale"]))
