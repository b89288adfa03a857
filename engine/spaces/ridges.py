"""Ridge dividers: walls seen as ONE dense surface, with no void to find (issue 8: hard buildings).

In the refinement of a large space, a wall whose void is gone (faces registered apart, glass) still runs
continuously along a line above door height: ridges found per chunk of the upper band are followed from
chunk to chunk into ridge lines, which cut boxes (:func:`box_cuts`) and divide faces (:func:`face_pieces`).
Why and how: ``docs/design/spaces.md`` (ridge dividers).
"""
from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage


@dataclass(frozen=True)
class RidgeSettings:
    """Physical parameters (metres) and ratios of the ridge search; see the module docstring."""

    #: Ridge density in the low slice over the room level (0: no ridges).
    ratio: float = 1.25
    #: Height of the low slice: the lowest part of the upper band (metres).
    low: float = 0.1
    #: Width of the ridge window and the gap between it and each side window.
    width: float = 0.05
    gap: float = 0.05
    #: Side windows: each must hold at least ``min_side`` room levels.
    side: float = 0.5
    min_side: float = 0.3
    #: Length of the chunks along the wall, the drift allowed between chunks, the gaps bridged.
    chunk: float = 0.5
    drift: float = 0.02
    max_gap: float = 0.5
    #: Shortest ridge line, and closest two ridge lines.
    min_run: float = 3.0
    min_spacing: float = 0.5
    #: Merging: a stretch of a face no ridge line covers is open only when at least this long (metres).
    min_open: float = 1.0
    #: ... and only where the ceiling was scanned over at least this fraction of it on both sides.
    min_scanned: float = 0.5
    #: Pixel of the ceiling's occupancy raster (metres).
    occupancy_pixel: float = 0.1
    #: A chunk's room level is measured on coarse bins of this width (metres).
    level_bin: float = 0.1

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @staticmethod
    def bins(metres: float, bin_width: float) -> int:
        """A length in whole bins (at least one)."""
        return max(1, int(round(metres / bin_width)))

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RidgeSettings:
        known = {f.name for f in dataclasses.fields(cls)}
        d = {k.replace("-", "_"): v for k, v in d.items()}
        return cls(**{k: float(v) for k, v in d.items() if k in known})


@dataclass(frozen=True)
class RidgeLine:
    """A ridge line: normal to ``axis`` (0: u, 1: v) at bin edge ``cut``; ``runs`` along the other axis (bins).

    ``lo``/``hi``: the extent of its ridges along the normal (a wall at a small
    angle to the frame drifts); default ``cut``.
    """

    axis: int
    cut: int
    runs: tuple[tuple[int, int], ...]
    strength: float
    lo: int | None = None
    hi: int | None = None

    def near(self, position: int, tol: int) -> bool:
        """Whether a face at bin ``position`` lies within ``tol`` bins of the line's extent."""
        lo = self.cut if self.lo is None else self.lo
        hi = self.cut if self.hi is None else self.hi
        return lo - tol <= position <= hi + tol

    @property
    def length(self) -> int:
        return int(sum(b - a for a, b in self.runs))

    def covered(self, a: int, b: int) -> int:
        """Bins of ``[a, b)`` (along the other axis) covered by the runs."""
        return int(sum(max(0, min(b, r1) - max(a, r0)) for r0, r1 in self.runs))


