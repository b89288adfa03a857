"""Colour normalisation of a space before its moments are summed (a feature layout's ``colour`` mode).

``"space-median"`` scales each space's colours so that the median luminance of its points is
:data:`COLOUR_TARGET`: a per-space exposure (a multiplicative factor) cancels exactly, while the contrast
between surfaces stays.  Why, and what it measured: ``docs/design/detection.md``.
"""
from __future__ import annotations

import numpy as np

#: Colour normalisations of a layout: raw colours, or scaled per space to a median luminance.
COLOUR_MODES = ("none", "space-median")
#: The median luminance of a space's points after ``"space-median"`` normalisation.
COLOUR_TARGET = 0.5


def normalise_colours(rgb: np.ndarray | None, mode: str = "space-median") -> np.ndarray | None:
    """A space's colours ``(n, 3)`` in [0, 1] normalised as ``mode`` says (see :data:`COLOUR_MODES`).

    ``"space-median"`` multiplies all colours by ``COLOUR_TARGET / median(luminance)``
    (luminance = mean of r, g, b), so that the same surfaces in a space scanned at
    any exposure give the same features; values may exceed 1.  A space without
    colours, or whose median luminance is 0, is returned unchanged.
    """
    factor = colour_factor(rgb, mode)
    if rgb is None or factor == 1.0:
        return rgb
    return np.asarray(rgb, dtype=np.float64) * factor


def colour_factor(rgb: np.ndarray | None, mode: str = "space-median") -> float:
    """The factor :func:`normalise_colours` multiplies a space's colours by (1.0 when it leaves them)."""
    if mode not in COLOUR_MODES:
        raise ValueError(f"unknown colour normalisation {mode!r}; known: {COLOUR_MODES}")
    if rgb is None or mode == "none" or len(rgb) == 0:
        return 1.0
    med = float(np.median(np.asarray(rgb, dtype=np.float64).mean(axis=1)))
    return COLOUR_TARGET / med if med > 0 else 1.0
