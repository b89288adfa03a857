"""Feature vectors of 3D windows (paper Table 1) from summed voxel moments.

A window is a box of whole voxels ``[lo, hi)`` of a space's :class:`~engine.detection.moments.VoxelGrid`
(canonical frame, see :mod:`engine.detection.canonical`).  Its vector (:class:`~engine.detection.layout.FeatureLayout`)
is the global block (:mod:`engine.detection.global_block`), the local block of each of its ``K x K x K``
sub-boxes (:mod:`engine.detection.local_block`) and the context block (:mod:`engine.detection.context_block`).
All sums come from the integral volume of the space (:mod:`engine.detection.moments`): a window's features cost
a few hundred look-ups, independent of its points.  Design notes: ``docs/design/detection.md``.
"""
from __future__ import annotations

import numpy as np

from engine.detection import moments as mom
from engine.detection.context_block import window_context
from engine.detection.global_block import global_features
from engine.detection.layout import FeatureLayout
from engine.detection.local_block import local_features, sub_bounds


def window_features(iv: np.ndarray, grid: mom.VoxelGrid, lo: np.ndarray, hi: np.ndarray,
                    layout: FeatureLayout, chunk: int = 4096) -> np.ndarray:
    """Feature vectors ``(n, layout.size)`` of windows ``[lo, hi)`` (voxel indices ``(n, 3)``).

    Used for training samples; :mod:`engine.detection.sliding` computes the same scores for
    all positions of a window shape at once without materialising the vectors.
    """
    lo = np.asarray(lo, dtype=np.int64).reshape(-1, 3)
    hi = np.asarray(hi, dtype=np.int64).reshape(-1, 3)
    k = layout.k
    out = np.zeros((len(lo), layout.size), dtype=np.float64)
    shape = np.asarray(grid.shape)
    vox = grid.voxel
    for s in range(0, len(lo), chunk):
        l, h = lo[s:s + chunk], hi[s:s + chunk]
        w = h - l
        out[s:s + chunk, :layout.n_global] = global_features(l / shape, w / shape, w * vox,
                                                              shape * vox if layout.boundary else None)
        b = sub_bounds(w, k)  # (m, 3, k+1)
        starts = l[:, :, None] + b[:, :, :-1]
        stops = l[:, :, None] + b[:, :, 1:]
        # all K^3 sub-boxes, x-major
        ix, iy, iz = np.meshgrid(np.arange(k), np.arange(k), np.arange(k), indexing="ij")
        ix, iy, iz = ix.ravel(), iy.ravel(), iz.ravel()
        slo = np.stack([starts[:, 0, ix], starts[:, 1, iy], starts[:, 2, iz]], axis=-1)  # (m, K^3, 3)
        shi = np.stack([stops[:, 0, ix], stops[:, 1, iy], stops[:, 2, iz]], axis=-1)
        sums = mom.box_sums(iv, slo, shi)  # (m, K^3, 13)
        n_win = mom.box_sums(iv, l, h)[:, 0]
        loc = local_features(sums, n_win[:, None], k, layout.min_points)
        out[s:s + chunk, layout.n_global:layout.local_end] = loc.reshape(len(l), -1)
        if layout.context:
            out[s:s + chunk, layout.local_end:] = window_context(iv, grid, l, h)
    out[:, ~layout.mask] = 0.0
    return out
