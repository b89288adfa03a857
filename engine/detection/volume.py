"""A space ready for windows (:class:`SpaceVolume`): its canonical frame, voxel grid and integral volume of moments."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from engine.detection import moments as mom
from engine.detection.colours import colour_factor
from engine.detection.context_block import CONTEXT_CHANNELS, context_bounds


@dataclass
class SpaceVolume:
    """One space ready for windows: its canonical frame, voxel grid and integral volume of moments."""

    frame: Any  # engine.detection.canonical.CanonicalFrame
    grid: mom.VoxelGrid
    iv: np.ndarray
    n_points: int

    @property
    def count_iv(self) -> np.ndarray:
        """The integral volume of point counts alone ``(nx+1, ny+1, nz+1, 1)``, contiguous (made once)."""
        return self._channels_iv("_count_iv", (0,))

    @property
    def context_iv(self) -> np.ndarray:
        """The integral volume of :data:`CONTEXT_CHANNELS` alone ``(nx+1, ny+1, nz+1, 4)``, contiguous (made once)."""
        return self._channels_iv("_context_iv", CONTEXT_CHANNELS)

    @property
    def context_range(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds ``(15,)`` of every window's context block in this space (:func:`context_bounds`; made once)."""
        return self._derived("_context_range", lambda: context_bounds(self.context_iv))

    def _channels_iv(self, key: str, channels: tuple[int, ...]) -> np.ndarray:
        """A contiguous copy of some channels of ``iv``, cached under ``key`` until ``iv`` is replaced."""
        return self._derived(key, lambda: np.ascontiguousarray(self.iv[..., list(channels)]))

    def _derived(self, key: str, make: Callable[[], Any]) -> Any:
        """``make()``, cached under ``key`` until ``iv`` is replaced."""
        cached = self.__dict__.get(key)
        if cached is None or cached[0] is not self.iv:
            cached = self.__dict__[key] = (self.iv, make())
        return cached[1]

    @classmethod
    def build(cls, xyz: np.ndarray, rgb: np.ndarray | None, frame: Any, voxel: float,
              max_cells: int, colour: str = "none") -> SpaceVolume:
        """Accumulate the moments of a space's points (``xyz`` in the frame's coordinates, ``rgb`` in [0, 1]).

        ``colour`` normalises the colours first (:func:`engine.detection.colours.normalise_colours`; a model's ``layout.colour``).
        """
        grid = mom.VoxelGrid.covering(frame.extent, voxel, max_cells)
        return cls.from_metric(frame.to_metric(xyz), rgb, frame, grid, colour)

    @classmethod
    def from_metric(cls, metric: np.ndarray, rgb: np.ndarray | None, frame: Any, grid: mom.VoxelGrid,
                    colour: str = "none", flat: np.ndarray | None = None) -> SpaceVolume:
        """:meth:`build` from points already in canonical metres (``frame.to_metric``) on a chosen grid.

        ``flat`` is their :meth:`engine.detection.moments.VoxelGrid.flat_index` when the caller has it.
        The colours are scaled by :func:`colour_factor` column by column as they are summed
        (the same values as :func:`engine.detection.colours.normalise_colours`, without a normalised copy).
        """
        m = mom.voxel_moments(metric, rgb, grid, flat, rgb_scale=colour_factor(rgb, colour))
        return cls(frame, grid, mom.integral_volume(m), int(len(metric)))

    def voxel_box(self, position: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit-cube boxes ``(n, 3)`` snapped to voxel boxes ``[lo, hi)`` inside the grid.

        Ends are rounded to the nearest voxel boundary; a box thinner than that
        along an axis becomes the one voxel holding its centre.
        """
        shape = np.asarray(self.grid.shape)
        p = np.asarray(position, dtype=np.float64) * shape
        q = (np.asarray(position, dtype=np.float64) + np.asarray(size, dtype=np.float64)) * shape
        lo = np.round(p).astype(np.int64)
        hi = np.round(q).astype(np.int64)
        thin = hi <= lo
        centre = np.floor((p + q) / 2.0).astype(np.int64)
        lo = np.where(thin, centre, lo)
        hi = np.where(thin, centre + 1, hi)
        lo = np.clip(lo, 0, shape - 1)
        hi = np.clip(hi, lo + 1, shape)
        return lo, hi
