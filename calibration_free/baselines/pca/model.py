"""The trained PCA system (paper sections 2.2 and 4.2) and its perception of one frame.

Translation as in the Gabor system: the shared front end finds the object's centroid and NN1
(the Gabor system's 2-3-2 MLP) maps it to (dx, dy). Rotation: the ROI around the centroid,
as a unit vector (``eigenimages.roi_vector``), is projected on m eigenimages and the B-spline
neuro-fuzzy controller maps the m projections to (sin, cos) of kappa dphi, decoded with the
Gabor system's angle codec.

File: ``model_file`` with kind "pca"; arrays ``nn1.*`` (``NumpyMLP.to_arrays``),
``pca.mean``, ``pca.basis``, ``pca.singular_values``, ``fc.lo``, ``fc.hi``, ``fc.consequents``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from calibration_free import angles
from calibration_free.baselines.pca.eigenimages import Eigenimages, roi_vector
from calibration_free.baselines.pca.fuzzy_controller import MAX_RULES, BSplineFuzzyController
from calibration_free.localise import Localisation
from calibration_free.mlp import NumpyMLP
from calibration_free.model_file import TaughtModel
from calibration_free.roi import ROI_PX, extract_roi
from drivers.core.errors import ConfigError
from drivers.core.typed_config import from_mapping, to_mapping

KIND = "pca"
FORMAT_VERSION = 1


@dataclass(frozen=True)
class PcaConfig:
    """Config of the PCA system.

    Attributes:
        eigenimages: m, the number of eigenimages (features); the paper used 3.
        roi_px: side of the ROI the eigenimages are computed on (the Gabor system's 50 px).
        fuzzy_sets: fuzzy sets (B-spline membership functions) per feature; the controller
            has fuzzy_sets ** eigenimages rules.
        fuzzy_order: B-spline order of the membership functions (2 triangular, 3 quadratic).
        smoothing: weight of the smoothness penalty on neighbouring rules' consequents.
    """

    eigenimages: int = field(default=3, metadata={"min": 1})
    roi_px: int = field(default=ROI_PX, metadata={"min": 4})
    fuzzy_sets: int = field(default=5, metadata={"min": 2})
    fuzzy_order: int = field(default=3, metadata={"min": 1})
    smoothing: float = field(default=1e-3, metadata={"min": 0.0})

    def __post_init__(self) -> None:
        if self.fuzzy_order > self.fuzzy_sets:
            raise ConfigError(f"pca.fuzzy_order: must be <= fuzzy_sets ({self.fuzzy_sets}), "
                              f"got {self.fuzzy_order}")
        if self.fuzzy_sets ** self.eigenimages > MAX_RULES:
            raise ConfigError(f"pca: {self.fuzzy_sets} fuzzy sets on {self.eigenimages} "
                              f"eigenimages make {self.fuzzy_sets ** self.eigenimages} rules, "
                              f"more than {MAX_RULES}; lower fuzzy_sets or eigenimages")


@dataclass(frozen=True)
class PcaPercept:
    """What the PCA system saw in one frame.

    Attributes:
        localisation: where the object is, or why it was not found.
        nn1_mm: NN1's (dx_mm, dy_mm); None unless the object was found.
        features: the m eigenimage projections; None unless found and rotation was asked for.
        fc_sc: the fuzzy controller's (sin, cos) of kappa dphi; None like ``features``.
        dphi_deg: the corrective rotation; None like ``features``.
        normalised: the normalised frame the ROI is cut from (kept for ``rotation``).
    """

    localisation: Localisation
    nn1_mm: tuple[float, float] | None
    features: np.ndarray | None = None
    fc_sc: tuple[float, float] | None = None
    dphi_deg: float | None = None
    normalised: np.ndarray | None = field(default=None, repr=False, compare=False)


@dataclass(frozen=True, eq=False)
class PcaModel(TaughtModel):
    """A trained PCA system for one part.

    Attributes:
        object_kind, kappa, nominal_pose: what it was taught on.
        front: the shared preprocessing and localisation.
        config: the PCA system's settings.
        nn1: (u_px, v_px) -> (dx_mm, dy_mm).
        eigen: the eigenimages of the training ROIs.
        controller: m projections -> (sin, cos) of kappa dphi.
        training: JSON-able training metadata (seconds, samples, explained variance...).
    """

    file_kind: ClassVar[str] = KIND
    file_version: ClassVar[int] = FORMAT_VERSION

    config: PcaConfig
    nn1: NumpyMLP
    eigen: Eigenimages
    controller: BSplineFuzzyController

    def __post_init__(self) -> None:
        n = self.config.roi_px ** 2
        if self.eigen.mean.size != n or self.eigen.m != self.config.eigenimages:
            raise ConfigError(f"pca model: {self.eigen.m} eigenimages of "
                              f"{self.eigen.mean.size} px do not match the config "
                              f"({self.config.eigenimages} of {n} px)")
        if self.controller.n_inputs != self.eigen.m or self.controller.consequents.shape[1] != 2:
            raise ConfigError("pca model: the controller must map the m projections to 2 "
                              "outputs")
        if self.nn1.layer_sizes[0] != 2 or self.nn1.n_outputs != 2:
            raise ConfigError(f"pca model: nn1 must map 2 inputs to 2 outputs, has "
                              f"{self.nn1.layer_sizes}")
        if isinstance(self.kappa, bool) or not isinstance(self.kappa, int) or self.kappa < 1:
            raise ConfigError(f"kappa: must be a whole number >= 1, got {self.kappa!r}")

    @property
    def feature_count(self) -> int:
        return self.eigen.m

    def features(self, normalised: np.ndarray, u_px: float, v_px: float) -> np.ndarray:
        """The m eigenimage projections of the ROI centred on (u_px, v_px)."""
        roi = extract_roi(normalised, u_px, v_px, self.config.roi_px)
        return self.eigen.project(roi_vector(roi))

    def translation(self, image: np.ndarray) -> PcaPercept:
        """Translation only (NN1); the percept keeps the normalised frame for ``rotation``.

        Raises:
            ImageError: the frame is not HxWx3 uint8 of the training frames' size.
        """
        normalised, loc = self.front.locate(image)
        if not loc.ok:
            return PcaPercept(loc, None)
        dx, dy = self.nn1(np.array((loc.u_px, loc.v_px)))
        return PcaPercept(loc, (float(dx), float(dy)), normalised=normalised)

    def rotation(self, percept: PcaPercept) -> PcaPercept:
        """Go on from a ``translation`` percept of the same frame: eigenimage projections of
        the ROI -> fuzzy controller -> dphi. A percept without the object is returned as is.

        Raises:
            ValueError: the percept is not one of ``translation``'s (no frame kept).
        """
        if percept.nn1_mm is None:
            return percept
        if percept.normalised is None:
            raise ValueError("rotation: needs the percept that translation() returned")
        loc = percept.localisation
        features = self.features(percept.normalised, loc.u_px, loc.v_px)
        s, c = self.controller(features)
        return dataclasses.replace(percept, features=features, fc_sc=(float(s), float(c)),
                                   dphi_deg=float(angles.decode(float(s), float(c),
                                                                self.kappa)))

    def perceive(self, image: np.ndarray) -> PcaPercept:
        """Translation (NN1) and rotation (eigenimages + fuzzy controller) in one pass.

        Raises:
            ImageError: the frame is not HxWx3 uint8 of the training frames' size.
        """
        return self.rotation(self.translation(image))

    def system_info(self) -> dict[str, Any]:
        """The PCA system's own JSON: its config (``pca``) and the controller's shape
        (``fuzzy``).

        Returns:
            A JSON-able dict, merged into the file's JSON by ``to_info``.
        """
        return {"pca": to_mapping(self.config),
                "fuzzy": {"n_sets": self.controller.n_sets, "order": self.controller.order}}

    def arrays(self) -> dict[str, np.ndarray]:
        """NN1, the eigenimages and the fuzzy controller as named arrays.

        Returns:
            ``nn1.*``, ``pca.mean``, ``pca.basis``, ``pca.singular_values``, ``fc.lo``,
            ``fc.hi``, ``fc.consequents``.
        """
        return {**self.nn1.to_arrays("nn1"), "pca.mean": self.eigen.mean,
                "pca.basis": self.eigen.basis,
                "pca.singular_values": self.eigen.singular_values,
                "fc.lo": self.controller.lo, "fc.hi": self.controller.hi,
                "fc.consequents": self.controller.consequents}

    @classmethod
    def from_file(cls, info: dict[str, Any], arrays: dict[str, np.ndarray],
                  taught: dict[str, Any]) -> PcaModel:
        """A PCA model from a model file's contents (see ``TaughtModel.from_file``)."""
        return cls(**taught, config=from_mapping(PcaConfig, info["pca"], "pca"),
                   nn1=NumpyMLP.from_arrays(arrays, "nn1"),
                   eigen=Eigenimages(arrays["pca.mean"], arrays["pca.basis"],
                                     arrays["pca.singular_values"]),
                   controller=BSplineFuzzyController(arrays["fc.lo"], arrays["fc.hi"],
                                                     int(info["fuzzy"]["n_sets"]),
                                                     int(info["fuzzy"]["order"]),
                                                     arrays["fc.consequents"]))
