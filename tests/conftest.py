"""Fixtures shared across test folders."""

from tests.synthetic_scene import cell, grids  # noqa: F401  (pytest fixtures)
