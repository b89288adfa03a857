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


def column_bounds(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(xyz.min(axis=0), xyz.max(axis=0))`` of ``(n, d)`` points, column by column (the same values).

    numpy reduces an ``(n, 3)`` array along its long axis three values at a time;
    one column at a time is about ten times faster on millions of points.
    """
    xyz = np.asarray(xyz)
    cols = [xyz[:, a] for a in range(xyz.shape[1])]
    return np.array([c.min() for c in cols]), np.array([c.max() for c in cols])


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
    def covering(cls, extent, voxel: float, max_cells: int) -> VoxelGrid:
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

    def flat_index(self, xyz: np.ndarray) -> np.ndarray:
        """Flat (C-order) voxel index ``(n,)`` of canonical-metre points: ``ravel_multi_index`` of :meth:`index`.

        The same values, one axis at a time (about three times fewer passes over memory).
        """
        xyz = np.asarray(xyz)
        voxel = self.voxel
        flat = np.zeros(len(xyz), dtype=np.int64)
        for a in range(3):
            t = xyz[:, a] / voxel[a]
            np.floor(t, out=t)
            i = t.astype(np.int64)
            np.clip(i, 0, self.shape[a] - 1, out=i)
            flat *= self.shape[a]
            flat += i
        return flat


def voxel_order(flat: np.ndarray, n_cells: int) -> np.ndarray:
    """``np.argsort(flat, kind="stable")`` for indices in ``[0, n_cells)``, by 16-bit digits.

    A least-significant-digit radix sort: numpy sorts 16-bit keys stably by
    counting (linear time), so two or three digit passes replace a merge sort of
    64-bit keys (about three times faster on millions of points).  The
    permutation is the same (a stable order is unique).
    """
    flat = np.asarray(flat, dtype=np.int64)
    order = np.argsort((flat & 0xFFFF).astype(np.uint16), kind="stable")
    shift = 16
    while (int(n_cells) - 1) >> shift > 0:
        digit = ((flat[order] >> shift) & 0xFFFF).astype(np.uint16)
        order = order[np.argsort(digit, kind="stable")]
        shift += 16
    return order


def voxel_moments(xyz: np.ndarray, rgb: np.ndarray | None, grid: VoxelGrid,
                  flat: np.ndarray | None = None, rgb_scale: float = 1.0) -> np.ndarray:
    """Moments ``(nx, ny, nz, 13)`` of the points in every voxel, in one pass.

    Parameters
    ----------
    xyz
        ``(n, 3)`` canonical metres (points outside ``[0, extent]`` fall in the border voxels).
    rgb
        ``(n, 3)`` colours in ``[0, 1]``, or None (colour sums stay zero).
    grid
        The voxel grid.
    flat
        The points' :meth:`VoxelGrid.flat_index`, when the caller already has it.
    rgb_scale
        The colours are summed times this factor (``rgb[:, a] * rgb_scale``, column by column).

    Returns a view of a channel-major array (``integral_volume`` copies it anyway).
    """
    ncell = int(np.prod(grid.shape))
    flat = grid.flat_index(xyz) if flat is None else flat
    xyz = np.asarray(xyz, dtype=np.float64)
    centre = grid.center
    out = np.empty((N_CHANNELS, ncell), dtype=np.float64)  # one contiguous row per channel
    out[0] = np.bincount(flat, minlength=ncell)
    p = [xyz[:, a] - centre[a] for a in range(3)]  # contiguous columns, relative to the grid centre
    for a in range(3):
        out[1 + a] = np.bincount(flat, weights=p[a], minlength=ncell)
    for k, (a, b) in enumerate(_PAIRS):
        out[4 + k] = np.bincount(flat, weights=p[a] * p[b], minlength=ncell)
    if rgb is None:
        out[10:] = 0.0
    else:
        rgb = np.asarray(rgb, dtype=np.float64)
        for a in range(3):
            col = rgb[:, a] * rgb_scale if rgb_scale != 1.0 else np.ascontiguousarray(rgb[:, a])
            out[10 + a] = np.bincount(flat, weights=col, minlength=ncell)
    return out.T.reshape(*grid.shape, N_CHANNELS)


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


def covariance_six(m: np.ndarray) -> np.ndarray:
    """Point covariances ``(..., 6)`` (xx, xy, xz, yy, yz, zz) from moment sums (zero where fewer than 2 points)."""
    n = m[..., 0]
    safe = np.where(n > 0, n, 1.0)[..., None]
    mean = m[..., 1:4] / safe
    second = m[..., 4:10] / safe
    a = np.array([0, 0, 0, 1, 1, 2])
    b = np.array([0, 1, 2, 1, 2, 2])
    six = second - mean[..., a] * mean[..., b]  # xx xy xz yy yz zz
    six[n < 2] = 0.0
    return six


def covariance(m: np.ndarray) -> np.ndarray:
    """Point covariance matrices ``(..., 3, 3)`` from moment sums (zero where fewer than 2 points)."""
    full = np.array([0, 1, 2, 1, 3, 4, 2, 4, 5])
    return covariance_six(m)[..., full].reshape(m.shape[:-1] + (3, 3))


#: Below this gap between the two smallest eigenvalues (relative to the largest) the smallest
#: eigenvector is ill-determined, and :func:`smallest_eigen` takes LAPACK's choice (``eigh``).
EIGEN_GAP = 1e-4


def _null_vector(xx, xy, xz, yy, yz, zz, lam) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit null vectors of ``A - lam I`` (``A`` given by its six entries): the longest cross product of two rows."""
    dx, dy, dz = xx - lam, yy - lam, zz - lam
    # the rows are (dx, xy, xz), (xy, dy, yz), (xz, yz, dz)
    a = (xy * yz - xz * dy, xz * xy - dx * yz, dx * dy - xy * xy)  # row 0 x row 1
    b = (xy * dz - xz * yz, xz * xz - dx * dz, dx * yz - xy * xz)  # row 0 x row 2
    c = (dy * dz - yz * yz, yz * xz - xy * dz, xy * yz - dy * xz)  # row 1 x row 2
    na, nb, nc = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2] for u in (a, b, c))
    use_b = nb > na
    v = [np.where(use_b, bi, ai) for ai, bi in zip(a, b)]
    nv = np.where(use_b, nb, na)
    use_c = nc > nv
    v = [np.where(use_c, ci, vi) for ci, vi in zip(c, v)]
    inv = 1.0 / np.sqrt(np.maximum(np.where(use_c, nc, nv), np.finfo(np.float64).tiny))
    return v[0] * inv, v[1] * inv, v[2] * inv


