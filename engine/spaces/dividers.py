"""Peak-gap-peak space dividers on a 1-D density histogram (paper section 3.1.1).

A wall or a slab shows as two peaks (its scanned faces) with a void between them, found by a bank of
peak-gap-peak filters with scale-free tests (contrast, prominence, void against the room level, evidence);
runs of empty bins are empty voids.  The filter and its tests: ``docs/design/spaces.md`` (peak-gap-peak
dividers).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage


@dataclass(frozen=True)
class DividerSettings:
    """Physical parameters (metres) of the divider search along one kind of axis.

    The defaults are for walls seen along a horizontal axis: most walls are
    0.10-0.35 m thick; the stop widths span 0.03-0.80 m to take thin drywall (a
    3-4 cm void between noisy faces) and thick structural or masonry walls too.
    See :func:`vertical_params` for slabs.
    """

    #: Histogram resolution.
    bin_width: float = 0.01
    #: Smallest and largest stop width δ (void thickness) and the number of widths between
    #: them (geometric progression).
    stop_min: float = 0.03
    stop_max: float = 0.80
    stop_steps: int = 14
    #: Pass widths c (width of each margin): from a crisp scanned face to a smeared one.
    pass_widths: tuple[float, ...] = (0.02, 0.04, 0.08, 0.16, 0.32)
    #: The gap may hold at most ``1 - min_contrast`` of the weaker margin's density.
    min_contrast: float = 0.6
    #: The stronger margin stands at least this many room levels above the gap: the void is bounded
    #: by a scanned face (a peak), not just the edges of an unscanned hole at the room's own level.
    #: (The other side may be unscanned: a wall seen from one room only.)
    min_prominence: float = 2.0
    #: In the upper band (above doors) the gap may hold at most this fraction of the room level
    #: on each side ...
    max_void_ratio: float = 0.35
    #: Without an upper band, over all heights at most this fraction (door jambs and thresholds
    #: fill a gap in part).
    max_void_ratio_full: float = 0.75
    #: Width of the window beyond each margin whose median density is the room level there.
    room_window: float = 1.0
    #: Two dividers are never closer than this (non-maximum suppression radius).
    min_spacing: float = 0.5
    #: The gap would hold at least this many points at the weaker margin's density.
    min_gap_points: float = 10.0
    #: A run of empty bins at least this long separates what lies on its two sides.
    empty_run: float = 1.0
    #: Across a shared face (merging only): a run at least ``empty_run`` long whose density, averaged
    #: over ``empty_smooth`` metres, stays at most this fraction of the scanned side's room level is
    #: empty too.  A few flying points or reflections in an unscanned stretch then no longer connect
    #: the two sides (they broke the strict run above).
    empty_fraction: float = 0.1
    empty_smooth: float = 0.1
    #: A void counts only where the upper band holds enough points beside it, never over all heights, and
    #: empty runs divide nothing: set for a storey whose floor was not scanned (:func:`engine.spaces.slicing.
    #: floor_scanned`), where furniture alone fills the histograms and the gaps between pieces look like
    #: walls' voids.  Not a user setting: decided per storey from its points.
    band_only: bool = False

    def bank(self) -> np.ndarray:
        """The filter bank as ``(k, 2)`` integer ``(δ, c)`` in bins, δ ≥ 1, c ≥ 1, no duplicates."""
        b = self.bin_width
        stops = np.geomspace(self.stop_min, self.stop_max, max(int(self.stop_steps), 1))
        ds = np.unique(np.maximum(1, np.round(stops / b).astype(int)))
        cs = np.unique(np.maximum(1, np.round(np.asarray(self.pass_widths, float) / b).astype(int)))
        return np.array([(d, c) for d in ds for c in cs], dtype=np.int64)

    def bins(self, metres: float) -> int:
        """A length in whole bins (at least one)."""
        return max(1, int(round(metres / self.bin_width)))

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["pass_widths"] = list(d["pass_widths"])
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> DividerSettings:
        known = {f.name for f in dataclasses.fields(cls)}
        d = {k.replace("-", "_"): v for k, v in d.items()}
        d = {k: v for k, v in d.items() if k in known}
        if "pass_widths" in d:
            d["pass_widths"] = tuple(float(v) for v in d["pass_widths"])
        return cls(**d)


def vertical_params(**overrides: Any) -> DividerSettings:
    """Defaults for storey dividers along z: the void between a ceiling and the next floor.

    A bare slab is 0.15-0.4 m; with a suspended ceiling and the unscanned plenum
    above it the void reaches 1.5 m and more, hence stop widths of 0.10-2.0 m.
    """
    base = dict(bin_width=0.02, stop_min=0.10, stop_max=2.0, stop_steps=14,
                pass_widths=(0.04, 0.08, 0.16, 0.32), min_spacing=0.5, empty_run=2.5, max_void_ratio_full=0.35)
    base.update(overrides)
    return DividerSettings(**base)


@dataclass
class Divider:
    """One divider found in a histogram (positions in the histogram's own coordinate, metres)."""

    position: float  # centre of the gap
    width: float  # stop width δ of the best filter
    margin: float  # pass width c of the best filter
    score: float  # ((L + R) / 2 - G) / room level: how far the margins stand above the gap, in room levels
    contrast: float  # 1 - G / min(L, R)
    void_ratio: float  # G / min(I_L, I_R)
    cut: int  # bin edge (index into the histogram) where the axis is cut

    def to_json(self) -> dict[str, Any]:
        return {k: (float(v) if isinstance(v, (float, np.floating)) else int(v))
                for k, v in dataclasses.asdict(self).items()}


@dataclass
class BankResponse:
    """Responses of a filter bank on a half-bin grid of gap centres.

    Row ``k`` is filter ``bank[k]``; column ``j`` is the gap centre ``j / 2`` bins
    from the start of the histogram.  ``left``, ``right``, ``gap`` are the mean
    densities (points per bin) of the two margins and the gap; positions where the
    filter does not fit inside the histogram hold ``-inf`` responses.
    """

    bank: np.ndarray
    response: np.ndarray
    left: np.ndarray
    right: np.ndarray
    gap: np.ndarray


def bank_responses(hist: np.ndarray, bank: np.ndarray) -> BankResponse:
    """Convolve the histogram with every peak-gap-peak filter of the bank (via cumulative sums)."""
    h = np.asarray(hist, dtype=np.float64)
    n = len(h)
    m = 2 * n + 1
    cs = np.concatenate(([0.0], np.cumsum(h)))
    k = len(bank)
    resp = np.full((k, m), -np.inf)
    left = np.zeros((k, m))
    right = np.zeros((k, m))
    gap = np.zeros((k, m))
    for row, (d, c) in enumerate(bank):
        # gap = bins [i, i + d), margins [i - c, i) and [i + d, i + d + c), all inside [0, n)
        i = np.arange(c, n - d - c + 1)
        if len(i) == 0:
            continue
        lm = (cs[i] - cs[i - c]) / c
        rm = (cs[i + d + c] - cs[i + d]) / c
        gm = (cs[i + d] - cs[i]) / d
        j = 2 * i + d
        resp[row, j] = np.minimum(lm, rm) - gm
        left[row, j], right[row, j], gap[row, j] = lm, rm, gm
    return BankResponse(np.asarray(bank), resp, left, right, gap)


def max_pool(br: BankResponse) -> tuple[np.ndarray, np.ndarray]:
    """Max-pooling over the bank: the best response per position and the filter giving it."""
    best = np.argmax(br.response, axis=0)
    return br.response[best, np.arange(br.response.shape[1])], best


def _margins(cs: np.ndarray, med: np.ndarray, i0, i1, i2, i3, d, c, ql, qr
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Mean density of the left margin ``[i0, i1)``, right margin ``[i2, i3)`` and gap ``[i1, i2)``
    (``cs``: cumulative counts), and the room level beside: the lower of the medians at ``ql`` and ``qr``."""
    lm = (cs[i1] - cs[i0]) / c
    rm = (cs[i3] - cs[i2]) / c
    gm = (cs[i2] - cs[i1]) / d
    return lm, rm, gm, np.minimum(med[ql], med[qr])


def non_maximum_suppression(score: np.ndarray, radius: int, valid: np.ndarray | None = None) -> np.ndarray:
    """Indices of positions that are the best valid score within ``radius`` positions (greedy, stable).

    Candidates are the local maxima of the valid scores; they are taken in
    decreasing score (ties: lower index first) and each suppresses every other
    candidate closer than or at ``radius``.
    """
    s = np.where(np.ones_like(score, bool) if valid is None else valid, score, -np.inf)
    finite = np.isfinite(s)
    if not finite.any():
        return np.zeros(0, dtype=np.int64)
    filled = np.where(finite, s, np.nanmin(s[finite]) - 1.0)
    local = ndimage.maximum_filter1d(filled, size=2 * radius + 1, mode="nearest")
    cand = np.flatnonzero(finite & (filled >= local))
    order = cand[np.lexsort((cand, -s[cand]))]
    kept: list[int] = []
    for j in order:
        if all(abs(int(j) - q) > radius for q in kept):
            kept.append(int(j))
    return np.array(sorted(kept), dtype=np.int64)


def empty_runs(hist: np.ndarray, min_bins: int) -> list[tuple[int, int]]:
    """Runs ``[a, b)`` of empty bins at least ``min_bins`` long (including runs at the two ends)."""
    empty = np.asarray(hist) <= 0
    if not empty.any():
        return []
    edges = np.diff(np.concatenate(([0], empty.astype(np.int8), [0])))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(a), int(b)) for a, b in zip(starts, stops) if b - a >= min_bins]


def nearly_empty_runs(hist: np.ndarray, min_bins: int, level: float, fraction: float, smooth_bins: int
                      ) -> list[tuple[int, int]]:
    """Runs ``[a, b)`` at least ``min_bins`` long where the density is at most ``fraction`` of ``level``.

    The density is the mean over ``smooth_bins`` bins, so that a few stray
    points (flying points, reflections: a real scan's artefacts) in an
    unscanned stretch do not break it, as they break :func:`empty_runs`.

    Parameters
    ----------
    hist
        Point counts per bin.
    min_bins
        Shortest run kept (bins).
    level
        The reference density (points per bin): the room level of the scanned side.
    fraction
        A bin is nearly empty when its smoothed density is at most ``fraction * level``.
    smooth_bins
        Width of the moving mean (bins).
    """
    h = np.asarray(hist, dtype=np.float64)
    if len(h) == 0 or level <= 0:
        return []
    mean = ndimage.uniform_filter1d(h, max(int(smooth_bins), 1), mode="nearest")
    return empty_runs(np.where(mean <= fraction * level, 0, 1), min_bins)


def occupied_extent(hist: np.ndarray) -> tuple[int, int] | None:
    """``[first, last + 1)`` of the non-empty bins, None if all are empty."""
    nz = np.flatnonzero(np.asarray(hist) > 0)
    if len(nz) == 0:
        return None
    return int(nz[0]), int(nz[-1]) + 1


def _evaluate(i, d, c, k, n: int, cs, med, ucs, umed, half: int, p: DividerSettings, pool) -> None:
    """Responses and tests of filters ``(d, c)`` (index ``k``) at gap starts ``i``; the valid ones are
    max-pooled into ``pool`` = (best score, best filter, contrast, void ratio) on the half-bin grid.

    ``i``, ``d``, ``c``, ``k`` broadcast together: scalars for one filter, or a
    column of filters against a row of positions.
    """
    best, best_k, best_contrast, best_ratio = pool
    fit = (i >= c) & (i + d + c <= n)
    i0, i2, i3 = np.clip(i - c, 0, n), np.minimum(i + d, n), np.minimum(i + d + c, n)
    ql = np.clip(i - c - half, 0, n - 1)
    qr = np.minimum(i + d + c + half, n - 1)
    lm, rm, gm, level = _margins(cs, med, i0, i, i2, i3, d, c, ql, qr)
    limit = np.full(np.broadcast(fit, lm).shape, -np.inf if p.band_only else p.max_void_ratio_full)
    if ucs is not None:
        # above the doors, where the band holds enough points beside the gap: test the band
        ulm, urm, ugm, ulevel = _margins(ucs, umed, i0, i, i2, i3, d, c, ql, qr)
        band = ulevel * d >= p.min_gap_points
        lm, rm, gm, level = (np.where(band, x, y) for x, y in ((ulm, lm), (urm, rm), (ugm, gm), (ulevel, level)))
        limit = np.where(band, p.max_void_ratio, limit)
    weaker = np.minimum(lm, rm)
    r = 0.5 * (lm + rm) - gm  # the paper's two margins, with the gap subtracted
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        contrast = np.where(weaker > 0, 1.0 - gm / weaker, -np.inf)
        ratio = np.where(level > 0, gm / level, np.inf)
        score = np.where(level > 0, r / level, -np.inf)
        prominence = np.where(level > 0, (np.maximum(lm, rm) - gm) / level, -np.inf)
    valid = (fit & (r > 0) & (contrast >= p.min_contrast) & (weaker * d >= p.min_gap_points) & (level > 0)
             & (ratio <= limit) & (prominence >= p.min_prominence))
    idx = np.nonzero(valid)
    if len(idx[0]) == 0:
        return
    shape = valid.shape
    jj = np.broadcast_to(2 * i + d, shape)[idx]  # gap centre on the half-bin grid
    kk = np.broadcast_to(k, shape)[idx]
    sc, co, ra = score[idx], contrast[idx], ratio[idx]
    # max-pooling over the bank at each gap centre: the best score, then the first filter
    order = np.lexsort((kk, -sc, jj))
    jj, kk, sc, co, ra = jj[order], kk[order], sc[order], co[order], ra[order]
    first = np.r_[True, jj[1:] != jj[:-1]]
    jj, kk, sc, co, ra = jj[first], kk[first], sc[first], co[first], ra[first]
    better = sc > best[jj]
    jj = jj[better]
    best[jj], best_k[jj], best_contrast[jj], best_ratio[jj] = sc[better], kk[better], co[better], ra[better]


def detect_dividers(hist: np.ndarray, params: DividerSettings | None = None, *, start: float = 0.0,
                    upper: np.ndarray | None = None) -> list[Divider]:
    """The peak-gap-peak dividers of a density histogram, in increasing position.

    Parameters
    ----------
    hist
        Point counts per bin of width ``params.bin_width`` (all heights).
    params
        The physical parameters (defaults: walls along a horizontal axis).
    start
        Coordinate (metres) of the histogram's first bin edge; positions are reported in it.
    upper
        Optional counts of the same bins for the points of the *upper band* only
        (above door height, see :mod:`engine.spaces.slicing`).  When given and the band
        holds enough points on both sides of a candidate, the void test is made in
        the band (``max_void_ratio``), where a wall is solid over its doors (door
        leaves, jambs and thresholds fill a wall's gap below) and a room's ceiling
        is continuous; otherwise over all heights (``max_void_ratio_full``).
    """
    p = params or DividerSettings()
    h = np.asarray(hist, dtype=np.float64)
    n = len(h)
    if n < 3:
        return []
    up = None if upper is None else np.asarray(upper, dtype=np.float64)
    if up is None and p.band_only:
        return []
    bank = p.bank()
    wb = p.bins(p.room_window)
    half = wb // 2
    cs = np.concatenate(([0.0], np.cumsum(h)))
    ucs = None if up is None else np.concatenate(([0.0], np.cumsum(up)))
    # room level: median of a window of room_window metres, centred half a window beyond each margin
    med = ndimage.median_filter(h, size=wb, mode="reflect")
    umed = None if up is None else ndimage.median_filter(up, size=wb, mode="reflect")
    m = 2 * n + 1
    best = np.full(m, -np.inf)
    best_k = np.full(m, -1, dtype=np.int64)
    best_contrast = np.zeros(m)
    best_ratio = np.zeros(m)
    pool = (best, best_k, best_contrast, best_ratio)
    if n * len(bank) <= 1 << 16:
        # short histograms (most of them): all filters at once on (filters x positions) arrays
        i = np.arange(n)[None, :]
        _evaluate(i, bank[:, :1], bank[:, 1:], np.arange(len(bank))[:, None], n, cs, med, ucs, umed, half, p, pool)
    else:
        for k, (d, c) in enumerate(bank):  # long ones: filter by filter, over the positions where it fits
            i = np.arange(c, n - d - c + 1)
            if len(i):
                _evaluate(i, d, c, k, n, cs, med, ucs, umed, half, p, pool)
    out: list[Divider] = []
    for j in non_maximum_suppression(best, 2 * p.bins(p.min_spacing), np.isfinite(best)):
        d, c = bank[best_k[j]]
        out.append(Divider(position=float(start + 0.5 * j * p.bin_width), width=int(d) * p.bin_width,
                           margin=int(c) * p.bin_width, score=float(best[j]),
                           contrast=float(best_contrast[j]), void_ratio=float(best_ratio[j]),
                           cut=int((int(j) + 1) // 2)))
    return out
