"""The building's main horizontal axes: a Manhattan-frame estimate reduced over tiles (paper section 3.1.1).

Two passes over the tiles: per-tile evidence (the histogram of density-image gradient orientations modulo 90
degrees, kept in ``meta/alignment``), then refinement of the yaw by the sharpness of the wall pixels'
projections.  ``aligned = R(-yaw) (world - origin)`` (see :class:`Frame`).  Why and how:
``docs/design/spaces.md`` (the building's frame).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from tiles.tasks import run_tasks


@dataclass(frozen=True)
class AlignmentSettings:
    """Parameters of the Manhattan-frame estimate (metres and degrees)."""

    #: Pixel of the evidence image: a wall is one or two pixels thick.
    pixel: float = 0.05
    #: Gaussian scale of the image gradient, in pixels.
    sigma: float = 1.0
    #: Integration scale of the structure tensor (metres): averages the staircase of a rasterised
    #: slanted wall into its true direction.
    integration: float = 0.3
    #: Bin of the orientation histograms (degrees, over [0, 90)).
    angle_bin: float = 0.5
    #: Half range and step of the refinement around the coarse yaw (degrees).
    refine_range: float = 1.5
    refine_step: float = 0.05
    #: Pixel of the refinement image and bin of its projections.
    refine_pixel: float = 0.01
    #: Refinement uses pixels at least this many times denser than the tile's median occupied pixel ...
    wall_factor: float = 3.0
    #: ... at most this many per tile (an even sample of them).
    max_wall_pixels: int = 20000

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> AlignmentSettings:
        known = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k.replace("-", "_"): v for k, v in d.items() if k.replace("-", "_") in known})


@dataclass
class Frame:
    """The aligned frame: ``aligned = R(-yaw) (world - origin)``; z is only shifted.

    ``yaw`` (radians) is the direction of the first aligned axis ``u`` from
    world x, counter-clockwise; ``origin`` is a world point ``[x, y, z]``.
    """

    yaw: float
    origin: tuple[float, float, float]

    @property
    def cos_sin(self) -> tuple[float, float]:
        return math.cos(self.yaw), math.sin(self.yaw)

    def rotate_to_aligned(self, xyz_rel: np.ndarray) -> np.ndarray:
        """Coordinates relative to ``origin`` (world axes) -> aligned ``(u, v, z)``."""
        c, s = self.cos_sin
        p = np.asarray(xyz_rel, dtype=np.float64)
        out = np.empty_like(p)
        out[..., 0] = c * p[..., 0] + s * p[..., 1]
        out[..., 1] = -s * p[..., 0] + c * p[..., 1]
        if p.shape[-1] > 2:
            out[..., 2:] = p[..., 2:]
        return out

    def to_aligned(self, world: np.ndarray) -> np.ndarray:
        """World ``(..., 2 or 3)`` -> aligned."""
        w = np.asarray(world, dtype=np.float64)
        return self.rotate_to_aligned(w - np.asarray(self.origin)[: w.shape[-1]])

    def to_world(self, aligned: np.ndarray) -> np.ndarray:
        """Aligned ``(..., 2 or 3)`` -> world."""
        a = np.asarray(aligned, dtype=np.float64)
        c, s = self.cos_sin
        out = np.empty_like(a)
        out[..., 0] = c * a[..., 0] - s * a[..., 1]
        out[..., 1] = s * a[..., 0] + c * a[..., 1]
        if a.shape[-1] > 2:
            out[..., 2:] = a[..., 2:]
        return out + np.asarray(self.origin)[: a.shape[-1]]

    def to_json(self) -> dict[str, Any]:
        return {"yaw": float(self.yaw), "yaw_deg": float(math.degrees(self.yaw)),
                "origin": [float(v) for v in self.origin]}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Frame:
        return cls(float(d["yaw"]), tuple(float(v) for v in d["origin"]))


# -- pass 1: orientation evidence per tile -------------------------------------------------

def density_image(xy: np.ndarray, pixel: float, lo: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Point counts on a square grid (rows: y, columns: x) and the grid's lower-left corner."""
    xy = np.asarray(xy, dtype=np.float64)
    if len(xy) == 0:
        return np.zeros((1, 1), dtype=np.int64), np.zeros(2) if lo is None else np.asarray(lo, float)
    if lo is None:
        lo = xy.min(axis=0)
    ix = ((xy[:, 0] - lo[0]) * (1.0 / pixel)).astype(np.int64)  # non-negative: truncation is floor
    iy = ((xy[:, 1] - lo[1]) * (1.0 / pixel)).astype(np.int64)
    shape = (int(iy.max()) + 1, int(ix.max()) + 1)
    iy *= shape[1]
    iy += ix
    img = np.bincount(iy, minlength=shape[0] * shape[1]).reshape(shape)
    return img, np.asarray(lo, dtype=np.float64)


