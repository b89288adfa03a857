"""The frame(s) of one space: its dominant wall orientation, and the regions of a space whose walls follow two.

A yaw within ``snap_deg`` of the building's is snapped to it; a space with a
wing at an angle is split into the regions of its two orientations, each
parsed in its own frame by the refinement (:mod:`engine.spaces.refine`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from engine.spaces.alignment import (
    AlignmentSettings,
    block_sum,
    coarse_yaw,
    density_image,
    orientation_field,
    parabolic_peak,
    refine_angles,
    refine_sample,
    tile_evidence,
)


def _snap(deg: float, building_yaw: float, snap_deg: float) -> float:
    """The direction ``deg + k * 90°`` closest to the building's yaw (radians); the building's within ``snap_deg``."""
    b = math.degrees(building_yaw)
    diff = ((deg - b + 45.0) % 90.0) - 45.0
    return building_yaw if abs(diff) <= snap_deg else math.radians(b + diff)


def space_yaw(xy: np.ndarray, params: AlignmentSettings, building_yaw: float, snap_deg: float,
              evidence: dict[str, Any] | None = None) -> float:
    """The dominant wall orientation of some points (radians), the building's yaw when within ``snap_deg``.

    The same estimator as the building's (:func:`engine.spaces.alignment.estimate_alignment`) on one
    "tile": orientation histogram modulo 90 degrees, then refinement by projection sharpness.
    The result is the one of the four directions ``yaw + k * 90°`` closest to ``building_yaw``.
    ``evidence``: :func:`engine.spaces.alignment.tile_evidence` of these very points when already computed.
    """
    ev = evidence if evidence is not None else tile_evidence(np.asarray(xy, dtype=np.float64), params)
    if not np.any(ev["histogram"] > 0):
        return building_yaw
    coarse = coarse_yaw(ev["histogram"], params.angle_bin)
    sharp = refine_sample(ev, coarse, params)["sharpness"]
    deg = parabolic_peak(refine_angles(coarse, params), sharp) if np.any(sharp > 0) else coarse
    return _snap(deg, building_yaw, snap_deg)


def _circular_offset(a: np.ndarray, b: float) -> np.ndarray:
    """``a - b`` modulo 90 degrees, in [-45, 45)."""
    return ((np.asarray(a, dtype=np.float64) - b + 45.0) % 90.0) - 45.0


def two_orientations(hist: np.ndarray, angle_bin: float, separation: float, half_width: float,
                     min_second: float) -> list[float]:
    """The dominant orientation of a histogram modulo 90 (degrees) and a second one when it is strong.

    The second is the peak of the circularly smoothed histogram at least
    ``separation`` degrees from the first; it counts when the weight within
    ``half_width`` degrees of it is at least ``min_second`` times the first's.
    """
    h = np.asarray(hist, dtype=np.float64)
    if not np.any(h > 0):
        return []
    centres = (np.arange(len(h)) + 0.5) * angle_bin
    first = coarse_yaw(h, angle_bin)
    sm = ndimage.gaussian_filter1d(h, 1.0 / angle_bin, mode="wrap")
    far = np.abs(_circular_offset(centres, first)) >= separation
    if not far.any():
        return [first]
    second = float(centres[np.flatnonzero(far)[int(np.argmax(sm[far]))]])
    m1 = h[np.abs(_circular_offset(centres, first)) <= half_width].sum()
    m2 = h[np.abs(_circular_offset(centres, second)) <= half_width].sum()
    if m2 < min_second * m1:
        return [first]
    sub = np.abs(_circular_offset(centres, second)) <= half_width  # the second's own circular mean
    z = np.sum(h[sub] * np.exp(1j * np.radians(4 * _circular_offset(centres[sub], second))))
    return [first, float((second + math.degrees(np.angle(z)) / 4.0) % 90.0)]


@dataclass
class Regions:
    """Which of two frames each part of a space belongs to: a label raster of ``block`` metre squares."""

    labels: np.ndarray  # (rows: y, cols: x) int8, 0 or 1
    lo: np.ndarray  # store-local x, y of the raster's corner
    block: float

    def of(self, xy: np.ndarray) -> np.ndarray:
        """Label of store-local points (clipped to the raster)."""
        ix = np.clip(np.floor((xy[:, 0] - self.lo[0]) / self.block).astype(np.int64), 0, self.labels.shape[1] - 1)
        iy = np.clip(np.floor((xy[:, 1] - self.lo[1]) / self.block).astype(np.int64), 0, self.labels.shape[0] - 1)
        return self.labels[iy, ix]


def frame_regions(xy: np.ndarray, params: AlignmentSettings, orientations: list[float], tolerance: float,
                  block: float, smooth: float) -> Regions:
    """Split a space into the parts whose walls follow each of two orientations (degrees modulo 90).

    Every pixel of the density image votes with its coherent wall strength
    (:func:`engine.spaces.alignment.orientation_field`) for the orientation within
    ``tolerance`` degrees of its own; the votes are summed over ``block``
    metre squares and smoothed (Gaussian, ``smooth`` metres); a square takes
    the orientation with more votes, a square without votes that of the
    nearest square with some.
    """
    img, lo = density_image(xy, params.pixel)
    ang, weight = orientation_field(img, params)
    k = max(1, int(round(block / params.pixel)))
    votes = []
    for o in orientations:
        near = np.abs(_circular_offset(ang, o)) <= tolerance
        votes.append(ndimage.gaussian_filter(block_sum(np.where(near, weight, 0.0), k), smooth / (k * params.pixel),
                                             mode="constant"))
    v = np.stack(votes)
    lab = np.argmax(v, axis=0).astype(np.int8)
    none = v.max(axis=0) <= 1e-9 * max(float(v.max()), 1e-300)
    if none.any() and not none.all():
        _, (iy, ix) = ndimage.distance_transform_edt(none, return_indices=True)
        lab = lab[iy, ix]
    return Regions(lab, np.asarray(lo, dtype=np.float64), k * params.pixel)
