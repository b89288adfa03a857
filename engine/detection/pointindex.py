"""A space's canonical points sorted by voxel (:class:`PointIndex`): the points of a voxel box in a few slices."""
from __future__ import annotations

import numpy as np

from engine.detection import moments as mom


class PointIndex:
    """A space's canonical points sorted by voxel, so that the points of a voxel box are a few slices.

    (Sorted once, by :func:`engine.detection.moments.voxel_order`: the refined boxes are
    few but large, floors and ceilings holding a third of the points each, and
    gathering them through the order box by box costs more than one sort.)
    """

    def __init__(self, metric: np.ndarray, grid: mom.VoxelGrid, flat: np.ndarray | None = None):
        self.grid = grid
        flat = grid.flat_index(metric) if flat is None else flat
        n_cells = int(np.prod(grid.shape))
        self.points = metric[mom.voxel_order(flat, n_cells)]
        self.offsets = np.concatenate([[0], np.cumsum(np.bincount(flat, minlength=n_cells))])

    def points_in_metric(self, lo: np.ndarray, hi: np.ndarray, at_most: int | None = None) -> np.ndarray:
        """Canonical points of the voxels that the metric box ``[lo, hi]`` touches (a superset of its points).

        ``at_most``: of more points than that, every ``ceil(n / at_most)``-th in voxel order (an even,
        deterministic subsample, for statistics that are shares and quantiles of the points).
        """
        vox = np.asarray(self.grid.voxel, dtype=np.float64)
        n = np.asarray(self.grid.shape)
        vlo = np.clip(np.floor(np.asarray(lo) / vox).astype(np.int64), 0, n - 1)
        vhi = np.clip(np.ceil(np.asarray(hi) / vox).astype(np.int64), vlo + 1, n)
        return self.points_in(vlo, vhi, at_most)

    def points_in(self, lo: np.ndarray, hi: np.ndarray, at_most: int | None = None) -> np.ndarray:
        """Canonical points ``(m, 3)`` of the voxel box ``[lo, hi)`` (``at_most``: as :meth:`points_in_metric`)."""
        nx, ny, nz = self.grid.shape
        xs, ys = np.meshgrid(np.arange(lo[0], hi[0]), np.arange(lo[1], hi[1]), indexing="ij")
        col = (xs.ravel() * ny + ys.ravel()) * nz
        start, stop = self.offsets[col + lo[2]], self.offsets[col + hi[2]]
        lengths = stop - start
        total = int(lengths.sum())
        if total == 0:
            return np.zeros((0, 3))
        first = np.cumsum(lengths) - lengths  # the rank of each run's first point among the box's points
        if at_most is not None and total > at_most:
            # every step-th of the box's points, found by rank before any is gathered
            rank = np.arange(0, total, -(-total // int(at_most)))
            run = np.searchsorted(first, rank, side="right") - 1
            return self.points[start[run] + (rank - first[run])]
        return self.points[np.repeat(start - first, lengths) + np.arange(total)]
