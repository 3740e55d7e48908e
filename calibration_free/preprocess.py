"""Image preprocessing: the max(R, G, B) channel and global intensity normalisation.

A coloured object on a grey table stands out best in the brightest of its channels (a yellow
cube has high R and G, the table is equal in all three). Normalisation then maps each image
linearly so that its mean and standard deviation equal the ones recorded at training time,
which removes global gain and offset changes of the lighting (``a * I + b`` with ``a > 0``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from calibration_free.errors import ImageError

# Below this standard deviation (grey levels) an image counts as flat: there is nothing to
# stretch, and stretching sensor noise would invent structure.
MIN_STD = 0.5


@dataclass(frozen=True)
class IntensityStats:
    """Target intensity statistics of normalised images, in grey levels.

    Attributes:
        mean: mean grey level every image is shifted to.
        std: standard deviation every image is scaled to (> 0).
    """

    mean: float
    std: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.mean) and np.isfinite(self.std) and self.std > 0.0):
            raise ImageError(f"intensity stats need a finite mean and std > 0, got "
                             f"mean={self.mean!r}, std={self.std!r}")


def check_rgb(image: np.ndarray) -> None:
    """Raise ImageError unless ``image`` is a non-empty HxWx3 uint8 array."""
    if not isinstance(image, np.ndarray):
        raise ImageError(f"image: expected a numpy array, got {type(image).__name__}")
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3 or image.size == 0:
        raise ImageError(f"image: expected HxWx3 uint8, got shape {image.shape} {image.dtype}")


def max_channel_u8(image_rgb: np.ndarray) -> np.ndarray:
    """Per-pixel max(R, G, B) of an HxWx3 uint8 image, as HxW uint8 (the fast form).

    Raises:
        ImageError: the image is not HxWx3 uint8.
    """
    check_rgb(image_rgb)
    r, g, b = cv2.split(image_rgb)
    return cv2.max(cv2.max(r, g), b)


# The image localisation binarises: the normalised max(R, G, B) (the paper's), saturation, or
# the part's colour against the table's (``calibration_free.part_colour``).
Channel = Literal["max", "saturation", "colour"]

# Below this max(R, G, B) (grey levels) saturation is divided by the floor instead: in black
# the ratio is camera noise over almost nothing.
SATURATION_FLOOR = 8


def max_and_saturation_u8(image_rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """max(R, G, B) and saturation (max - min) / max, both HxW uint8 (saturation 0..255).

    Saturation is the localisation channel that ignores illumination: a coloured part keeps it
    in the light and in a shadow (the ratio does not change when the light dims), where
    max(R, G, B) of a shaded face drops to the table's level.

    Raises:
        ImageError: the image is not HxWx3 uint8.
    """
    check_rgb(image_rgb)
    r, g, b = cv2.split(image_rgb)
    top = cv2.max(cv2.max(r, g), b)
    spread = cv2.subtract(top, cv2.min(cv2.min(r, g), b))
    return top, cv2.divide(spread, cv2.max(top, SATURATION_FLOOR), scale=255)


def max_channel(image_rgb: np.ndarray) -> np.ndarray:
    """Per-pixel max(R, G, B) of an HxWx3 uint8 image, as HxW float32 grey levels (0..255).

    Raises:
        ImageError: the image is not HxWx3 uint8.
    """
    return max_channel_u8(image_rgb).astype(np.float32)


def image_stats(gray: np.ndarray) -> IntensityStats | None:
    """Mean and standard deviation of a grey image; None when the image is flat."""
    mean, std = cv2.meanStdDev(gray)
    m, s = float(mean[0, 0]), float(std[0, 0])
    return IntensityStats(m, s) if s >= MIN_STD else None


def normalise(gray: np.ndarray, stats: IntensityStats) -> np.ndarray:
    """Map ``gray`` linearly so its mean and standard deviation become ``stats``.

    A flat image (standard deviation below ``MIN_STD`` grey levels) has no contrast to map;
    it becomes a constant image at ``stats.mean``, in which nothing will be found.

    Args:
        gray: HxW uint8 (fast) or float32 grey image.
        stats: the target statistics recorded at training time.

    Returns:
        HxW float32 normalised image.

    Raises:
        ImageError: ``gray`` is not a non-empty 2-D uint8 or float32 array, or is not finite.
    """
    if not isinstance(gray, np.ndarray) or gray.ndim != 2 or gray.size == 0 \
            or gray.dtype not in (np.uint8, np.float32):
        raise ImageError(f"grey image: expected HxW uint8 or float32, got "
                         f"{getattr(gray, 'shape', None)} {getattr(gray, 'dtype', type(gray))}")
    mean, std = cv2.meanStdDev(gray)
    m, s = float(mean[0, 0]), float(std[0, 0])
    if not np.isfinite(s):
        raise ImageError("grey image: contains NaN or infinite values")
    if s < MIN_STD:
        return np.full(gray.shape, stats.mean, dtype=np.float32)
    scale = stats.std / s
    return cv2.addWeighted(gray, scale, gray, 0.0, stats.mean - m * scale, dtype=cv2.CV_32F)


def mean_frame(images: list[np.ndarray]) -> np.ndarray:
    """The pixel-wise mean of frames of one size (uint8, rounded): where the arm stands still
    only the camera's noise differs between them (a settling look, a re-zero)."""
    total = np.zeros(images[0].shape, np.uint32)
    for image in images:
        total += image
    return ((total + len(images) // 2) // len(images)).astype(np.uint8)


def frame_groups(images: Sequence[np.ndarray], average: int) -> list[list[np.ndarray]]:
    """Consecutive groups of ``average`` frames, the last one maybe smaller."""
    return [list(images[i:i + average]) for i in range(0, len(images), average)]


def frame_means(images: Sequence[np.ndarray], average: int) -> list[np.ndarray]:
    """The means (``mean_frame``) of ``frame_groups``, as a settling look reads them;
    ``average`` 1: the frames themselves."""
    if average == 1:
        return list(images)
    return [mean_frame(group) for group in frame_groups(images, average)]
