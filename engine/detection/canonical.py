"""The canonical reference frame of a space (paper section 3.2) and its exact inverse.

From a space's own points only (the same at training and at run time): z is gravity; the Manhattan
orientation from the normals of planar vertical voxel patches, sharpened by :func:`refine_yaw`; ``x`` along
the entrance wall (the widest door-like opening, else the longest shared face with a neighbour, else the
longest wall), ``y`` into the space; the unit cube from the robust box of the aligned points.
A :class:`CanonicalFrame` keeps yaw, origin and extent, so that every detection maps back to world
coordinates exactly (:meth:`CanonicalFrame.unit_box_to_world`).  Design notes: ``docs/design/detection.md``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from engine.detection import moments as mom
from engine.detection.orientations import QUARTER, wrap_quarter

#: Sides of the aligned box, in the order of the quarter turns that bring each to ``y = 0``.
SIDES = ("y-min", "x-max", "y-max", "x-min")


def rotation_z(yaw: float) -> np.ndarray:
    """3x3 rotation by ``yaw`` radians about z."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass
class CanonicalFrame:
    """The frame of one space: ``unit = R(-yaw) (world - origin) / extent``.

    Attributes
    ----------
    yaw
        Radians about z from world x to the canonical x axis (along the entrance wall).
    origin
        World coordinates of the canonical corner ``(0, 0, 0)``.
    extent
        Metres of the space along canonical x, y, z (the unit cube's scale).
    entrance
        How the entrance wall was chosen: ``"opening"``, ``"neighbour"`` or ``"longest-wall"``.
    """

    yaw: float
    origin: np.ndarray
    extent: np.ndarray
    entrance: str = "longest-wall"
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.yaw = float(self.yaw)
        self.origin = np.asarray(self.origin, dtype=np.float64).reshape(3)
        self.extent = np.asarray(self.extent, dtype=np.float64).reshape(3)
        if np.any(self.extent <= 0):
            raise ValueError(f"extent must be positive, got {self.extent}")

    # -- points ------------------------------------------------------------------------------
    def to_metric(self, xyz: np.ndarray) -> np.ndarray:
        """World points ``(n, 3)`` to canonical metres (aligned, origin at the corner)."""
        return (np.asarray(xyz, dtype=np.float64) - self.origin) @ rotation_z(self.yaw)

    def from_metric(self, m: np.ndarray) -> np.ndarray:
        """Canonical metres ``(n, 3)`` back to world points."""
        return np.asarray(m, dtype=np.float64) @ rotation_z(self.yaw).T + self.origin

    def to_unit(self, xyz: np.ndarray) -> np.ndarray:
        """World points to the unit cube."""
        return self.to_metric(xyz) / self.extent

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        """Unit-cube points back to world points."""
        return self.from_metric(np.asarray(u, dtype=np.float64) * self.extent)

    # -- boxes --------------------------------------------------------------------------------
    def unit_box_to_world(self, position: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """A unit-cube box (min corner ``P``, size ``S``) as world ``(center, size, yaw)``."""
        position = np.asarray(position, dtype=np.float64)
        size = np.asarray(size, dtype=np.float64)
        center = self.from_unit((position + size / 2.0)[None])[0]
        return center, size * self.extent, self.yaw

    def world_box_to_unit(self, center, size, yaw: float) -> tuple[np.ndarray, np.ndarray]:
        """The unit-cube box (``P``, ``S``) bounding a world box; exact inverse of :meth:`unit_box_to_world`
        when the box's yaw equals the frame's modulo 90 degrees."""
        rel = float(yaw) - self.yaw
        quarter = np.round(rel / (np.pi / 2))
        size = np.asarray(size, dtype=np.float64)
        if abs(rel - quarter * np.pi / 2) < 1e-9:
            half = (size[[1, 0, 2]] if int(quarter) % 2 else size) / 2.0
        else:
            c, s = abs(np.cos(rel)), abs(np.sin(rel))
            half = np.array([c * size[0] + s * size[1], s * size[0] + c * size[1], size[2]]) / 2.0
        cm = self.to_metric(np.asarray(center, dtype=np.float64)[None])[0]
        return (cm - half) / self.extent, 2.0 * half / self.extent

    # -- persistence ---------------------------------------------------------------------------
    def to_json(self) -> dict[str, Any]:
        return {"yaw": self.yaw, "origin": self.origin.tolist(), "extent": self.extent.tolist(),
                "entrance": self.entrance, "info": self.info}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> CanonicalFrame:
        return cls(d["yaw"], d["origin"], d["extent"], d.get("entrance", "longest-wall"), d.get("info", {}))


# -- estimation ---------------------------------------------------------------------------------

def dominant_yaw(xyz: np.ndarray, voxel: float = 0.25, max_cells: int = 400_000) -> float:
    """Manhattan orientation in ``(-pi/4, pi/4]`` of a space's points from its vertical planar patches."""
    xyz = np.asarray(xyz, dtype=np.float64)
    lo, hi = mom.column_bounds(xyz)
    grid = mom.VoxelGrid.covering(hi - lo, voxel, max_cells)
    m = mom.voxel_moments(xyz - lo, None, grid).reshape(-1, mom.N_CHANNELS)
    m = m[m[:, 0] >= 8]
    if len(m):
        w, v = np.linalg.eigh(mom.covariance(m))
        w = np.maximum(w, 0.0)
        total, normal = w.sum(axis=1), v[:, :, 0]
        # planar: the smallest eigenvalue tiny next to the middle one, the middle one not tiny
        planar = (w[:, 0] <= 0.05 * np.maximum(w[:, 1], 1e-12)) & (w[:, 1] > 0.05 * np.maximum(total, 1e-12))
        vertical = np.abs(normal[:, 2]) < 0.3
        keep = planar & vertical & (total > 0)
        if keep.sum() >= 3:
            ang = np.arctan2(normal[keep, 1], normal[keep, 0])
            wgt = m[keep, 0]
            z = np.sum(wgt * np.exp(4j * ang))
            if abs(z) > 1e-9 * wgt.sum():
                return _wrap_quarter(np.angle(z) / 4.0)
    # fallback: principal axis in plan
    xy = xyz[:, :2] - xyz[:, :2].mean(axis=0)
    cov = xy.T @ xy / max(len(xy), 1)
    w, v = np.linalg.eigh(cov)
    return _wrap_quarter(float(np.arctan2(v[1, 1], v[0, 1])))


def _wrap_quarter(a: float) -> float:
    """Angle modulo 90 degrees into ``(-pi/4, pi/4]``."""
    a = float(wrap_quarter(a))
    return float(QUARTER / 2 if np.isclose(a, -QUARTER / 2) else a)


def refine_yaw(xyz: np.ndarray, yaw: float, *, span: float = np.radians(1.5), bin_size: float = 0.01,
               max_points: int = 200_000) -> float:
    """Sharpen a Manhattan yaw: the angle near ``yaw`` whose projections on both axes are sharpest.

    Points of the middle height band (walls, not floor or ceiling) are projected
    on the rotated x and y axes into ``bin_size`` histograms; the sum of squared
    bin counts peaks when the walls fall in the fewest bins.  Two passes
    (``span`` in 61 steps, then one step in 21), the maximum refined by a parabola:
    about 0.01 degree, where the voxel-normal vote alone is off by up to half a
    degree (too much for a 3 cm thick, 9 m long wall box).
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    z = xyz[::max(1, len(xyz) // max_points), 2]
    z0, z1 = np.quantile(z, [0.02, 0.98]) if len(z) else (0.0, 0.0)
    band = xyz[(xyz[:, 2] > z0 + 0.25 * (z1 - z0)) & (xyz[:, 2] < z1 - 0.25 * (z1 - z0))]
    if len(band) < 100:
        return float(yaw)
    band = band[::max(1, len(band) // max_points), :2]
    band = band - band.mean(axis=0)

    def sharpness(a: float) -> float:
        c, s = np.cos(a), np.sin(a)
        total = 0.0
        for u in (c * band[:, 0] + s * band[:, 1], -s * band[:, 0] + c * band[:, 1]):
            h = np.bincount(np.floor((u - u.min()) / bin_size).astype(np.int64)).astype(np.float64)
            total += float(np.dot(h, h))
        return total

    best = float(yaw)
    for width, steps in ((span, 61), (2 * span / 60, 21)):
        grid = best + np.linspace(-width, width, steps)
        vals = np.array([sharpness(a) for a in grid])
        i = int(np.argmax(vals))
        best = float(grid[i])
        if 0 < i < steps - 1:
            den = vals[i - 1] - 2 * vals[i] + vals[i + 1]
            if den < 0:
                best += float(0.5 * (vals[i - 1] - vals[i + 1]) / den) * (grid[1] - grid[0])
    return _wrap_quarter(best)


def manhattan_yaw(xyz: np.ndarray) -> float:
    """A space's own Manhattan yaw in ``(-pi/4, pi/4]``: :func:`dominant_yaw` sharpened by :func:`refine_yaw`."""
    return refine_yaw(xyz, dominant_yaw(xyz))


def _robust_box(m: np.ndarray, quantile: float) -> tuple[np.ndarray, np.ndarray]:
    if len(m) == 0:
        return np.zeros(3), np.ones(3)
    lo, hi = np.quantile(m, [quantile, 1.0 - quantile], axis=0)  # one partition for both ends
    return lo, np.maximum(hi, lo + 0.05)


def opening_widths(m: np.ndarray, lo: np.ndarray, hi: np.ndarray, *, slab: float = 0.35,
                   door_top: float = 1.8, door_bottom: float = 0.25, min_width: float = 0.55,
                   max_width: float = 3.5) -> np.ndarray:
    """Width (m) of the widest door-like opening in each wall of ``SIDES`` (0 where none).

    ``m`` are the points in the aligned frame, ``lo``/``hi`` the box of the space.
    Along each wall the points within ``slab`` of its face are binned (bins sized
    from their density, 5 to 30 cm); a bin is open when at most 15 % of its height
    band ``[floor + door_bottom, floor + min(door_top, 0.7 height)]`` holds points.
    A run of open bins of door width, in a face whose other bins mostly hold
    points (a real divider), is an opening.
    """
    height = hi[2] - lo[2]
    z0, z1 = lo[2] + door_bottom, lo[2] + min(door_top, 0.7 * height)
    out = np.zeros(4)
    if z1 <= z0 or len(m) == 0:
        return out
    for k, side in enumerate(SIDES):
        axis = 1 if side.startswith("y") else 0  # axis normal to the wall
        along = 1 - axis
        face = lo[axis] if side.endswith("min") else hi[axis]
        dist = np.abs(m[:, axis] - face)
        sel = (dist <= slab) & (m[:, 2] >= z0) & (m[:, 2] <= z1)
        length = hi[along] - lo[along]
        if length < min_width:
            continue
        pts = m[sel]
        density = len(pts) / max(length * (z1 - z0), 1e-9)
        b = float(np.clip(np.sqrt(6.0 / max(density, 1e-9)), 0.05, 0.3))
        nu = max(int(np.ceil(length / b)), 1)
        nz = max(int(np.ceil((z1 - z0) / b)), 1)
        iu = np.clip(((pts[:, along] - lo[along]) / length * nu).astype(np.int64), 0, nu - 1)
        iz = np.clip(((pts[:, 2] - z0) / (z1 - z0) * nz).astype(np.int64), 0, nz - 1)
        occ = np.zeros((nu, nz), dtype=bool)
        occ[iu, iz] = True
        open_col = occ.mean(axis=1) <= 0.15
        if open_col.mean() > 0.8:  # no divider on this side at all
            continue
        best = 0.0
        run = 0
        for is_open in np.append(open_col, False):  # runs over <= a few hundred bins
            if is_open:
                run += 1
                continue
            width = run * length / nu
            if min_width <= width <= max_width:
                best = max(best, width)
            run = 0
        out[k] = best
    return out


def estimate_frame(xyz: np.ndarray, *, connection: np.ndarray | None = None, quantile: float = 0.0005,
                   yaw: float | None = None) -> CanonicalFrame:
    """The canonical frame of one space from its points (world or store-local coordinates).

    Parameters
    ----------
    xyz
        ``(n, 3)`` points of the space.
    connection
        Optional ``(2,)`` plan position (same coordinates as ``xyz``) of the
        largest connection area with a neighbouring space (from ``meta/spaces``):
        when no wall has a door-like opening, the nearest wall is the entrance.
    quantile
        The robust box of the space drops this fraction of points at each end of each axis.
    yaw
        Force the Manhattan orientation (modulo 90 degrees) instead of estimating it.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    if len(xyz) < 4:
        raise ValueError("a space needs at least 4 points for a canonical frame")
    base = manhattan_yaw(xyz) if yaw is None else _wrap_quarter(float(yaw))
    # statistics of the box from an evenly strided subsample of large spaces (deterministic)
    sub = xyz[::max(1, len(xyz) // 400_000)]
    center = np.median(sub, axis=0)
    lo, hi = _robust_box((sub - center) @ rotation_z(base), quantile)
    # openings from an evenly strided subsample of at most a million points (density is relative)
    m = (xyz[::max(1, len(xyz) // 1_000_000)] - center) @ rotation_z(base)
    widths = opening_widths(m, lo, hi)
    lengths = np.array([hi[0] - lo[0], hi[1] - lo[1], hi[0] - lo[0], hi[1] - lo[1]])
    info: dict[str, Any] = {"openings": widths.round(3).tolist()}
    if widths.max() > 0:
        side, how = int(np.argmax(widths)), "opening"
    elif connection is not None:
        c = (np.array([connection[0], connection[1], 0.0]) - center) @ rotation_z(base)
        d = np.array([abs(c[1] - lo[1]), abs(c[0] - hi[0]), abs(c[1] - hi[1]), abs(c[0] - lo[0])])
        side, how = int(np.argmin(d)), "neighbour"
    else:
        longest = lengths >= lengths.max() - 0.05
        counts = np.array([np.sum(np.abs(m[:, 1] - lo[1]) < 0.3), np.sum(np.abs(m[:, 0] - hi[0]) < 0.3),
                           np.sum(np.abs(m[:, 1] - hi[1]) < 0.3), np.sum(np.abs(m[:, 0] - lo[0]) < 0.3)])
        side, how = int(np.argmax(np.where(longest, counts, -1))), "longest-wall"
    final = base + side * np.pi / 2
    final = float(np.arctan2(np.sin(final), np.cos(final)))
    mc = (sub - center) @ rotation_z(final)
    lo, hi = _robust_box(mc, quantile)
    origin = center + rotation_z(final) @ lo
    info["side"] = SIDES[side]
    return CanonicalFrame(final, origin, hi - lo, how, info)
