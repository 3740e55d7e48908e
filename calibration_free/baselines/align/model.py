"""The trained image-alignment servo and its perception of one frame.

Perception: the shared front end finds the part's blob; the frame's soft silhouette (what the
Gabor system's features see, ``FrontEnd.feature_frame``) is registered to the taught template
(``register``); least squares map the reference point's shift (du, dv) and the image turn a
to the tool step: dphi from a, harmonics of kappa a, du, dv and their products (the tilted
camera sees the tool's turn foreshortened), then (dx, dy) from a cubic in (du, dv) plus (sin,
cos) of kappa dphi times (1, du, dv).

File: ``model_file`` with kind "align"; arrays ``align.template`` (T x T), ``align.xy``
(translation coefficients, 24 x 2), ``align.phi`` (rotation coefficients, 17).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from calibration_free.baselines.align.register import Registration, Template, wrap_deg
from calibration_free.localise import Localisation
from calibration_free.model_file import TaughtModel
from drivers.core.errors import ConfigError
from drivers.core.typed_config import from_mapping, to_mapping

KIND = "align"
FORMAT_VERSION = 1
SHIFT_SCALE_PX = 10.0  # (du, dv) enter the fit in tens of pixels: a well-conditioned basis
XY_TERMS = 24
PHI_TERMS = 17
TURN_SCALE_DEG = 30.0  # the turn enters the rotation fit in units of 30 deg


@dataclass(frozen=True)
class AlignConfig:
    """Config of the image-alignment servo (``perception.align``).

    Attributes:
        margin_px: the template's side is the diagonal of the part's box at the taught pose
            (the part fits in it at any turn) plus this on every side.
        scan_step_deg: the rotation scan's step over the symmetry period.
        ecc_iterations: ECC's largest number of iterations.
        ecc_epsilon: ECC stops when the correlation improves by less than this.
        near_weight: weight of the rotation set's samples (within a few millimetres of the
            taught pose) in the least squares, against 1 for the translation set's.
        taught_weight: weight of the frames at the taught pose (they pin the zero).
        min_correlation: images registered with a correlation below this fraction of the
            median are left out of the fit (a long part cut by the frame's edge at the far
            end of the translation grid).
    """

    margin_px: int = field(default=6, metadata={"min": 0, "max": 64})
    scan_step_deg: float = field(default=5.0, metadata={"min": 0.5, "max": 45.0})
    ecc_iterations: int = field(default=50, metadata={"min": 1, "max": 1000})
    ecc_epsilon: float = field(default=1e-5, metadata={"min": 0.0})
    near_weight: float = field(default=30.0, metadata={"min": 0.0})
    taught_weight: float = field(default=100.0, metadata={"min": 0.0})
    min_correlation: float = field(default=0.9, metadata={"min": 0.0, "max": 1.0})


@dataclass(frozen=True)
class AlignPercept:
    """What the servo saw in one frame.

    Attributes:
        localisation: where the part's blob is, or why it was not found.
        registration: the frame registered to the template; None unless found.
        step: the tool step (dx_mm, dy_mm, dphi_deg); None unless found.
    """

    localisation: Localisation
    registration: Registration | None = None
    step: tuple[float, float, float] | None = None


def xy_basis(du: np.ndarray, dv: np.ndarray, dphi_deg: np.ndarray, kappa: int) -> np.ndarray:
    """The translation fit's terms, (N, 24): a cubic in the shift (tens of px), (sin,
    cos - 1) of kappa times the tool's turn (as the rotation fit reads it), alone and times
    the shift."""
    du, dv = np.asarray(du) / SHIFT_SCALE_PX, np.asarray(dv) / SHIFT_SCALE_PX
    a = np.radians(np.asarray(dphi_deg) * kappa)
    s, c = np.sin(a), np.cos(a) - 1.0
    one = np.ones_like(du)
    s2, c2 = np.sin(2 * a), np.cos(2 * a) - 1.0
    return np.stack([one, du, dv, du * du, du * dv, dv * dv, du ** 3, du * du * dv,
                     du * dv * dv, dv ** 3, s, c, s * du, s * dv, c * du, c * dv, s2, c2,
                     s * du * du, s * du * dv, s * dv * dv, c * du * du, c * du * dv,
                     c * dv * dv], axis=-1)


def phi_basis(du: np.ndarray, dv: np.ndarray, angle_deg: np.ndarray, kappa: int) -> np.ndarray:
    """The rotation fit's terms, (N, 17): the image turn (in 30 deg), a constant, the first
    two harmonics of kappa times the turn, a quadratic in the shift (tens of px), the shift
    times the first harmonic and times the turn. The tilted camera sees the tool's turn
    foreshortened, by an amount that goes round with the turn and changes over the image; over
    a whole turn (kappa 1) the reading is the turn plus a periodic part."""
    du, dv = np.asarray(du) / SHIFT_SCALE_PX, np.asarray(dv) / SHIFT_SCALE_PX
    turn = np.asarray(angle_deg, dtype=float)
    k = np.radians(turn * kappa)
    s1, c1, s2, c2 = np.sin(k), np.cos(k) - 1.0, np.sin(2 * k), np.cos(2 * k) - 1.0
    a = turn / TURN_SCALE_DEG
    return np.stack([a, np.ones_like(a), s1, c1, s2, c2, du, dv, du * du, du * dv, dv * dv,
                     du * s1, du * c1, dv * s1, dv * c1, a * du, a * dv], axis=-1)


@dataclass(frozen=True, eq=False)
class AlignModel(TaughtModel):
    """A trained image-alignment servo for one part.

    Attributes:
        object_kind, kappa, nominal_pose: what it was taught on.
        front: the shared preprocessing and localisation (its ``nominal_uv_px`` is the
            template's reference point in the taught frames).
        config: the servo's settings.
        template: the taught silhouette (T x T float32), its centre on the reference point.
        xy: (24, 2) coefficients of ``xy_basis`` -> (dx_mm, dy_mm).
        phi: (17,) coefficients of ``phi_basis`` -> dphi_deg.
        training: JSON-able training metadata.
    """

    file_kind: ClassVar[str] = KIND
    file_version: ClassVar[int] = FORMAT_VERSION

    config: AlignConfig
    template: np.ndarray
    xy: np.ndarray
    phi: np.ndarray
    _template: Template = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if isinstance(self.kappa, bool) or not isinstance(self.kappa, int) or self.kappa < 1:
            raise ConfigError(f"kappa: must be a whole number >= 1, got {self.kappa!r}")
        xy = np.asarray(self.xy, dtype=np.float64)
        phi = np.asarray(self.phi, dtype=np.float64).reshape(-1)
        if xy.shape != (XY_TERMS, 2) or phi.shape != (PHI_TERMS,) \
                or not (np.isfinite(xy).all() and np.isfinite(phi).all()):
            raise ConfigError(f"align model: expected finite coefficients of shapes "
                              f"({XY_TERMS}, 2) and ({PHI_TERMS},), got {xy.shape} and "
                              f"{phi.shape}")
        if self.front.nominal_uv_px is None:
            raise ConfigError("align model: the front end has no reference point "
                              "(nominal_uv_px)")
        object.__setattr__(self, "xy", xy)
        object.__setattr__(self, "phi", phi)
        object.__setattr__(self, "_template", Template(
            self.template, self.kappa, self.config.scan_step_deg, self.config.ecc_iterations,
            self.config.ecc_epsilon))
        object.__setattr__(self, "template", self._template.image)

    @property
    def feature_count(self) -> int:
        return 3  # the shift and the turn

    def register(self, image: np.ndarray) -> tuple[Localisation, Registration | None]:
        """Localise the part and register its silhouette (None where it was not found).

        Raises:
            ImageError: the frame is not HxWx3 uint8 of the training frames' size.
        """
        preprocessed, loc = self.front.locate(image)
        if not loc.ok:
            return loc, None
        return loc, self.register_silhouette(self.front.feature_frame(preprocessed, loc), loc)

    def register_silhouette(self, silhouette: np.ndarray, loc: Localisation) -> Registration:
        """Register a located frame's silhouette (``FrontEnd.feature_frame``) to the
        template, the scan laid on the blob's centre."""
        return self._template.register(silhouette, loc.u_px, loc.v_px)

    def step(self, reg: Registration) -> tuple[float, float, float]:
        """The tool step (dx_mm, dy_mm, dphi_deg) a registration reads as."""
        u0, v0 = self.front.nominal_uv_px
        du, dv = reg.u_px - u0, reg.v_px - v0
        dphi = float(phi_basis(du, dv, reg.angle_deg, self.kappa) @ self.phi)
        dx, dy = xy_basis(du, dv, dphi, self.kappa) @ self.xy
        return float(dx), float(dy), wrap_deg(dphi, 360.0 / self.kappa)

    def perceive(self, image: np.ndarray) -> AlignPercept:
        """Localisation, registration and the fitted step in one pass.

        Raises:
            ImageError: the frame is not HxWx3 uint8 of the training frames' size.
        """
        loc, reg = self.register(image)
        if reg is None:
            return AlignPercept(loc)
        return AlignPercept(loc, reg, self.step(reg))

    def system_info(self) -> dict[str, Any]:
        """The servo's own JSON: its config (``align``)."""
        return {"align": to_mapping(self.config)}

    def arrays(self) -> dict[str, np.ndarray]:
        """The template and the fits' coefficients: ``align.template``, ``align.xy``,
        ``align.phi``."""
        return {"align.template": self.template, "align.xy": self.xy, "align.phi": self.phi}

    @classmethod
    def from_file(cls, info: dict[str, Any], arrays: dict[str, np.ndarray],
                  taught: dict[str, Any]) -> AlignModel:
        """A servo from a model file's contents (see ``TaughtModel.from_file``)."""
        return cls(**taught, config=from_mapping(AlignConfig, info["align"], "align"),
                   template=arrays["align.template"], xy=arrays["align.xy"],
                   phi=arrays["align.phi"])