def _runs(mask: np.ndarray, max_gap: int) -> list[tuple[int, int]]:
    """Runs ``[a, b)`` of True in a 1-D mask, gaps of at most ``max_gap`` False bridged."""
    m = np.asarray(mask, dtype=bool)
    if not m.any():
        return []
    if max_gap > 0:
        m = ndimage.binary_closing(np.pad(m, max_gap + 1), structure=np.ones(2 * max_gap + 1, bool))
        m = m[max_gap + 1:-(max_gap + 1)]
    edges = np.diff(np.concatenate(([0], m.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist()))


def _group_sums(h: np.ndarray, coarse: int) -> np.ndarray:
    """Points per group of ``coarse`` normal bins and chunk (whole groups only)."""
    nc = h.shape[0] // coarse
    return h[:nc * coarse].reshape(nc, coarse, h.shape[1]).sum(axis=1)


def chunk_level(hist2d: np.ndarray, coarse: int) -> np.ndarray:
    """Per chunk: the median density per bin of its occupied ``coarse``-bin groups (0: none occupied)."""
    sums = _group_sums(np.asarray(hist2d, dtype=np.float64), coarse)
    level = np.zeros(sums.shape[1])
    for j in np.flatnonzero((sums > 0).any(axis=0)):
        level[j] = np.median(sums[sums[:, j] > 0, j]) / coarse
    return level


def local_level(hist2d: np.ndarray, coarse: int, groups: int, offset: int = 0) -> np.ndarray:
    """Per (normal bin ``i``, chunk): the median density per bin of the occupied groups among the ``groups``
    ``coarse``-bin groups on each side of the one holding ``i + offset`` (left out: a wall stands there); 0
    where none is occupied.  Between rooms scanned at densities ``a`` and ``b``: near ``(a + b) / 2``."""
    sums = _group_sums(np.asarray(hist2d, dtype=np.float64), coarse)
    n, (nc, k) = len(hist2d), sums.shape
    if nc == 0:
        return np.zeros((n, k))
    r = max(1, int(groups))
    vals = np.pad(np.where(sums > 0, sums, np.nan), ((r, r), (0, 0)), constant_values=np.nan)
    win = np.lib.stride_tricks.sliding_window_view(vals, 2 * r + 1, axis=0)  # (nc, k, 2r + 1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN windows: no occupied group
        med = np.nan_to_num(np.nanmedian(np.delete(win, r, axis=-1), axis=-1), nan=0.0) / coarse
    return med[np.clip((np.arange(n) + offset) // coarse, 0, nc - 1)]


def ridge_mask(hist2d: np.ndarray, low2d: np.ndarray, p: RidgeSettings, bin_width: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """Per (normal bin, chunk) of an upper-band 2-D histogram: ridge found there, and its density ratio.

    ``hist2d[i, k]``: upper-band points in normal bin ``i`` (``bin_width``) and
    chunk ``k``; ``low2d`` the same for the low slice only.  Returns ``(mask,
    ratio)`` of the same shape; a ridge at ``i`` covers bins ``[i, i + width)``.
    """
    h = np.asarray(hist2d, dtype=np.float64)
    n, k = h.shape
    w = max(1, int(round(p.width / bin_width)))
    g = max(0, int(round(p.gap / bin_width)))
    s = max(1, int(round(p.side / bin_width)))
    lb = max(1, int(round(p.level_bin / bin_width)))
    # room level: the ceiling's density, the median of the occupied coarse bins over the chunk.  A side is
    # scanned when it holds min_side of the level beside the position (the median over the side windows) or
    # of the chunk's, whichever is lower: the chunk's is the level of the room that fills most of it, too
    # high beside a room scanned at a third of its density.
    level = chunk_level(h, lb)[None, :]
    beside = np.minimum(local_level(h, lb, max(1, int(round(s / lb))), w // 2), level)
    cs = np.vstack([np.zeros((1, k)), np.cumsum(h, axis=0)])
    cl = np.vstack([np.zeros((1, k)), np.cumsum(np.asarray(low2d, dtype=np.float64), axis=0)])
    i = np.arange(n)

    def mean(c: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        a, b = np.clip(a, 0, n), np.clip(b, 0, n)
        return (c[b] - c[a]) / np.maximum(b - a, 1)[:, None]

    ridge = mean(cl, i, i + w)
    left = mean(cs, i - g - s, i - g)
    right = mean(cs, i + w + g, i + w + g + s)
    fits = ((i - g - s >= 0) & (i + w + g + s <= n))[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(level > 0, ridge / level, 0.0)
    mask = (fits & (level > 0) & (ratio >= p.ratio) & (left >= p.min_side * beside)
            & (right >= p.min_side * beside))
    return mask, ratio


def find_ridges(normal: np.ndarray, along: np.ndarray, low: np.ndarray, axis: int, p: RidgeSettings,
                bin_width: float) -> list[RidgeLine]:
    """Ridge lines normal to ``axis`` from upper-band points' bins (``normal``, ``along``: int bins).

    ``low``: the points in the low slice (bool).  Positions are in the same
    bins as the input; runs are along the other axis.
    """
    if p.ratio <= 0 or len(normal) < 10:
        return []
    normal = np.asarray(normal, dtype=np.int64)
    along = np.asarray(along, dtype=np.int64)
    n0, a0 = int(normal.min()), int(along.min())
    cb = max(1, int(round(p.chunk / bin_width)))
    n = int(normal.max()) - n0 + 1
    kk = (along - a0) // cb
    k = int(kk.max()) + 1
    key = (normal - n0) * k + kk
    h = np.bincount(key, minlength=n * k).reshape(n, k)
    hl = np.bincount(key[np.asarray(low, dtype=bool)], minlength=n * k).reshape(n, k)
    mask, ratio = ridge_mask(h, hl, p, bin_width)
    return ridge_lines(mask, ratio, axis, n0, a0, cb, p, bin_width)


def ridge_lines(mask: np.ndarray, ratio: np.ndarray, axis: int, n0: int, a0: int, cb: int, p: RidgeSettings,
           bin_width: float) -> list[RidgeLine]:
    """Ridge lines from the per-(normal bin, chunk) ridge mask: chunks linked along the wall by tracking.

    A ridge in one chunk continues in the next when it lies within ``drift``
    of it (a wall at a small angle to the frame shifts a little from chunk to
    chunk; the two faces of a wall registered apart are two nearby ridges of
    the same line); gaps of up to ``max_gap`` are bridged.  Each connected
    set is one candidate, its position the median of its ridges, ``lo``/``hi``
    their extent; its runs of at least ``min_run`` are the line.
    """
    d = max(0, int(round(p.drift / bin_width)))
    gap = int(round(p.max_gap / p.chunk))
    wide = ndimage.maximum_filter1d(mask.astype(np.uint8), 2 * d + 1, axis=0) if d else mask.astype(np.uint8)
    if gap:
        wide = ndimage.maximum_filter1d(wide, 2 * gap + 1, axis=1)  # reach across the gaps ...
    comp, n_comp = ndimage.label(wide.astype(bool))
    if n_comp == 0:
        return []
    min_chunks = p.min_run / p.chunk
    w = max(1, int(round(p.width / bin_width)))
    ii, kk = np.nonzero(mask)  # ... but a line holds only the chunks with a ridge
    lab = comp[ii, kk]
    cand = []
    for c in range(1, n_comp + 1):
        sel = lab == c
        if not sel.any():
            continue
        ks = np.zeros(mask.shape[1], dtype=bool)
        ks[kk[sel]] = True
        runs = [r for r in _runs(ks, gap) if r[1] - r[0] >= min_chunks]
        if not runs:
            continue
        total = sum(b - a for a, b in runs)
        pos = ii[sel]
        strength = total + 1e-3 * float(np.mean(ratio[ii[sel], kk[sel]]))
        cand.append((strength, int(np.median(pos)), int(pos.min()), int(pos.max()), runs))
    out: list[RidgeLine] = []
    sp = max(1, int(round(p.min_spacing / bin_width)))
    for strength, i, lo, hi, runs in sorted(cand, key=lambda c: (-c[0], c[1])):
        clash = [r for r in out if abs(r.cut - (n0 + i + w // 2)) < sp
                 and any(r.covered(a0 + a * cb, a0 + b * cb) for a, b in runs)]
        if clash:
            continue
        out.append(RidgeLine(axis, n0 + i + w // 2, tuple((a0 + a * cb, a0 + b * cb) for a, b in runs),
                             float(strength), n0 + lo + w // 2, n0 + hi + w // 2))
    return sorted(out, key=lambda r: (r.axis, r.cut))


def space_ridges(bu: np.ndarray, bv: np.ndarray, bz: np.ndarray, band_z: int, z_bin: float, p: RidgeSettings,
                 bin_width: float) -> list[RidgeLine]:
    """Ridge lines along both axes from points' bins; ``band_z``: the first z bin of the upper band."""
    up = np.asarray(bz) >= band_z
    low = np.asarray(bz)[up] < band_z + max(1, int(round(p.low / z_bin)))
    bu, bv = np.asarray(bu)[up], np.asarray(bv)[up]
    return find_ridges(bu, bv, low, 0, p, bin_width) + find_ridges(bv, bu, low, 1, p, bin_width)


def box_cuts(ridges: list[RidgeLine], axis: int, lo: int, hi: int, other: tuple[int, int], p: RidgeSettings,
             bin_width: float, avoid: list[int] = ()) -> list[RidgeLine]:
    """Ridge lines that cut a box searched along ``axis`` over ``[lo, hi)``, ``other`` its range across.

    A line cuts when it lies ``min_spacing`` inside the box, runs at least
    ``min_run`` within the box's other range, and is ``min_spacing`` from every
    cut in ``avoid`` (the box's void dividers, which take precedence).
    """
    sp = max(1, int(round(p.min_spacing / bin_width)))
    need = p.min_run / bin_width
    out = []
    for r in ridges:
        if r.axis != axis or not (lo + sp <= r.cut <= hi - sp):
            continue
        if r.covered(*other) < need or any(abs(r.cut - c) < sp for c in avoid):
            continue
        out.append(r)
    return out


@dataclass(frozen=True)
class Occupancy:
    """Where the upper band (the ceiling) was scanned: a boolean raster of ``pixel`` bins from bin ``(u0, v0)``."""

    scanned: np.ndarray  # (u pixels, v pixels)
    u0: int
    v0: int
    pixel: int
    #: With ``max_span``: the top z bin of each scanned pixel's upper-band points (the ceiling's height), else None.
    height: np.ndarray | None = None

    @classmethod
    def build(cls, bu: np.ndarray, bv: np.ndarray, bz: np.ndarray, band_z: int, pixel: int,
              max_span: int | None = None) -> Occupancy:
        """From points' bins; ``band_z``: the first z bin of the upper band; ``pixel`` in bins.

        With ``max_span`` (z bins) a pixel counts only where its upper-band
        points span at most that many z bins: a horizontal surface (the
        ceiling), not a wall running down the band (:mod:`engine.spaces.ceilings`).
        """
        z = np.asarray(bz)
        up = z >= band_z
        if not up.any():
            return cls(np.zeros((0, 0), bool), 0, 0, pixel)
        pu, pv = np.asarray(bu)[up] // pixel, np.asarray(bv)[up] // pixel
        u0, v0 = int(pu.min()), int(pv.min())
        shape = (int(pu.max()) - u0 + 1, int(pv.max()) - v0 + 1)
        img = np.zeros(shape, dtype=bool)
        if max_span is None:
            img[pu - u0, pv - v0] = True
        else:
            key = (pu - u0) * shape[1] + (pv - v0)
            zu = z[up]
            order = np.lexsort((zu, key))
            ks, zs = key[order], zu[order]
            first = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
            last = np.r_[first[1:], len(ks)] - 1
            flat = img.reshape(-1)
            flat[ks[first]] = (zs[last] - zs[first]) <= max_span
            top = np.full(img.size, -1, dtype=np.int64)
            top[ks[first]] = zs[last]
            top[~flat] = -1
            return cls(img, u0 * pixel, v0 * pixel, pixel, top.reshape(shape))
        return cls(img, u0 * pixel, v0 * pixel, pixel)

    def side_profiles(self, axis: int, position: int, a: int, b: int, depth: int) -> tuple[np.ndarray, np.ndarray]:
        """Per pixel along the stretch ``[a, b)`` of a face (normal to ``axis`` at bin ``position``): whether a
        scanned pixel lies within ``depth`` bins of the face on each side (below, above)."""
        if self.scanned.size == 0 or b <= a:
            return np.zeros(0, bool), np.zeros(0, bool)
        img = self.scanned if axis == 0 else self.scanned.T
        n0, o0 = (self.u0, self.v0) if axis == 0 else (self.v0, self.u0)
        px = self.pixel
        ka, kb = (a - o0) // px, -(-(b - o0) // px)
        out = []
        for lo, hi in ((position - depth, position), (position, position + depth)):
            prof = np.zeros(max(kb - ka, 1), dtype=bool)
            ia, ib = max((lo - n0) // px, 0), min(-(-(hi - n0) // px), img.shape[0])
            ja, jb = max(ka, 0), min(kb, img.shape[1])
            if ib > ia and jb > ja:
                prof[ja - ka:jb - ka] = img[ia:ib, ja:jb].any(axis=0)
            out.append(prof)
        return out[0], out[1]

    def side_fraction(self, axis: int, position: int, a: int, b: int, depth: int) -> tuple[float, float]:
        """Fraction of the stretch ``[a, b)`` of a face (normal to ``axis`` at bin ``position``) with the ceiling
        scanned within ``depth`` bins on each side (below, above)."""
        below, above = self.side_profiles(axis, position, a, b, depth)
        if not len(below):
            return 0.0, 0.0
        return float(below.mean()), float(above.mean())


def face_pieces(ridges: list[RidgeLine], axis: int, position: int, overlap: tuple[int, int], p: RidgeSettings,
                bin_width: float, occupancy: Occupancy | None = None) -> list[tuple[int, int, RidgeLine | None]]:
    """A shared face (normal to ``axis`` at bin ``position``) cut into the pieces a ridge line covers and the rest.

    The ridge lines considered lie within ``width + drift`` of the face (the
    strongest first where two overlap).  Returns ``(a, b, ridge or None)`` over
    ``overlap`` in order; a face no ridge line touches is one piece with None.
    A partial wall (a spur inside an L-shaped room) divides only the stretch it
    covers: the two sides stay connected around its end.  When a face has a
    ridge, an uncovered stretch shows an opening only where the ceiling was
    scanned on both sides (``occupancy``: at least ``min_scanned`` of it within
    ``side`` metres); the others (beyond the building, where flying points
    stretched the cells) are left out of the face.
    """
    tol = int(round((p.width + p.drift) / bin_width))
    o0, o1 = overlap
    owner: list[tuple[int, int, RidgeLine]] = []
    for r in sorted((r for r in ridges if r.axis == axis and r.near(position, tol)),
                    key=lambda r: -r.strength):
        for a, b in r.runs:
            a, b = max(a, o0), min(b, o1)
            for x0, x1, _ in owner:  # keep only what stronger lines left uncovered
                if a < x1 and x0 < b:
                    a, b = (x1, b) if x0 <= a else (a, min(b, x0))
            if b > a:
                owner.append((a, b, r))
    if not owner:
        return [(o0, o1, None)]
    owner.sort(key=lambda t: t[0])
    # an uncovered stretch shorter than min_open (where a run ends early, short of a corner) is no opening:
    # it goes to the ridge piece before it (or after it, at the start of the face)
    short = max(1, int(round(p.min_open / bin_width)))
    out: list[list] = []
    at = o0
    for a, b, r in owner:
        if a > at:
            if a - at >= short:
                out.append([at, a, None])
            elif out:
                out[-1][1] = a
            else:
                a = at
        out.append([a, b, r])
        at = b
    if at < o1:
        if o1 - at >= short:
            out.append([at, o1, None])
        else:
            out[-1][1] = o1
    if occupancy is not None:
        depth = max(1, int(round(p.side / bin_width)))
        out = [x for x in out if x[2] is not None
               or min(occupancy.side_fraction(axis, position, x[0], x[1], depth)) >= p.min_scanned]
    return [(int(a), int(b), r) for a, b, r in out]
