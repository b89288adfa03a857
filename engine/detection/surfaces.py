"""Surfaces in a space's detections: its one ceiling and floor, and thin boxes fitted to their surfaces.

:func:`surface_order` orders a space's ceiling (floor) windows for ``one-per-space``;
:func:`refine_surfaces` moves the thin boxes of the surface classes (``refine-classes``: walls, floors,
ceilings) onto the surface beside them (:func:`surface_shift`) and fits their thickness to it
(:func:`refine_extent`).  Design notes: ``docs/design/detection.md``.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from scipy.special import ndtri

from engine.detection import moments as mom
from engine.detection.pointindex import PointIndex
from engine.detection.settings import REFINE_BANDS, DetectionSettings
from tiles.classes import ELEMENT_CLASSES

CEILING, FLOOR = ELEMENT_CLASSES.index("ceiling"), ELEMENT_CLASSES.index("floor")


def expected_extreme(n: int) -> float:
    """The expected largest of ``n`` standard normal values (Blom's approximation), at least 1.

    The half-width, in noise sigmas, of the tightest box of ``n`` points of a plane scanned with Gaussian
    noise: 3.9 for 10,000 points, 4.9 for 1,000,000.
    """
    return max(float(ndtri((n - 0.375) / (n + 0.25))), 1.0) if n > 1 else 1.0


def refine_extent(values: np.ndarray, lo: float, hi: float, bin_size: float, frac: float = 0.02,
                  sigmas: float | None = 3.0) -> tuple[float, float]:
    """The extent of the surface in ``values`` around the peak of their histogram in ``[lo, hi]``.

    First the dense run of the histogram (``bin_size`` bins holding at least ``frac``
    of the peak) around its peak; then, within it, the band ``median +- sigmas``
    robust standard deviations (1.4826 MAD) of its values, without the few
    stray points of things touching the surface that widen the dense run.  With
    ``sigmas`` 3 the band holds the surface's points under Gaussian scan noise
    (99.7 %), within the run; with None it is the tightest box the run's n points
    are expected to have under that noise (:func:`expected_extreme`; S3DIS's
    convention for an element's box), within ``[lo, hi]``.  The band is at least
    one bin wide.
    """
    if len(values) == 0:
        return lo, hi
    nb = max(int(np.ceil((hi - lo) / bin_size)), 1)
    h = np.bincount(np.clip(((values - lo) / bin_size).astype(np.int64), 0, nb - 1), minlength=nb)
    peak = int(np.argmax(h))
    dense = h >= frac * h[peak]
    a = peak
    while a > 0 and dense[a - 1]:
        a -= 1
    b = peak
    while b < nb - 1 and dense[b + 1]:
        b += 1
    run_lo, run_hi = lo + a * bin_size, min(lo + (b + 1) * bin_size, hi)
    v = values[(values >= run_lo) & (values <= run_hi)]
    if len(v) < 3:
        return run_lo, run_hi
    med = float(np.median(v))
    sigma = 1.4826 * float(np.median(np.abs(v - med)))
    if sigmas is None:  # the run stops where a bin holds under frac of the peak (2.8 sigma at 2 %): not a bound here
        half = max(expected_extreme(len(v)) * sigma, bin_size / 2)
        return max(lo, med - half), min(hi, med + half)
    half = max(sigmas * sigma, bin_size / 2)
    return max(run_lo, med - half), min(run_hi, med + half)


def surface_shift(values: np.ndarray, lo: int, hi: int, search_lo: int, search_hi: int, voxel: float,
                  bin_size: float, min_gain: float = 2.0) -> int:
    """Voxels to move a thin box ``[lo, hi)`` along one axis so that it holds the surface beside it.

    ``values`` are the coordinates (metres) along that axis of the points in
    ``[search_lo, search_hi)`` voxels.  The surface is the peak of their histogram
    (``bin_size`` metres) when it lies outside ``[lo, hi)`` and holds at least
    ``min_gain`` times the points of the densest bin inside it (a plane, not the
    random top of evenly spread points); the box then makes the smallest move that
    brings the peak's voxel into it.  Otherwise (and without points) 0.
    """
    if len(values) == 0:
        return 0
    a, b = search_lo * voxel, search_hi * voxel
    nb = max(int(np.ceil((b - a) / bin_size)), 1)
    h = np.bincount(np.clip(((values - a) / bin_size).astype(np.int64), 0, nb - 1), minlength=nb)
    centres = a + (np.arange(nb) + 0.5) * bin_size
    layer = np.clip(np.floor(centres / voxel).astype(np.int64), search_lo, search_hi - 1)
    inside = (layer >= lo) & (layer < hi)
    peak = int(np.argmax(h))
    if inside[peak] or h[peak] < min_gain * h[inside].max(initial=0):
        return 0
    return int(layer[peak] - (hi - 1) if layer[peak] >= hi else layer[peak] - lo)


def surface_order(keep: np.ndarray, lo: np.ndarray, hi: np.ndarray, nz: int, upper: bool,
                  choice: str = "extreme") -> np.ndarray:
    """A space's ceiling (``upper``) or floor windows ``keep`` (best score first) in the order its one is taken from.

    ``"extreme"``: highest top first for a ceiling, lowest bottom first for a floor (ties by
    score): a room's ceiling is its highest horizontal surface, its floor its lowest, while
    beams' undersides, table tops and shelves can outscore them.  ``"halves"``: the windows
    whose middle lies in the upper (ceiling) or lower (floor) half of the space's ``nz``
    voxels, best first (all of them if none does).  ``"score"``: unchanged (best first).
    """
    if not len(keep) or choice == "score":
        return keep
    if choice == "halves":
        mid = (lo[keep, 2] + hi[keep, 2]) / 2.0
        ok = mid >= nz / 2.0 if upper else mid <= nz / 2.0
        return keep[ok] if ok.any() else keep
    z = hi[keep, 2] if upper else -lo[keep, 2]
    return keep[np.argsort(-z, kind="stable")]


def refine_surfaces(lo: np.ndarray, hi: np.ndarray, lo_m: np.ndarray, hi_m: np.ndarray, cls_all: np.ndarray,
                    atom_index: np.ndarray, atoms: list[Any], grid: mom.VoxelGrid, index: PointIndex,
                    settings: DetectionSettings) -> None:
    """Thin-box refinement of the detections of the ``refine-classes``, in place.

    ``lo``, ``hi`` are the voxel boxes ``(n, 3)``, ``lo_m``, ``hi_m`` the same in canonical metres,
    ``cls_all`` and ``atom_index`` each detection's class and dictionary atom (index into ``atoms``).
    Along an axis where a detection is at most ``thin-voxels`` voxels thick and its window's learned
    size is under half a voxel, the box first moves to the surface (:func:`surface_shift`), then its
    metric extent becomes the surface's (:func:`refine_extent`).
    """
    vox = grid.voxel
    n = np.asarray(grid.shape)
    surface = np.isin(cls_all, [ELEMENT_CLASSES.index(c) for c in settings.refine_classes])
    for i in np.nonzero(surface)[0]:
        # surfaces thinner than half a voxel (walls, floors, ceilings as seen from inside)
        atom = atoms[int(atom_index[i])]
        need = np.minimum(atom.size_in(grid.extent), atom.metric_size)
        thin = np.nonzero((hi[i] - lo[i] <= settings.thin_voxels) & (need < 0.5 * vox))[0]
        for a in thin:
            # the surface is looked for in the box grown along this axis as NMS grew it: the
            # windows NMS merged into this one lie there, and the best-scoring layer may be the
            # one beside the surface (under a ceiling crossed by beams: the beams' sides)
            pad = int(max(np.ceil(settings.nms_min_size / vox[a]) - (hi[i, a] - lo[i, a]), 0) // 2)
            # a space's one ceiling (floor) is its highest (lowest) dense surface: looked for up to the
            # top (down to the bottom) of the space, above beams' undersides or a lowered part
            up = a == 2 and settings.surface_choice == "extreme" and cls_all[i] == CEILING
            down = a == 2 and settings.surface_choice == "extreme" and cls_all[i] == FLOOR
            if pad or up or down:
                blo, bhi = lo[i].copy(), hi[i].copy()
                blo[a], bhi[a] = max(lo[i, a] - pad, 0), min(hi[i, a] + pad, n[a])
                bhi[a] = n[a] if up else bhi[a]
                blo[a] = 0 if down else blo[a]
                shift = surface_shift(index.points_in(blo, bhi)[:, a], int(lo[i, a]), int(hi[i, a]),
                                      int(blo[a]), int(bhi[a]), vox[a], settings.refine_bin)
                lo[i, a] += shift
                hi[i, a] += shift
                lo_m[i, a], hi_m[i, a] = lo[i, a] * vox[a], hi[i, a] * vox[a]
            pts = index.points_in(lo[i], hi[i])
            lo_m[i, a], hi_m[i, a] = refine_extent(pts[:, a], lo_m[i, a], hi_m[i, a], settings.refine_bin,
                                                   sigmas=REFINE_BANDS[settings.refine_band])
