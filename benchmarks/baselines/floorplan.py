"""What the two baselines of paper Table 2 share: wall segments -> barriers -> free-space components -> ARI.

Both baselines (RANSAC planes, 2D Hough lines) only detect walls.  They are made
into a space segmentation in the simplest honest way:

1. storeys from the building's z histogram (the same slab search as our method,
   :func:`engine.spaces.slicing.find_storeys`, so that storeys are not what is compared);
2. per storey, a sample of the points (at most ``max_points``) in memory;
3. the detected wall segments are drawn as barriers (``barrier`` metres thick)
   on an occupancy raster of the storey (``pixel`` metres; a pixel is occupied
   when points fall in it, gaps of one pixel closed);
4. the 4-connected components of occupied, non-barrier pixels are the spaces;
   components under ``min_area`` m² join the nearest larger one;
5. every point takes the label of its pixel, or of the nearest labelled pixel
   (points on barriers), one task per tile, and the per-tile contingency tables
   against ``gt_space`` are summed into the ARI (:mod:`engine.metrics.ari`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from engine.metrics.ari import ari_from_contingency, contingency_pairs, contingency_table, sum_pairs
from engine.spaces.dividers import vertical_params
from engine.spaces.histograms import share, z_histogram
from engine.spaces.slicing import find_storeys
from tiles.tasks import run_tasks


@dataclass(frozen=True)
class RasterParams:
    pixel: float = 0.05
    barrier: float = 0.10
    min_area: float = 1.0
    max_points: int = 400_000
    z_bin: float = 0.02


def _tile_z(tile: str, store, z_lo: int, z_n: int, z_bin: float) -> np.ndarray:
    z = store.xyz(tile)[:, 2]
    return z_histogram(np.floor(z / z_bin).astype(np.int64), z_lo, z_n)


def storeys(store, client=None, z_bin: float = 0.02) -> list[tuple[float, float]]:
    """Storey z ranges (store-local metres) from the z histogram and the slab search."""
    m = store.meta
    z_lo = int(math.floor((m.bounds[2] - m.origin[2]) / z_bin)) - 1
    z_n = int(math.floor((m.bounds[5] - m.origin[2]) / z_bin)) + 2 - z_lo
    tiles = [t.name for t in store.tiles]
    hist = np.sum(run_tasks(_tile_z, tiles, client=client, label="baseline z", extra_args=(store, z_lo, z_n, z_bin)),
                  axis=0)
    floors, _ = find_storeys(hist, z_lo, vertical_params(bin_width=z_bin))
    return [(a * z_bin, b * z_bin) for a, b in floors]


def _tile_sample(tile: str, store, step: int) -> np.ndarray:
    return store.xyz(tile)[::step]


def sample_points(store, max_points: int, client=None) -> np.ndarray:
    """An even sample (every k-th point of every tile) of at most about ``max_points`` store-local points."""
    step = max(1, int(math.ceil(store.meta.point_count / max_points)))
    tiles = [t.name for t in store.tiles]
    return np.concatenate(run_tasks(_tile_sample, tiles, client=client, label="baseline sample",
                                    extra_args=(store, step)))


@dataclass
class LabelRaster:
    """Space labels on a storey raster: ``labels[row, col]`` (-1: none), corner ``lo``, pixel, z range."""

    labels: np.ndarray
    lo: np.ndarray
    pixel: float
    z_range: tuple[float, float]
    first_label: int


def label_raster(xy: np.ndarray, segments: list[tuple[float, float, float, float]], z_range: tuple[float, float],
                 first_label: int, params: RasterParams) -> LabelRaster:
    """Spaces of one storey: components of occupied pixels cut by the wall segments ``(x0, y0, x1, y1)``."""
    from skimage.draw import line

    p = params
    lo = xy.min(axis=0) - 2 * p.pixel if len(xy) else np.zeros(2)
    ij = np.floor((xy - lo) / p.pixel).astype(np.int64)
    shape = (int(ij[:, 1].max()) + 3, int(ij[:, 0].max()) + 3) if len(xy) else (1, 1)
    occ = np.zeros(shape, dtype=bool)
    occ[ij[:, 1], ij[:, 0]] = True
    occ = ndimage.binary_closing(occ, np.ones((3, 3)), border_value=0) | occ
    barrier = np.zeros(shape, dtype=bool)
    for x0, y0, x1, y1 in segments:
        c0, r0 = (np.array([x0, y0]) - lo) / p.pixel
        c1, r1 = (np.array([x1, y1]) - lo) / p.pixel
        rr, cc = line(int(round(r0)), int(round(c0)), int(round(r1)), int(round(c1)))
        ok = (rr >= 0) & (rr < shape[0]) & (cc >= 0) & (cc < shape[1])
        barrier[rr[ok], cc[ok]] = True
    k = max(1, int(round(p.barrier / p.pixel)))
    if k > 1:
        barrier = ndimage.binary_dilation(barrier, np.ones((k, k)))
    free = occ & ~barrier
    comp, n = ndimage.label(free)  # 4-connected
    sizes = np.bincount(comp.ravel(), minlength=n + 1)
    big = sizes >= p.min_area / p.pixel ** 2
    big[0] = False
    keep = big[comp]
    if keep.any():
        # small components and barrier pixels take the nearest big component
        _, idx = ndimage.distance_transform_edt(~keep, return_indices=True)
        comp = comp[idx[0], idx[1]]
    else:
        comp = np.where(occ, 1, 0)
    ids = np.unique(comp[comp > 0])
    relabel = np.full(comp.max() + 1, -1, dtype=np.int64)
    relabel[ids] = first_label + np.arange(len(ids))
    return LabelRaster(relabel[comp], lo, p.pixel, z_range, first_label)


def _tile_contingency(tile: str, store, rasters: list[LabelRaster]) -> tuple[np.ndarray, np.ndarray]:
    xyz = store.xyz(tile)
    truth = store.read(tile, ["gt_space"])["gt_space"]
    pred = np.full(len(xyz), -1, dtype=np.int64)
    for r in rasters:
        sel = np.flatnonzero((xyz[:, 2] >= r.z_range[0]) & (xyz[:, 2] < r.z_range[1]))
        ij = np.floor((xyz[sel, :2] - r.lo) / r.pixel).astype(np.int64)
        ij[:, 0] = np.clip(ij[:, 0], 0, r.labels.shape[1] - 1)
        ij[:, 1] = np.clip(ij[:, 1], 0, r.labels.shape[0] - 1)
        pred[sel] = r.labels[ij[:, 1], ij[:, 0]]
    return contingency_pairs(truth, pred)


def raster_ari(store, rasters: list[LabelRaster], client=None) -> float:
    """ARI of the points labelled by the rasters against ``gt_space`` (per-tile tables summed)."""
    tiles = [t.name for t in store.tiles]
    parts = run_tasks(_tile_contingency, tiles, client=client, label="baseline ARI",
                      extra_args=(store, share(client, rasters)))
    return ari_from_contingency(contingency_table(*sum_pairs(parts)))


def segment_storeys(store, detect, params: RasterParams | None = None, client=None) -> dict[str, Any]:
    """Run a wall detector ``detect(xyz_storey) -> segments`` per storey; labels rasters and the ARI."""
    p = params or RasterParams()
    pts = sample_points(store, p.max_points, client=client)
    rasters, n_segments, first = [], 0, 0
    for z0, z1 in storeys(store, client=client, z_bin=p.z_bin):
        sel = pts[(pts[:, 2] >= z0) & (pts[:, 2] < z1)]
        if len(sel) < 100:
            continue
        segs = detect(sel)
        n_segments += len(segs)
        r = label_raster(sel[:, :2], segs, (z0, z1), first, p)
        first = int(r.labels.max()) + 1 if (r.labels >= 0).any() else first
        rasters.append(r)
    return {"ari": raster_ari(store, rasters, client=client), "spaces": first, "segments": n_segments}
