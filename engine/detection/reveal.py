"""Depth of detections that sit in a wall: doors as deep as their points, not as a voxel.

A door's ground truth spans its frame from the wall's middle to the casing
proud of the face (11-24 cm), a board's from its face to the wall behind it
(10 cm): about one voxel of the detector's 0.1 m grid, so a window placed one
voxel off along the wall's normal overlaps it by nothing, and one placed right
by at most the voxel's share of the depth.  After NMS, along each horizontal
axis where such a detection is at most ``reveal-thin-voxels`` voxels deep, its extent
becomes the span of the points in the box grown by ``reveal-grow`` metres on
both sides along that axis, without its bottom and top voxel layers (the floor
in front of a door, a ceiling), from the ``reveal-quantile`` to the ``1 -
reveal-quantile`` quantile of their coordinates (a few stray points do not
widen it): the
jambs behind the wall face, the casing and the leaf of a door; the board and
nothing behind it.  The box never shrinks below half its voxel depth, and its
position along the wall, its height and its score are unchanged.

Solid elements (``solid-classes``: columns, bookcases) get their horizontal extent the same
way along both horizontal axes, but a side moves only where the points stop
inside the grown box (a face); where they run on to within ``solid-edge`` of its
edge, a surface continues there (the wall a pilaster stands against) and the
window's side stays.  A 10 cm grid places a 25-35 cm column's sides to a voxel:
on held-out generated buildings, column AP 13.6 -> 26.1 and 13.9 -> 25.5; bookcase
AP 53.3 -> 57.8 on one pair of buildings, unchanged on two others.

Settings: ``buildingparser.detection.reveal-*`` and ``solid-*`` (``engine/detection/detection.yaml``).  On for doors
only: on held-out generated buildings it raised door AP from 0.7 to 6.1 and did
not help boards (0.1 to 0) or windows (62.6 to 59.2; a window's sill board and
frame are not its reveal's depth).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from engine import config
from tiles.classes import ELEMENT_CLASSES, element_class_list


@dataclass
class RevealSettings:
    """Which classes get their depth from their points, and how (``detection.reveal-*``)."""

    classes: tuple[str, ...] = ("door",)
    grow: float = 0.1
    quantile: float = 0.01
    thin_voxels: int = 2
    solid_classes: tuple[str, ...] = ()
    solid_edge: float = 0.02

    def __post_init__(self) -> None:
        self.classes = element_class_list(self.classes, "reveal-classes")
        self.solid_classes = element_class_list(self.solid_classes, "solid-classes")
        if self.grow < 0 or not 0 <= self.quantile < 0.5 or self.thin_voxels < 0 or self.solid_edge < 0:
            raise ValueError("need reveal-grow >= 0, 0 <= reveal-quantile < 0.5, thin-voxels >= 0, solid-edge >= 0")

    @classmethod
    def from_config(cls, **overrides: Any) -> RevealSettings:
        kw = config.settings_fields(cls, "detection", keys={
            "classes": "reveal-classes", "grow": "reveal-grow", "quantile": "reveal-quantile",
            "thin_voxels": "reveal-thin-voxels", "solid_classes": "solid-classes", "solid_edge": "solid-edge"})
        kw.update(overrides)
        return cls(**kw)

    @property
    def codes(self) -> list[int]:
        return [ELEMENT_CLASSES.index(c) for c in self.classes]

    @property
    def solid_codes(self) -> list[int]:
        return [ELEMENT_CLASSES.index(c) for c in self.solid_classes]


def point_span(values: np.ndarray, lo: float, hi: float, quantile: float, min_size: float) -> tuple[float, float]:
    """The ``[quantile, 1 - quantile]`` span of ``values`` (at least ``min_size`` wide), else ``(lo, hi)``."""
    if len(values) < 3:
        return lo, hi
    a, b = (float(x) for x in np.quantile(values, [quantile, 1.0 - quantile]))
    if b - a < min_size:
        mid = (a + b) / 2.0
        a, b = mid - min_size / 2.0, mid + min_size / 2.0
    return a, b


def refine_reveals(lo: np.ndarray, hi: np.ndarray, lo_m: np.ndarray, hi_m: np.ndarray, class_code: np.ndarray,
                   grid: Any, index: Any, settings: RevealSettings | None = None) -> None:
    """Set in place the depth (``lo_m``, ``hi_m``, canonical metres) of thin detections of the reveal classes,
    and the horizontal sides of detections of the solid classes.

    Parameters
    ----------
    lo, hi
        ``(n, 3)`` voxel boxes of the detections (not changed).
    lo_m, hi_m
        ``(n, 3)`` their boxes in canonical metres, changed along the refined axes.
    class_code
        ``(n,)`` their classes.
    grid, index
        The space's :class:`engine.detection.moments.VoxelGrid` and :class:`engine.detection.pointindex.PointIndex`.
    settings
        Default: :meth:`RevealSettings.from_config`.
    """
    settings = settings or RevealSettings.from_config()
    if not len(class_code):
        return
    vox = np.asarray(grid.voxel)
    n = np.asarray(grid.shape)
    for i in np.nonzero(np.isin(class_code, settings.codes))[0]:
        for a in (0, 1):  # horizontal axes: the wall's normal
            if hi[i, a] - lo[i, a] > settings.thin_voxels or hi[i, a] - lo[i, a] >= n[a]:
                continue
            blo, bhi = _grown(lo[i], hi[i], a, settings.grow, vox, n)
            pts = index.points_in(blo, bhi)[:, a]
            lo_m[i, a], hi_m[i, a] = point_span(pts, lo_m[i, a], hi_m[i, a], settings.quantile, 0.5 * vox[a])
    for i in np.nonzero(np.isin(class_code, settings.solid_codes))[0]:
        for a in (0, 1):
            if hi[i, a] - lo[i, a] >= n[a]:
                continue
            blo, bhi = _grown(lo[i], hi[i], a, settings.grow, vox, n)
            pts = index.points_in(blo, bhi)[:, a]
            if len(pts) < 3:
                continue
            qa, qb = (float(x) for x in np.quantile(pts, [settings.quantile, 1.0 - settings.quantile]))
            # a side moves only where the points stop inside the grown box: else a surface runs on
            a_lo = qa if qa > blo[a] * vox[a] + settings.solid_edge else lo_m[i, a]
            a_hi = qb if qb < bhi[a] * vox[a] - settings.solid_edge else hi_m[i, a]
            if a_hi - a_lo >= 0.5 * vox[a]:
                lo_m[i, a], hi_m[i, a] = a_lo, a_hi


def _grown(lo: np.ndarray, hi: np.ndarray, a: int, grow: float, vox: np.ndarray,
           n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A voxel box grown by ``grow`` metres along axis ``a`` (within the grid), without its bottom and top
    voxel layers when it has three or more (the floor in front, the ceiling)."""
    g = int(np.ceil(grow / vox[a] - 1e-9))
    blo, bhi = lo.copy(), hi.copy()
    blo[a], bhi[a] = max(lo[a] - g, 0), min(hi[a] + g, n[a])
    if bhi[2] - blo[2] >= 3:
        blo[2], bhi[2] = blo[2] + 1, bhi[2] - 1
    return blo, bhi