def covariance_columns(m: np.ndarray) -> list[np.ndarray]:
    """:func:`covariance_six` of moment sums ``(n, 13)`` as six contiguous columns (the same values)."""
    n = m[:, 0]
    safe = np.where(n > 0, n, 1.0)
    mean = [m[:, 1 + a] / safe for a in range(3)]
    cols = [m[:, 4 + k] / safe - mean[a] * mean[b] for k, (a, b) in enumerate(_PAIRS)]
    few = n < 2
    if few.any():
        for c in cols:
            c[few] = 0.0
    return cols


def smallest_eigen_six(six: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`smallest_eigen` of symmetric matrices given by their six entries ``(..., 6)`` (xx xy xz yy yz zz)."""
    six = np.asarray(six, dtype=np.float64)
    lead = six.shape[:-1]
    s = six.reshape(-1, 6)
    lam, total, vec = smallest_eigen_columns(*(np.ascontiguousarray(s[:, i]) for i in range(6)))
    return lam.reshape(lead), total.reshape(lead), vec.reshape(*lead, 3)


def smallest_eigen_columns(xx: np.ndarray, xy: np.ndarray, xz: np.ndarray, yy: np.ndarray, yz: np.ndarray,
                           zz: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`smallest_eigen` of ``n`` symmetric matrices given as six ``(n,)`` columns of their entries."""
    q = (xx + yy + zz) / 3.0
    dx, dy, dz = xx - q, yy - q, zz - q
    p2 = (dx * dx + dy * dy + dz * dz + 2.0 * (xy * xy + xz * xz + yz * yz)) / 6.0
    p = np.sqrt(p2)
    det = dx * (dy * dz - yz * yz) + xy * (yz * xz - xy * dz) + xz * (xy * yz - dy * xz)  # det(A - qI)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.clip(det / (2.0 * p2 * p), -1.0, 1.0)  # det((A - qI) / p) / 2
    phi = np.arccos(r) / 3.0
    big = q + 2.0 * p * np.cos(phi)
    small = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    # the cubic's smallest root loses digits where two eigenvalues nearly meet: the Rayleigh
    # quotient of its null vector is exact to the square of that vector's error
    x, y, z = _null_vector(xx, xy, xz, yy, yz, zz, small)
    small = xx * x * x + yy * y * y + zz * z * z + 2.0 * (xy * x * y + xz * x * z + yz * y * z)
    x, y, z = _null_vector(xx, xy, xz, yy, yz, zz, small)
    vec = np.stack([x, y, z], axis=-1)
    mid = 3.0 * q - big - small
    lam = np.maximum(small, 0.0)
    total = lam + np.maximum(mid, 0.0) + np.maximum(big, 0.0)
    hard = ~((mid - small) > EIGEN_GAP * big)  # also: zero or non-finite matrices
    if hard.any():
        h = [c[hard] for c in (xx, xy, xz, xy, yy, yz, xz, yz, zz)]
        w, v = np.linalg.eigh(np.stack(h, axis=-1).reshape(-1, 3, 3))
        w = np.maximum(w, 0.0)
        lam[hard], total[hard], vec[hard] = w[:, 0], w.sum(axis=1), v[:, :, 0]
    return lam, total, vec


def smallest_eigen(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smallest eigenvalue, eigenvalue sum and unit eigenvector of the smallest eigenvalue.

    ``cov`` is ``(..., 3, 3)`` symmetric positive semi-definite; eigenvalues are
    clipped at 0.  Closed form, vectorised (about twice as fast as numpy's batched
    LAPACK ``eigh``, which it replaces):

    * the eigenvalues by the trigonometric solution of the characteristic cubic;
    * the eigenvector of the smallest as the longest cross product of two rows
      of ``cov - lambda I``; its Rayleigh quotient then sharpens ``lambda`` and
      the cross product is taken again with it.

    Where the two smallest eigenvalues are within ``EIGEN_GAP`` of the largest
    (a line, a sphere, a zero matrix: the eigenvector is not determined, and any
    choice but LAPACK's would change the features) ``np.linalg.eigh`` solves
    them.  Elsewhere the results equal ``eigh``'s to about 1e-11 (the vector up
    to its sign, which the features drop; tested).
    """
    c = np.asarray(cov, dtype=np.float64)
    # the lower triangle, as eigh reads it
    six = np.stack([c[..., 0, 0], c[..., 1, 0], c[..., 2, 0], c[..., 1, 1], c[..., 2, 1], c[..., 2, 2]], axis=-1)
    return smallest_eigen_six(six)
