"""Per-voxel point moments and their integral volumes: the one pass over a space's points.

Every feature of Table 1 is a function of a few sums over the points of a box:
the count, the sums of coordinates, of their outer products and of colours.
These sums are additive, so they are accumulated once per fine voxel
(:func:`voxel_moments`, one ``bincount`` per channel) and turned into an
integral volume (cumulative sums along the three axes, :func:`integral_volume`);
the sums over any box of whole voxels then cost eight look-ups
(:func:`box_sums`, :func:`box_sums_grid`) however many points it holds.  From
the sums, :func:`covariance` and :func:`smallest_eigen` give the normal (the
eigenvector of the smallest eigenvalue of the covariance) and the curvature
``lambda_min / sum(lambda)`` without any neighbour search.

Coordinates are metres relative to the centre of the grid so that the second
moments keep their precision in float64 (see :class:`VoxelGrid`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Channels of a moment vector: count, sum x, y, z, sum xx, xy, xz, yy, yz, zz, sum r, g, b.
CHANNELS = ("n", "x", "y", "z", "xx", "xy", "xz", "yy", "yz", "zz", "r", "g", "b")
N_CHANNELS = len(CHANNELS)
_PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


@dataclass(frozen=True)
class VoxelGrid:
    """A regular grid covering ``[0, extent]`` (canonical metres) with ``shape`` voxels.

    The voxel size along each axis is ``extent / shape``: close to the requested
    size, but the grid tiles the space's box exactly so that unit-cube positions
    map to whole voxels.
    """

    extent: tuple[float, float, float]
    shape: tuple[int, int, int]

    @classmethod
    def covering(cls, extent, voxel: float, max_cells: int) -> "VoxelGrid":
        """The grid of about ``voxel`` metres over ``extent``, coarsened to at most ``max_cells`` voxels."""
        e = np.maximum(np.asarray(extent, dtype=np.float64), 1e-6)
        v = float(voxel)
        while True:
            shape = np.maximum(np.ceil(e / v - 1e-9).astype(np.int64), 1)
            if int(np.prod(shape)) <= max_cells:
                break
            v *= (np.prod(shape) / max_cells) ** (1 / 3) * 1.001
        return cls(tuple(float(x) for x in e), tuple(int(s) for s in shape))

    @property
    def voxel(self) -> np.ndarray:
        return np.asarray(self.extent) / np.asarray(self.shape)

    @property
    def center(self) -> np.ndarray:
        return np.asarray(self.extent) / 2.0

    def index(self, xyz: np.ndarray) -> np.ndarray:
        """Voxel indices ``(n, 3)`` of canonical-metre points (clipped into the grid)."""
        idx = np.floor(xyz / self.voxel).astype(np.int64)
        return np.clip(idx, 0, np.asarray(self.shape) - 1)


def voxel_moments(xyz: np.ndarray, rgb: np.ndarray | None, grid: VoxelGrid) -> np.ndarray:
    """Moments ``(nx, ny, nz, 13)`` of the points in every voxel, in one pass.

    Parameters
    ----------
    xyz
        ``(n, 3)`` canonical metres (points outside ``[0, extent]`` fall in the border voxels).
    rgb
        ``(n, 3)`` colours in ``[0, 1]``, or None (colour sums stay zero).
    grid
        The voxel grid.
    """
    shape = grid.shape
    ncell = int(np.prod(shape))
    idx = grid.index(xyz)
    flat = np.ravel_multi_index((idx[:, 0], idx[:, 1], idx[:, 2]), shape)
    p = np.asarray(xyz, dtype=np.float64) - grid.center
    out = np.empty((ncell, N_CHANNELS), dtype=np.float64)
    out[:, 0] = np.bincount(flat, minlength=ncell)
    for a in range(3):
        out[:, 1 + a] = np.bincount(flat, weights=p[:, a], minlength=ncell)
    for k, (a, b) in enumerate(_PAIRS):
        out[:, 4 + k] = np.bincount(flat, weights=p[:, a] * p[:, b], minlength=ncell)
    if rgb is None:
        out[:, 10:] = 0.0
    else:
        for a in range(3):
            out[:, 10 + a] = np.bincount(flat, weights=rgb[:, a], minlength=ncell)
    return out.reshape(*shape, N_CHANNELS)


def integral_volume(moments: np.ndarray) -> np.ndarray:
    """Summed-volume table ``(nx+1, ny+1, nz+1, C)``: entry ``[i, j, k]`` sums voxels ``[:i, :j, :k]``."""
    nx, ny, nz, c = moments.shape
    out = np.zeros((nx + 1, ny + 1, nz + 1, c), dtype=np.float64)
    out[1:, 1:, 1:] = moments
    for axis in range(3):
        np.cumsum(out, axis=axis, out=out)
    return out


def box_sums(iv: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Moment sums ``(..., C)`` over boxes of voxels ``[lo, hi)`` (integer arrays ``(..., 3)``).

    Eight corner look-ups of the integral volume, as rows of its flattened
    ``(cells, C)`` view (one ``take`` each, about twice as fast as indexing by
    three arrays; the same values).
    """
    nx, ny, nz, c = iv.shape
    rows = iv.reshape(-1, c)
    x0, y0, z0 = lo[..., 0] * (ny * nz), lo[..., 1] * nz, lo[..., 2]
    x1, y1, z1 = hi[..., 0] * (ny * nz), hi[..., 1] * nz, hi[..., 2]

    def at(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
        return rows.take(x + y + z, axis=0)

    return (at(x1, y1, z1) - at(x0, y1, z1) - at(x1, y0, z1) - at(x1, y1, z0)
            + at(x0, y0, z1) + at(x0, y1, z0) + at(x1, y0, z0) - at(x0, y0, z0))


def box_sums_grid(iv: np.ndarray, xs: np.ndarray, ys: np.ndarray, zs: np.ndarray) -> np.ndarray:
    """Sums ``(len(xs), len(ys), len(zs), C)`` over every product of per-axis intervals.

    ``xs`` etc. are ``(m, 2)`` integer arrays of ``[start, stop)`` voxel intervals.
    The differences are taken one axis at a time (separable: three gathers rather
    than eight full-size ones), in the axis order that keeps the intermediate
    arrays smallest.
    """
    ivs = (xs, ys, zs)
    n = iv.shape[:3]
    best, order = None, (0, 1, 2)
    for o in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
        sizes = list(n)
        cost = 0
        for ax in o:
            sizes[ax] = len(ivs[ax])
            cost += sizes[0] * sizes[1] * sizes[2]
        if best is None or cost < best:
            best, order = cost, o
    a = iv
    for ax in order:
        lo = np.take(a, ivs[ax][:, 0], axis=ax)
        a = np.take(a, ivs[ax][:, 1], axis=ax)
        a -= lo
    return a


def covariance(m: np.ndarray) -> np.ndarray:
    """Point covariance matrices ``(..., 3, 3)`` from moment sums (zero where fewer than 2 points)."""
    n = m[..., 0]
    safe = np.where(n > 0, n, 1.0)[..., None]
    mean = m[..., 1:4] / safe
    second = m[..., 4:10] / safe
    a = np.array([0, 0, 0, 1, 1, 2])
    b = np.array([0, 1, 2, 1, 2, 2])
    six = second - mean[..., a] * mean[..., b]  # xx xy xz yy yz zz
    six[n < 2] = 0.0
    full = np.array([0, 1, 2, 1, 3, 4, 2, 4, 5])
    return six[..., full].reshape(m.shape[:-1] + (3, 3))


def smallest_eigen(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smallest eigenvalue, eigenvalue sum and unit eigenvector of the smallest eigenvalue.

    ``cov`` is ``(..., 3, 3)`` symmetric; numpy's batched ``eigh`` (LAPACK) does
    the work (faster here than a vectorised closed-form cubic solution).
    """
    w, v = np.linalg.eigh(cov)
    w = np.maximum(w, 0.0)
    return w[..., 0], w.sum(axis=-1), v[..., :, 0]
