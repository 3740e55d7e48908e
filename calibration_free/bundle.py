"""Model bundle: everything needed to run perception for one taught object, in one file.

Format: a finepos model file (``calibration_free.model_file``: safetensors, so loading cannot
execute code; a JSON header; a sha256 over both) of kind ``gabor``. Arrays: the networks
(``nn1.*``, ``nn1_rot.*``, ``nn1_near.*``, ``nn2.*``, see ``NumpyMLP.to_arrays``). JSON:
object kind, kappa, nominal pose, the front end (``frame_px``, ``intensity``,
``localisation``: see ``FrontEnd.to_info``), Gabor configuration, ``near_mm``, the axis map
(``axis``, or null), the zero by the tool's heading (``heading_zero``, or null), training
metadata.

Saving is atomic. Loading returns a new bundle or raises BundleError; it never modifies
anything, so a failed load leaves the caller's current bundle in place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from calibration_free.axis import AxisMap
from calibration_free.errors import BundleError
from calibration_free.front_end import FrontEnd
from calibration_free.gabor import GaborConfig
from calibration_free.heading_zero import HeadingZero
from calibration_free.mlp import NumpyMLP
from calibration_free.model_file import TaughtModel
from calibration_free.stages import check_stages
from drivers.core.pose import Pose
from drivers.core.typed_config import from_mapping, to_mapping

KIND = "gabor"
FORMAT_VERSION = 11  # 2: max_elongation; 3: channel, nominal_uv_px; 4: nn1_rot; 5: nn1_near;
# 6: axis; 7: axis.ends; 8: axis.silhouette; 9: localisation.edge_fill_holes; 10: heading_zero;
# 11: heading_zero.dx_mm, dy_mm
POSE_KEYS = ("x_mm", "y_mm", "z_mm", "o_deg", "a_deg", "t_deg")


@dataclass(frozen=True, eq=False)
class ModelBundle(TaughtModel):
    """A trained perception model for one object.

    Attributes:
        object_kind: what was taught, e.g. "cube"; checked by ``load(expect_object=...)``.
        kappa: rotational symmetry count of the object (4 for the cube).
        nominal_pose: the taught grasp pose, {x_mm, y_mm, z_mm, o_deg, a_deg, t_deg}.
        front: preprocessing and localisation as trained: frame size (NN1 maps pixel
            positions, so other sizes are refused), intensity statistics, channel,
            threshold, polarity, area window, shape, and where the part appeared at the
            taught pose (``nominal_uv_px``, required here).
        gabor: the filter-bank configuration NN2's inputs come from.
        nn1: (u_px, v_px) -> (dx_mm, dy_mm) (half loops).
        nn1_rot: (u_px, v_px, sin(kappa dphi), cos(kappa dphi)) -> (dx_mm, dy_mm) over the
            whole training range (every look's translation, which knows the rotation from
            NN2).
        nn1_near: a correction of ``nn1_rot`` on the same inputs, fitted to its error on the
            samples near the taught pose (the NN2 set's range); added where ``nn1_rot`` reads
            at most ``near_mm``: where the loop makes its full loops and settles.
        near_mm: up to this translation (nn1_rot's reading, mm) the correction is added.
        nn2: Gabor features -> (sin(kappa dphi), cos(kappa dphi)).
        axis: for an elongated part, the map from its long axis to the turn near the taught
            pose (``calibration_free.axis``), which takes over from NN2 there; None: NN2
            alone.
        heading_zero: the zero by the tool's heading in the cell's light: NN2's turn and
            the translation (``calibration_free.heading_zero``, made by a re-zero with a
            heading step; the positioning loop takes it off each full look's step); None:
            one zero for every heading.
        training: JSON-able training metadata (loss curves, seconds, sample counts, seed),
            and ``stages``, where the recipe named them: the optional perception stages the
            bundle runs (``calibration_free.stages``; absent: every one whose data it has);
            one it has no data for is refused at load.
        format_version: file format version this bundle follows.
    """

    file_kind: ClassVar[str] = KIND
    file_version: ClassVar[int] = FORMAT_VERSION
    # A version-4 file has no near net: it loads with nn1_rot in its place, never used
    # (near_mm 0), so it perceives as it did; files before version 6 have no axis map, files
    # of version 6 no end map in it (no hidden-end correction: calibration_free.ends), files
    # before version 8 an axis map read on the features' silhouette, files before version 9
    # a colour edge that reads the rims of the part's holes too, files before version 10 no
    # zero by heading.
    older_versions: ClassVar[tuple[int, ...]] = (4, 5, 6, 7, 8, 9, 10)

    gabor: GaborConfig
    nn1: NumpyMLP
    nn1_rot: NumpyMLP
    nn1_near: NumpyMLP
    near_mm: float
    nn2: NumpyMLP
    axis: AxisMap | None = None
    heading_zero: HeadingZero | None = None
    format_version: int = FORMAT_VERSION

    def __post_init__(self) -> None:
        if not isinstance(self.object_kind, str) or not self.object_kind:
            raise BundleError(f"object_kind: must be a non-empty string, got "
                              f"{self.object_kind!r}")
        if isinstance(self.kappa, bool) or not isinstance(self.kappa, int) or self.kappa < 1:
            raise BundleError(f"kappa: must be a whole number >= 1, got {self.kappa!r}")
        pose = dict(self.nominal_pose)
        if sorted(pose) != sorted(POSE_KEYS) or not all(
                isinstance(v, (int, float)) and math.isfinite(v) for v in pose.values()):
            raise BundleError(f"nominal_pose: needs finite {', '.join(POSE_KEYS)}, got {pose}")
        object.__setattr__(self, "nominal_pose", {k: float(pose[k]) for k in POSE_KEYS})
        if not isinstance(self.front, FrontEnd) or self.front.nominal_uv_px is None:
            raise BundleError(f"front: needs a FrontEnd with nominal_uv_px, got {self.front!r}")
        if self.nn1.layer_sizes[0] != 2 or self.nn1.n_outputs != 2:
            raise BundleError(f"nn1: must map 2 inputs to 2 outputs, has layers "
                              f"{self.nn1.layer_sizes}")
        for name in ("nn1_rot", "nn1_near"):
            net = getattr(self, name)
            if net.layer_sizes[0] != 4 or net.n_outputs != 2:
                raise BundleError(f"{name}: must map 4 inputs to 2 outputs, has layers "
                                  f"{net.layer_sizes}")
        if isinstance(self.near_mm, bool) or not isinstance(self.near_mm, (int, float)) \
                or not (math.isfinite(self.near_mm) and self.near_mm >= 0.0):
            raise BundleError(f"near_mm: must be a finite number >= 0, got {self.near_mm!r}")
        if self.axis is not None and (not isinstance(self.axis, AxisMap)
                                      or self.axis.kappa != self.kappa):
            raise BundleError(f"axis: must be an axis map of the part's kappa {self.kappa}")
        stages = self.training.get("stages")
        if stages is not None and not (isinstance(stages, (list, tuple))
                                       and all(isinstance(s, str) for s in stages)):
            raise BundleError(f"training.stages: must be a list of stage names, got {stages!r}")
        check_stages(stages, self.axis, self.front)
        if self.heading_zero is not None and not isinstance(self.heading_zero, HeadingZero):
            raise BundleError("heading_zero: must be a HeadingZero or None")
        if self.nn2.n_inputs != self.gabor.n_filters or self.nn2.n_outputs != 2:
            raise BundleError(f"nn2: must map {self.gabor.n_filters} features to 2 outputs, "
                              f"has layers {self.nn2.layer_sizes}")

    @property
    def pose(self) -> Pose:
        """The nominal pose as a ``drivers.core.pose.Pose``."""
        return Pose(**self.nominal_pose)

    def system_info(self) -> dict[str, Any]:
        """The Gabor system's own JSON: the filter-bank configuration (``gabor``), where
        the near translation net takes over (``near_mm``), the axis map (``axis``) and the
        zero by heading (``heading_zero``).

        Returns:
            {"gabor": ..., "near_mm": ..., "axis": ..., "heading_zero": ...}, merged into the
            file's JSON by ``to_info``.
        """
        return {"gabor": to_mapping(self.gabor), "near_mm": float(self.near_mm),
                "axis": None if self.axis is None else self.axis.to_info(),
                "heading_zero": None if self.heading_zero is None
                else self.heading_zero.to_info()}

    def arrays(self) -> dict[str, np.ndarray]:
        """The networks' weights as named arrays (what the file stores besides the JSON).

        Returns:
            ``nn1.*``, ``nn1_rot.*``, ``nn1_near.*`` and ``nn2.*`` (``NumpyMLP.to_arrays``).
        """
        return {**self.nn1.to_arrays("nn1"), **self.nn1_rot.to_arrays("nn1_rot"),
                **self.nn1_near.to_arrays("nn1_near"), **self.nn2.to_arrays("nn2")}

    @classmethod
    def from_file(cls, info: dict[str, Any], arrays: dict[str, np.ndarray],
                  taught: dict[str, Any]) -> ModelBundle:
        """A bundle from a model file's contents (see ``TaughtModel.from_file``)."""
        nn1_rot = NumpyMLP.from_arrays(arrays, "nn1_rot")
        if info["format_version"] == 4:
            nn1_near, near_mm = nn1_rot, 0.0
        else:
            nn1_near, near_mm = NumpyMLP.from_arrays(arrays, "nn1_near"), info["near_mm"]
        axis = None
        if info["format_version"] >= 6 and info.get("axis") is not None:
            axis = AxisMap.from_info(info["axis"])
        heading_zero = None
        if info["format_version"] >= 10 and info.get("heading_zero") is not None:
            heading_zero = HeadingZero.from_info(info["heading_zero"])
        return cls(**taught, gabor=from_mapping(GaborConfig, info["gabor"], "gabor"),
                   nn1=NumpyMLP.from_arrays(arrays, "nn1"), nn1_rot=nn1_rot,
                   nn1_near=nn1_near, near_mm=near_mm, nn2=NumpyMLP.from_arrays(arrays, "nn2"),
                   axis=axis, heading_zero=heading_zero, format_version=info["format_version"])
