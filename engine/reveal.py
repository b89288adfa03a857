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

Settings: ``buildingparser.detection.reveal-*`` (``engine/detection.yaml``).  On for doors
only: on held-out generated buildings it raised door AP from 0.7 to 6.1 and did
not help boards (0.1 to 0) or windows (62.6 to 59.2; a window's sill board and
frame are not its reveal's depth).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from engine import config
from tiles.classes import ELEMENT_CLASSES


@dataclass
class RevealSettings:
    """Which classes get their depth from their points, and how (``detection.reveal-*``)."""

    classes: tuple[str, ...] = ("door",)
    grow: float = 0.1
    quantile: float = 0.01
    thin_voxels: int = 2

    def __post_init__(self) -> None:
        v = self.classes
        v = tuple(c.strip() for c in v.split(",") if c.strip()) if isinstance(v, str) else tuple(v)
        bad = [c for c in v if c not in ELEMENT_CLASSES]
        if bad:
            raise ValueError(f"reveal-classes: unknown element class(es) {', '.join(bad)}")
        self.classes = v
        if self.grow < 0 or not 0 <= self.quantile < 0.5 or self.thin_voxels < 0:
            raise ValueError("need reveal-grow >= 0, 0 <= reveal-quantile < 0.5, thin-voxels >= 0")

    @classmethod
    def from_config(cls, **overrides: Any) -> "RevealSettings":
        kw: dict[str, Any] = {}
        for name, key in (("classes", "reveal-classes"), ("grow", "reveal-grow"), ("quantile", "reveal-quantile"),
                          ("thin_voxels", "reveal-thin-voxels")):
            v = config.get(f"detection.{key}")
            if v is not None:
                kw[name] = v if name == "classes" else type(getattr(cls, name))(v)
        kw.update(overrides)
        return cls(**kw)

    @property
    def codes(self) -> list[int]:
        return [ELEMENT_CLASSES.index(c) for c in self.classes]


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
    """Set in place the depth (``lo_m``, ``hi_m``, canonical metres) of thin detections of the reveal classes.

    Parameters
    ----------
    lo, hi
        ``(n, 3)`` voxel boxes of the detections (not changed).
    lo_m, hi_m
        ``(n, 3)`` their boxes in canonical metres, changed along the refined axes.
    class_code
        ``(n,)`` their classes.
    grid, index
        The space's :class:`engine.moments.VoxelGrid` and :class:`engine.detection.PointIndex`.
    settings
        Default: :meth:`RevealSettings.from_config`.
    """
    settings = settings or RevealSettings.from_config()
    if not settings.classes or not len(class_code):
        return
    vox = np.asarray(grid.voxel)
    n = np.asarray(grid.shape)
    for i in np.nonzero(np.isin(class_code, settings.codes))[0]:
        for a in (0, 1):  # horizontal axes: the wall's normal
            if hi[i, a] - lo[i, a] > settings.thin_voxels or hi[i, a] - lo[i, a] >= n[a]:
                continue
            g = int(np.ceil(settings.grow / vox[a] - 1e-9))
            blo, bhi = lo[i].copy(), hi[i].copy()
            blo[a], bhi[a] = max(lo[i, a] - g, 0), min(hi[i, a] + g, n[a])
            if bhi[2] - blo[2] >= 3:  # not the bottom and top layers: the floor in front, the ceiling
                blo[2], bhi[2] = blo[2] + 1, bhi[2] - 1
            pts = index.points_in(blo, bhi)[:, a]
            lo_m[i, a], hi_m[i, a] = point_span(pts, lo_m[i, a], hi_m[i, a], settings.quantile, 0.5 * vox[a])
