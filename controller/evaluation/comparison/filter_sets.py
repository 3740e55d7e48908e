"""The Gabor filter configurations the Fig. 5 search compares, by name.

A name reads ``<grid>x<grid>x<orientations>-l<lambda_px>-s<sigma_px>-<kind>``. Grid centres sit
12 px apart, centred in the 50 px ROI (3x3: 13, 25, 37 px; reading note 1); n orientations are
spread evenly over 180 deg. The set varies one factor at a time around the paper's winner
(``3x3x4-l30-s12.5-even``): grid size, orientation count, wavelength (with the envelope fixed
and scaled along), envelope width, and the kernel's phase; plus a few combinations the paper's
bar plot suggests (small and large banks, magnitude responses).
"""

from __future__ import annotations

from calibration_free.gabor import GaborConfig, Kind
from drivers.core.errors import ConfigError

PAPER_SET = "3x3x4-l30-s12.5-even"
ROI_PX = 50
SPACING_PX = 12.0

# (grid, orientations, lambda_px, sigma_px, kind)
_SETS: tuple[tuple[int, int, float, float, Kind], ...] = (
    (3, 4, 30.0, 12.5, "even"),  # the paper's winner
    (1, 4, 30.0, 12.5, "even"),
    (2, 4, 30.0, 12.5, "even"),
    (4, 4, 30.0, 12.5, "even"),
    (3, 2, 30.0, 12.5, "even"),
    (3, 8, 30.0, 12.5, "even"),
    (3, 4, 15.0, 12.5, "even"),
    (3, 4, 60.0, 12.5, "even"),
    (3, 4, 15.0, 6.25, "even"),
    (3, 4, 60.0, 25.0, "even"),
    (3, 4, 30.0, 6.25, "even"),
    (3, 4, 30.0, 25.0, "even"),
    (3, 4, 30.0, 12.5, "odd"),
    (3, 4, 30.0, 12.5, "magnitude"),
    (1, 8, 30.0, 12.5, "magnitude"),
    (1, 8, 60.0, 25.0, "even"),
    (2, 8, 15.0, 6.25, "even"),
    (4, 8, 15.0, 6.25, "even"),
)


def grid_centres_px(n: int) -> tuple[float, ...]:
    """n centres SPACING_PX apart, centred in the ROI."""
    return tuple(ROI_PX / 2 + SPACING_PX * (i - (n - 1) / 2) for i in range(n))


def orientations_deg(n: int) -> tuple[float, ...]:
    """n orientations evenly over [0, 180) deg."""
    return tuple(180.0 * i / n for i in range(n))


def set_name(grid: int, orientations: int, lambda_px: float, sigma_px: float,
             kind: Kind) -> str:
    """The set's name, ``<grid>x<grid>x<orientations>-l<lambda_px>-s<sigma_px>-<kind>``."""
    return f"{grid}x{grid}x{orientations}-l{lambda_px:g}-s{sigma_px:g}-{kind}"


def gabor_config(grid: int, orientations: int, lambda_px: float, sigma_px: float,
                 kind: Kind) -> GaborConfig:
    """The Gabor bank of a grid x grid layout with n orientations (see the module docstring)."""
    return GaborConfig(centres_px=grid_centres_px(grid),
                       orientations_deg=orientations_deg(orientations), lambda_px=lambda_px,
                       sigma_px=sigma_px, kind=kind, roi_px=ROI_PX)


FILTER_SETS: dict[str, GaborConfig] = {set_name(*s): gabor_config(*s) for s in _SETS}


def select_sets(names: list[str] | None) -> dict[str, GaborConfig]:
    """The named sets in the given order (None: all of FILTER_SETS).

    Raises:
        ConfigError: a name is not in FILTER_SETS.
    """
    if names is None:
        return dict(FILTER_SETS)
    unknown = [n for n in names if n not in FILTER_SETS]
    if unknown:
        raise ConfigError(f"--sets: unknown filter set {unknown[0]!r} (known: "
                          f"{', '.join(FILTER_SETS)})")
    return {n: FILTER_SETS[n] for n in names}
