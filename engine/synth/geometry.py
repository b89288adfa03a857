"""Geometric primitives of a generated building: what gets sampled and what occludes.

Everything is in the building's *local* frame (metres, z up, origin at a
corner of the ground floor); :class:`engine.synth.building.Frame` maps it to
world coordinates at the very end, so a rotated or shifted building has the
same points up to that rigid transform.

Three primitives cover every surface a scanner can see:

* :class:`Rect` -- a planar rectangle (wall faces, door jambs, glass), with
  rectangular holes (door and window openings); its visible side is ``u x v``.
* :class:`Poly` -- a horizontal polygon (floors and ceilings).
* :class:`Box` -- a solid oriented box (furniture parts, columns, beams, door
  leaves): its faces are sampled and it occludes what is behind it.

Walls are general segments with a thickness (:func:`wall_frame`), not only
axis-aligned ones, so non-Manhattan walls can be added without changing the
scan.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Rect:
    """A planar rectangle ``origin + s*u + t*v`` (``s, t`` in [0, 1]) seen from the ``u x v`` side.

    ``holes`` are ``(s0, s1, t0, t1)`` in metres along ``u`` and ``v`` (openings).
    ``rgb`` is the base colour, ``jitter`` the per-point colour noise (0-255 units),
    ``density`` a multiplier of the scan density (glass returns few points).
    """

    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    rgb: tuple[float, float, float]
    holes: list[tuple[float, float, float, float]] = field(default_factory=list)
    jitter: float = 6.0
    density: float = 1.0

    @property
    def area(self) -> float:
        return float(np.linalg.norm(np.cross(self.u, self.v)))

    def corners(self) -> np.ndarray:
        o = np.asarray(self.origin, float)
        return np.array([o, o + self.u, o + self.u + self.v, o + self.v])


@dataclass
class Poly:
    """A horizontal polygon at height ``z`` (vertices ``(k, 2)``), seen from above (``up``) or below."""

    xy: np.ndarray
    z: float
    up: bool
    rgb: tuple[float, float, float]
    jitter: float = 6.0
    density: float = 1.0

    @property
    def area(self) -> float:
        x, y = self.xy[:, 0], self.xy[:, 1]
        return float(abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) / 2)

    def corners(self) -> np.ndarray:
        return np.c_[self.xy, np.full(len(self.xy), self.z)]


@dataclass
class Box:
    """A solid box: ``center`` (3), ``size`` along its own axes (3), ``yaw`` about z (radians).

    Its faces are sampled except the bottom when it stands on the floor (and
    the top when it touches the ceiling); it always occludes.
    """

    center: np.ndarray
    size: np.ndarray
    yaw: float
    rgb: tuple[float, float, float]
    jitter: float = 6.0
    density: float = 1.0

    def axes(self) -> np.ndarray:
        """The box's unit axes as rows (x, y, z)."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])

    def corners(self) -> np.ndarray:
        h = np.asarray(self.size, float) / 2
        signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
        return np.asarray(self.center, float) + (signs * h) @ self.axes()

    def faces(self, floor_z: float | None = None, ceiling_z: float | None = None) -> list[Rect]:
        """The visible-side-out faces as rectangles (bottom on the floor and top at the ceiling left out)."""
        ax = self.axes()
        h = np.asarray(self.size, float) / 2
        c = np.asarray(self.center, float)
        out = []
        for k in range(3):
            i, j = (k + 1) % 3, (k + 2) % 3
            for sign in (1.0, -1.0):
                if k == 2 and sign < 0 and floor_z is not None and c[2] - h[2] <= floor_z + 1e-6:
                    continue
                if k == 2 and sign > 0 and ceiling_z is not None and c[2] + h[2] >= ceiling_z - 1e-6:
                    continue
                centre = c + sign * h[k] * ax[k]
                u, v = 2 * h[i] * ax[i], 2 * h[j] * ax[j]
                if sign < 0:
                    u, v = v, u  # keep u x v pointing out of the box
                out.append(Rect(centre - u / 2 - v / 2, u, v, self.rgb, jitter=self.jitter, density=self.density))
        return out


def rect(origin, u, v, normal, rgb, **kw) -> Rect:
    """A :class:`Rect` whose visible side is ``normal`` (``u`` and ``v`` swapped if needed)."""
    origin, u, v = (np.asarray(a, float) for a in (origin, u, v))
    if np.dot(np.cross(u, v), np.asarray(normal, float)) < 0:
        u, v = v, u
        holes = kw.pop("holes", None)
        if holes:
            kw["holes"] = [(t0, t1, s0, s1) for s0, s1, t0, t1 in holes]
    return Rect(origin, u, v, rgb, **kw)


def wall_frame(p0, p1) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Unit direction ``d``, left normal ``n`` (2-D), length and yaw of a segment."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = p1 - p0
    length = float(np.hypot(*d))
    d = d / length
    return d, np.array([-d[1], d[0]]), length, math.atan2(d[1], d[0])


def v3(xy, z: float = 0.0) -> np.ndarray:
    """A 3-D point or vector from a 2-D one and a height."""
    return np.array([xy[0], xy[1], z], float)


def at(p0, d, n, s: float, t: float, z: float) -> np.ndarray:
    """The 3-D point ``s`` along ``d`` and ``t`` along ``n`` from ``p0`` (2-D) at height ``z``."""
    xy = np.asarray(p0, float) + s * np.asarray(d, float) + t * np.asarray(n, float)
    return np.array([xy[0], xy[1], z])


def oriented_bounds(corners: np.ndarray, yaw: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre (world frame) and size of the tightest box with the given yaw around points ``(k, 3)``."""
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # box axes as columns
    local = corners @ rot
    lo, hi = local.min(0), local.max(0)
    return rot @ ((lo + hi) / 2), hi - lo
