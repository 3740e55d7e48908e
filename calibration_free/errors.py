"""Typed errors raised by the calibration-free perception and learning code."""

from drivers.core.errors import FineposError


class ImageError(FineposError, ValueError):
    """An image or array has the wrong shape, dtype or contents for the stage it was given to."""


class DatasetError(FineposError):
    """A dataset file cannot be read or its contents are inconsistent."""


class BundleError(FineposError):
    """A model bundle is corrupt, truncated, of an unsupported version or for another object."""


class TrainingError(FineposError):
    """Training cannot proceed: too few usable samples or inconsistent training data."""
