"""Is a face between two spaces open?  Evidence from the points across it (issue 23).

The space update (:mod:`engine.spaces.update`) merges two neighbouring spaces
only on *positive* evidence that the faces they share are open; the absence
of a detected wall is not such evidence.  This module measures it from the
points within ``window`` metres of a face (in the face's aligned frame: ``n``
across the face, ``a`` along it, world ``z``), in slices ``slice`` metres long
along the face:

* **floor runs through**: the slice has floor points (within ``floor_tol`` of
  the floor height) within ``strip`` metres of the face itself, where a wall
  leaves a void;
* **no wall surface**: the slice has fewer points within ``2.5 strip`` of the
  face in the lower height band (``band`` metres above the floor to
  ``band_top`` above it, below door heads and lintels, and at most ``band``
  under the ceiling) than ``wall_fraction`` of what a scanned vertical
  surface of that size would hold (the density is the floor's beside the face);
* **one height**: the floor and ceiling heights on the two sides (the
  densest level in the lower and upper halves of the face's storey) differ by
  at most ``max_step`` metres.

A face is open when at least ``min_open`` of its slices with points on both
sides are open, and the two sides share one floor and one ceiling height.  The
points are gathered by one task per tile (only the points near some face).
"""
from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from engine.spaces.alignment import Frame
from engine.spaces.document import Face
from tiles.tasks import run_tasks


@dataclass(frozen=True)
class OpennessSettings:
    """How the points across a face are read (see the module docstring)."""

    window: float = 0.6
    strip: float = 0.06
    slice: float = 0.3
    floor_tol: float = 0.08
    band: float = 0.4
    band_top: float = 1.9
    wall_fraction: float = 0.15
    max_step: float = 0.12
    min_open: float = 0.6


def _face_frame(face: Face, frame: Frame) -> Frame:
    return frame if face.yaw is None else Frame(float(face.yaw), frame.origin)


def _tile_near(tile: str, store, faces: list[tuple[Frame, Face]], window: float) -> dict[int, np.ndarray]:
    """One tile's task: per face index, ``(k, 3)`` ``[n, a, z]`` of the points within ``window`` of the face."""
    xyz = store.xyz(tile, local=False)
    out: dict[int, np.ndarray] = {}
    if len(xyz) == 0:
        return out
    for i, (fr, f) in enumerate(faces):
        al = fr.to_aligned(xyz[:, :2])
        k = 0 if f.axis == "u" else 1
        n = al[:, k] - float(f.position)
        a = al[:, 1 - k]
        z = xyz[:, 2]
        sel = ((np.abs(n) <= window) & (a >= f.extent[0]) & (a <= f.extent[1])
               & (z >= f.z_range[0] - 0.3) & (z <= f.z_range[1] + 0.3))
        if np.any(sel):
            out[i] = np.stack([n[sel], a[sel], z[sel]], axis=1)
    return out


def _level(z: np.ndarray, lo: float, hi: float, bin_: float = 0.04) -> float | None:
    """The densest height (a floor or ceiling) among ``z`` within ``[lo, hi]``."""
    z = z[(z >= lo) & (z <= hi)]
    if len(z) < 20:
        return None
    edges = np.arange(lo, hi + bin_, bin_)
    h, e = np.histogram(z, bins=edges)
    return float(e[int(np.argmax(h))] + bin_ / 2)


def face_evidence(pts: np.ndarray, face: Face, p: OpennessSettings) -> dict[str, Any]:
    """Openness of one face from its nearby points ``(k, 3)`` ``[n, a, z]``."""
    z0, z1 = float(face.z_range[0]), float(face.z_range[1])
    mid = (z0 + z1) / 2
    sides = [pts[(pts[:, 0] < -2 * p.strip)], pts[(pts[:, 0] > 2 * p.strip)]]
    floors = [_level(s[:, 2], z0 - 0.3, mid) for s in sides]
    ceils = [_level(s[:, 2], mid, z1 + 0.3) for s in sides]
    out: dict[str, Any] = {"floors": floors, "ceilings": ceils, "slices": 0, "open_slices": 0}
    if None in floors or None in ceils:
        out["open"] = False
        out["reason"] = "a side without floor or ceiling"
        return out
    step = max(abs(floors[0] - floors[1]), abs(ceils[0] - ceils[1]))
    floor_z, ceil_z = float(np.mean(floors)), float(np.mean(ceils))
    a0, a1 = float(face.extent[0]), float(face.extent[1])
    nsl = max(1, int(round((a1 - a0) / p.slice)))
    sl = np.clip(((pts[:, 1] - a0) / max(a1 - a0, 1e-9) * nsl).astype(np.int64), 0, nsl - 1)
    on_floor = np.abs(pts[:, 2] - floor_z) <= p.floor_tol
    near = np.abs(pts[:, 0]) <= p.strip
    side = (np.abs(pts[:, 0]) > 2 * p.strip) & on_floor
    top = min(floor_z + p.band_top, ceil_z - p.band)
    band = (pts[:, 2] >= floor_z + p.band) & (pts[:, 2] <= top)
    side_area = max(2 * (p.window - 2 * p.strip) * (a1 - a0), 1e-9)
    density = np.count_nonzero(side) / side_area  # floor points per m² beside the face
    left = np.bincount(sl[side & (pts[:, 0] < 0)], minlength=nsl) > 0
    right = np.bincount(sl[side & (pts[:, 0] > 0)], minlength=nsl) > 0
    through = np.bincount(sl[near & on_floor], minlength=nsl) > 0
    surface = np.bincount(sl[(np.abs(pts[:, 0]) <= 2.5 * p.strip) & band], minlength=nsl)
    expected = density * ((a1 - a0) / nsl) * max(top - floor_z - p.band, 0.1)
    blocked = surface >= p.wall_fraction * expected
    seen = left & right
    open_ = seen & through & ~blocked
    out.update(slices=int(seen.sum()), open_slices=int(open_.sum()), step=float(step),
               blocked_slices=int((seen & blocked).sum()), floor_through=int((seen & through).sum()))
    ratio = open_.sum() / max(seen.sum(), 1)
    out["open_ratio"] = float(ratio)
    out["open"] = bool(seen.sum() > 0 and ratio >= p.min_open and step <= p.max_step)
    out["reason"] = ("open" if out["open"] else "height step" if step > p.max_step
                     else "no slice seen from both sides" if seen.sum() == 0 else "floor gap or wall surface")
    return out


def faces_open(store, frame: Frame, faces: Sequence[Face], client=None,
               params: OpennessSettings | None = None) -> list[dict[str, Any]]:
    """Openness evidence of every face (one pass over the tiles; see the module docstring)."""
    p = params or OpennessSettings()
    if not faces:
        return []
    framed = [(_face_frame(f, frame), f) for f in faces]
    tiles = [t.name for t in store.tiles]
    parts = run_tasks(_tile_near, tiles, client=client, label="space update: points across faces", keys=tiles,
                      extra_args=(store, framed, p.window))
    near: dict[int, list[np.ndarray]] = defaultdict(list)
    for part in parts:
        for i, arr in part.items():
            near[i].append(arr)
    out = []
    for i, f in enumerate(faces):
        pts = np.concatenate(near[i]) if near.get(i) else np.zeros((0, 3))
        out.append(face_evidence(pts, f, p))
    return out