def block_sum(img: np.ndarray, k: int) -> np.ndarray:
    """Sum of ``k x k`` blocks of an image (padded with zeros): the same counts on a k-times coarser grid."""
    if k <= 1:
        return img
    h, w = img.shape
    pad = np.zeros((-(-h // k) * k, -(-w // k) * k), dtype=img.dtype)
    pad[:h, :w] = img
    return pad.reshape(pad.shape[0] // k, k, pad.shape[1] // k, k).sum(axis=(1, 3))


def orientation_histogram(xy: np.ndarray, params: AlignmentSettings | None = None) -> np.ndarray:
    """Gradient-orientation histogram modulo 90 degrees of the density image of some points (see below)."""
    p = params or AlignmentSettings()
    if len(xy) < 16:
        return np.zeros(int(round(90.0 / p.angle_bin)))
    return image_orientation_histogram(density_image(xy, p.pixel)[0], p)


def image_orientation_histogram(img: np.ndarray, params: AlignmentSettings) -> np.ndarray:
    """Orientation histogram modulo 90 degrees of a density image with ``params.pixel`` pixels.

    Densities above ``wall_factor`` times the median occupied pixel (the floor
    and ceiling level) count, as ``log(1 + excess)``; the structure tensor of its
    Gaussian gradient, integrated over ``integration`` metres, gives per pixel the
    dominant orientation and its coherent strength (λ1 - λ2), which is the
    weight.  Bins of ``angle_bin`` degrees over [0, 90); pixels within three
    sigmas of the image border are left out (a tile's border is no edge).
    """
    p = params
    nbins = int(round(90.0 / p.angle_bin))
    if not (img > 0).any():
        return np.zeros(nbins)
    ang, weight = orientation_field(img, p)
    border = int(math.ceil(3 * p.sigma))
    inner = np.zeros(img.shape, dtype=bool)
    if img.shape[0] > 2 * border and img.shape[1] > 2 * border:
        inner[border:-border, border:-border] = True
    idx = np.minimum((ang[inner] / p.angle_bin).astype(np.int64), nbins - 1)
    return np.bincount(idx, weights=weight[inner], minlength=nbins)


def orientation_field(img: np.ndarray, params: AlignmentSettings) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel of a density image: the dominant orientation modulo 90 degrees and its coherent strength.

    See :func:`image_orientation_histogram` (which bins these); both arrays have the image's shape.
    """
    p = params
    occ = img > 0
    if not occ.any():
        return np.zeros(img.shape), np.zeros(img.shape)
    floor_level = p.wall_factor * float(np.median(img[occ]))
    f = np.log1p(np.maximum(img - floor_level, 0.0))
    gy = ndimage.gaussian_filter(f, p.sigma, order=(1, 0), mode="nearest")
    gx = ndimage.gaussian_filter(f, p.sigma, order=(0, 1), mode="nearest")
    rho = p.integration / p.pixel
    jxx = ndimage.gaussian_filter(gx * gx, rho, mode="constant")
    jyy = ndimage.gaussian_filter(gy * gy, rho, mode="constant")
    jxy = ndimage.gaussian_filter(gx * gy, rho, mode="constant")
    weight = np.hypot(jxx - jyy, 2 * jxy)
    ang = np.mod(np.degrees(0.5 * np.arctan2(2 * jxy, jxx - jyy)), 90.0)
    return ang, weight


def coarse_yaw(hist: np.ndarray, angle_bin: float) -> float:
    """Peak (degrees in [0, 90)) of a summed orientation histogram, circularly smoothed and refined.

    The peak bin of the histogram smoothed by a 1-degree Gaussian (wrapping at
    90) is refined by the weighted circular mean of 4x the angle within 2
    degrees of it.
    """
    h = np.asarray(hist, dtype=np.float64)
    n = len(h)
    if not np.any(h > 0):
        return 0.0
    sm = ndimage.gaussian_filter1d(h, 1.0 / angle_bin, mode="wrap")
    k = int(np.argmax(sm))
    centres = (np.arange(n) + 0.5) * angle_bin
    off = ((centres - centres[k] + 45.0) % 90.0) - 45.0
    near = np.abs(off) <= 2.0
    z = np.sum(h[near] * np.exp(1j * np.radians(4 * off[near])))
    return float((centres[k] + math.degrees(np.angle(z)) / 4.0) % 90.0)


# -- pass 2: refinement by projection sharpness ---------------------------------------------

def wall_pixels(xy: np.ndarray, params: AlignmentSettings) -> tuple[np.ndarray, np.ndarray]:
    """Centres and counts of the pixels of a fine density image that are much denser than the median."""
    if len(xy) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    img, lo = density_image(xy, params.refine_pixel)
    return image_wall_pixels(img, lo, params)


def image_wall_pixels(img: np.ndarray, lo: np.ndarray, params: AlignmentSettings) -> tuple[np.ndarray, np.ndarray]:
    """Wall pixels of a fine image (``refine_pixel``): at least ``wall_factor`` times its median occupied pixel."""
    occ = img > 0
    if not occ.any():
        return np.zeros((0, 2)), np.zeros(0)
    med = float(np.median(img[occ]))
    rows, cols = np.nonzero(img >= max(params.wall_factor * med, 1.0))
    centres = lo + (np.stack([cols, rows], axis=1) + 0.5) * params.refine_pixel
    return centres, img[rows, cols].astype(np.float64)


def projection_sharpness(centres: np.ndarray, weights: np.ndarray, angles_deg: np.ndarray,
                         bin_width: float) -> np.ndarray:
    """Sum over both axes of the squared bin counts of weighted points projected at each angle."""
    out = np.zeros(len(angles_deg))
    if len(weights) == 0:
        return out
    for k, a in enumerate(np.radians(angles_deg)):
        c, s = math.cos(a), math.sin(a)
        for u in (c * centres[:, 0] + s * centres[:, 1], -s * centres[:, 0] + c * centres[:, 1]):
            b = np.floor(u / bin_width).astype(np.int64)
            h = np.bincount(b - b.min(), weights=weights)
            out[k] += float(np.dot(h, h))
    return out


def refine_angles(coarse_deg: float, params: AlignmentSettings) -> np.ndarray:
    k = int(round(params.refine_range / params.refine_step))
    return coarse_deg + params.refine_step * np.arange(-k, k + 1)


def parabolic_peak(x: np.ndarray, y: np.ndarray) -> float:
    """The maximum of ``y(x)`` (equally spaced x), refined by the parabola through its neighbours."""
    k = int(np.argmax(y))
    if 0 < k < len(y) - 1:
        y0, y1, y2 = y[k - 1], y[k], y[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            return float(x[k] + 0.5 * (y0 - y2) / den * (x[1] - x[0]))
    return float(x[k])


def tile_evidence(xy: np.ndarray, params: AlignmentSettings) -> dict[str, np.ndarray]:
    """Everything the frame estimate needs from one tile, from one read of its points.

    ``histogram``: the orientation histogram (pass 1); ``pixels``/``weights``: a
    deterministic sample (every k-th) of at most ``max_wall_pixels`` wall pixels of
    the fine image, for the refinement, which then needs no second read of the
    tile; ``cells``: centres of the occupied 1-metre cells (the tile's outline, for
    the extents along the axes).
    """
    p = params
    nbins = int(round(90.0 / p.angle_bin))
    if len(xy) < 16:
        return {"histogram": np.zeros(nbins), "pixels": np.zeros((0, 2)), "weights": np.zeros(0),
                "cells": np.zeros((0, 2))}
    # one pass over the points: the fine image; the coarser ones are its block sums
    fine, lo = density_image(xy, p.refine_pixel)
    k = max(1, int(round(p.pixel / p.refine_pixel)))
    coarse_params = dataclasses.replace(p, pixel=k * p.refine_pixel)
    out = {"histogram": image_orientation_histogram(block_sum(fine, k), coarse_params)}
    centres, weights = image_wall_pixels(fine, lo, p)
    step = max(1, -(-len(weights) // p.max_wall_pixels))
    out["pixels"], out["weights"] = centres[::step], weights[::step] * step
    m = max(1, int(round(1.0 / p.refine_pixel)))
    rows, cols = np.nonzero(block_sum(fine, m))
    out["cells"] = lo + (np.stack([cols, rows], axis=1) + 0.5) * (m * p.refine_pixel)
    return out


def refine_sample(evidence: dict[str, np.ndarray], coarse_deg: float, params: AlignmentSettings) -> dict[str, Any]:
    """One tile's sharpness curve around the coarse yaw, and its extent along the coarse axes."""
    angles = refine_angles(coarse_deg, params)
    a = math.radians(coarse_deg)
    c, s = math.cos(a), math.sin(a)
    pts = evidence["cells"]
    ext = None
    if len(pts):
        u = c * pts[:, 0] + s * pts[:, 1]
        v = -s * pts[:, 0] + c * pts[:, 1]
        ext = [float(u.min()), float(u.max()), float(v.min()), float(v.max())]
    return {"sharpness": projection_sharpness(evidence["pixels"], evidence["weights"], angles, params.refine_pixel),
            "extent": ext}


# -- the estimate over a tile store ------------------------------------------------------------

@dataclass
class Alignment:
    """The frame and the evidence it was estimated from (the ``meta/alignment`` document)."""

    frame: Frame
    coarse_deg: float
    refined_deg: float
    swapped: bool
    histogram: list[float]
    tiles: dict[str, dict[str, Any]]
    refine_angles: list[float]
    refine_sharpness: list[float]
    params: AlignmentSettings

    def to_doc(self) -> dict[str, Any]:
        return {"frame": self.frame.to_json(), "coarse_deg": self.coarse_deg, "refined_deg": self.refined_deg,
                "swapped": self.swapped, "angle_bin": self.params.angle_bin, "histogram": self.histogram,
                "tiles": self.tiles, "refine_angles": self.refine_angles,
                "refine_sharpness": self.refine_sharpness, "params": self.params.to_dict()}


def _tile_evidence(tile: str, store, params: AlignmentSettings) -> dict[str, np.ndarray]:
    return tile_evidence(store.xyz(tile)[:, :2], params)


def summarize_tile(hist: np.ndarray, angle_bin: float) -> dict[str, Any]:
    """Compact per-tile evidence: 1-degree histogram, its peak and total weight."""
    h = np.asarray(hist, dtype=np.float64)
    per = max(1, int(round(1.0 / angle_bin)))
    h1 = h[: len(h) // per * per].reshape(-1, per).sum(axis=1)
    return {"peak_deg": coarse_yaw(h, angle_bin) if h.any() else None, "weight": float(h.sum()),
            "histogram_1deg": [round(float(v), 3) for v in h1]}


def choose_frame(refined_deg: float, extents: list[list[float] | None],
                 origin: tuple[float, float, float]) -> tuple[Frame, bool]:
    """The frame with ``u`` along the longer extent (extents measured along the coarse axes)."""
    known = [e for e in extents if e is not None]
    swapped = False
    yaw = float(refined_deg)  # within refine_range of the coarse yaw: the same two axes
    if known:
        ext = np.array(known)
        du = ext[:, 1].max() - ext[:, 0].min()
        dv = ext[:, 3].max() - ext[:, 2].min()
        if dv > du:
            yaw += 90.0
            swapped = True
    return Frame(math.radians(yaw % 180.0), origin), swapped


def estimate_alignment(store, *, client=None, params: AlignmentSettings | None = None,
                       evidence: list[dict[str, np.ndarray]] | None = None) -> Alignment:
    """Estimate the building's aligned frame over a tile store: one pass over the tiles, then small tasks.

    ``evidence`` may pass the per-tile :func:`tile_evidence` (in tile order)
    when another pass already computed it, so that the tiles are read once.
    """
    p = params or AlignmentSettings()
    tiles = [t.name for t in store.tiles]
    if evidence is None:
        evidence = run_tasks(_tile_evidence, tiles, client=client, label="alignment evidence", keys=tiles,
                             extra_args=(store, p))
    hists = [e["histogram"] for e in evidence]
    total = np.sum(np.stack(hists), axis=0) if hists else np.zeros(int(round(90 / p.angle_bin)))
    coarse = coarse_yaw(total, p.angle_bin)
    items = client.scatter(list(evidence)) if client is not None else evidence
    refs = run_tasks(refine_sample, items, client=client, label="alignment refinement", keys=tiles,
                     extra_args=(coarse, p))
    angles = refine_angles(coarse, p)
    sharp = np.sum([r["sharpness"] for r in refs], axis=0) if refs else np.zeros(len(angles))
    refined = parabolic_peak(angles, sharp) if np.any(sharp > 0) else coarse
    origin = tuple(float(v) for v in store.meta.origin)
    frame, swapped = choose_frame(refined, [r["extent"] for r in refs], origin)
    per_tile = {t: summarize_tile(h, p.angle_bin) for t, h in zip(tiles, hists)}
    return Alignment(frame=frame, coarse_deg=float(coarse), refined_deg=float(refined % 90.0), swapped=swapped,
                     histogram=[round(float(v), 3) for v in total], tiles=per_tile,
                     refine_angles=[float(a) for a in angles], refine_sharpness=[float(v) for v in sharp],
                     params=p)
