"""Depth of detections that sit in a wall: doors as deep as their points, not as a voxel.

After NMS, along each horizontal axis where such a detection is at most ``reveal-thin-voxels`` voxels deep,
its extent becomes the span (``reveal-quantile`` quantiles) of the points in the box grown by ``reveal-grow``
metres along that axis, without its bottom and top voxel layers.  Solid elements (``solid-classes``: columns,
bookcases) get their horizontal sides the same way, but a side moves only where the points stop inside the
grown box (a face).  Settings: ``buildingparser.detection.reveal-*`` and ``solid-*``
(``engine/detection/detection.yaml``).  Why, and what it measured: ``docs/design/detection.md``.
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
