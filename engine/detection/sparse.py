"""Spaces too sparse to be scanned rooms: no elements are detected in them.

A parse leaves, beside its rooms, spaces made of stray points: flying pixels
and window reflections outside the walls, a few points cut off in a corner.
They hold well under 1 % of a building's points, yet each gets a floor and a
ceiling (``one-per-space-always``) and, in a frame fitted to a few hundred
points, dozens of beams and columns.  What they lack is what every scanned
room has: its floor and ceiling under every part of its footprint.

So a space's density is its point count over its footprint's area, and it is
compared with the *typical* space's: the point-weighted median density, the
density of the space that holds the building's median point.  Stray spaces
cannot move it, however many there are, because they hold so few points.  A
space under ``detection.min-space-density`` of it is left without elements
(its points stay in it, labelled clutter).  The value and its measurements:
``engine/detection/detection.yaml`` and ``docs/experiments/detection.md``.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np


def space_densities(doc: Mapping[str, Any]) -> dict[int, tuple[int, float]]:
    """Per space of a spaces document (``meta/spaces``): its point count and points per m² of its footprint.

    A space with no footprint area has an infinite density (it cannot be called sparse).
    """
    out: dict[int, tuple[int, float]] = {}
    for sp in doc.get("spaces", []):
        n, area = int(sp.get("point_count", 0)), float(sp.get("area_m2", 0.0))
        out[int(sp["id"])] = (n, n / area if area > 0 else np.inf)
    return out


def point_median(values: np.ndarray, counts: np.ndarray) -> float:
    """The value of the item (a space, a histogram bin) that holds the median point, items ordered by value and
    weighted by their point ``counts`` (NaN: no points)."""
    values, counts = np.asarray(values, dtype=np.float64), np.asarray(counts, dtype=np.float64)
    if counts.sum() <= 0:
        return float("nan")
    order = np.argsort(values, kind="stable")
    cum = np.cumsum(counts[order])
    return float(values[order][np.searchsorted(cum, 0.5 * cum[-1])])


def typical_density(densities: Mapping[int, tuple[int, float]]) -> float:
    """The point-weighted median density: the density of the space holding the median point (NaN: no points)."""
    return point_median(np.array([d for _, d in densities.values()], dtype=np.float64),
                        np.array([n for n, _ in densities.values()], dtype=np.float64))


def sparse_spaces(doc: Mapping[str, Any] | None, ratio: float) -> dict[int, tuple[int, float]]:
    """The spaces whose density is under ``ratio`` times the typical one, with their point count and relative density.

    ``ratio`` 0 (or no document) finds none.
    """
    if not doc or ratio <= 0:
        return {}
    dens = space_densities(doc)
    typical = typical_density(dens)
    if not np.isfinite(typical) or typical <= 0:
        return {}
    return {i: (n, d / typical) for i, (n, d) in dens.items() if d < ratio * typical}
