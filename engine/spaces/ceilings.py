"""Ceiling dividers: where a ceiling stops, or changes height, there is a wall (issue 8: hard buildings).

In the refinement of a large space, a face between a side with a ceiling in the storey and a side without
one (a stair shaft beside its lobby) is divided (:func:`ceiling_dividers`), and lines along which the ceiling
changes height with a partition below (:func:`step_lines`, :func:`partition_support`) cut and divide like
ridge lines.  Why and how, and what it cannot tell: ``docs/design/spaces.md`` (ceiling dividers).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from engine.spaces.merging import Edge
from engine.spaces.ridges import Occupancy, RidgeLine, RidgeSettings, ridge_lines


@dataclass(frozen=True)
class CeilingSettings:
    """The ceiling tests of the refinement: faces to a side without a ceiling, step lines (metres, fractions)."""

    #: Points of one pixel within this height of each other are a horizontal surface (0: no ceiling dividers).
    span: float = 0.1
    #: Raster pixel.
    pixel: float = 0.1
    #: Depth of each side of a face searched for the ceiling.
    side: float = 0.5
    #: A side has a ceiling along a face when it has one along at least this fraction of the face.
    min_scanned: float = 0.5
    #: Two sides with a ceiling whose top levels differ by at least this much are under two ceilings (0: off).
    step: float = 0.1
    #: Each side of a step lies at one height over ``level_window`` m: the spread between the ``1 - level_quantile``
    #: and ``level_quantile`` quantiles of its ceiling pixels' heights is below ``step``.
    level_quantile: float = 0.9
    level_window: float = 1.0
    #: A step line divides only where at least this fraction of its ``ridges.chunk`` stretches hold a point
    #: within ``partition_tolerance`` of it between the floor band and the ceiling band: the partition under a
    #: step, which a soffit's free edge lacks (0: no test).
    min_partition: float = 0.5
    partition_tolerance: float = 0.1
    #: The floor band (above the storey's floor) and the ceiling band (below the lower ceiling of the step) left
    #: out of that test: floor, skirting, tracks, trims and fittings lie in them under a soffit's edge too.
    floor_band: float = 0.2
    ceiling_band: float = 0.2
    #: A stretch holds the partition only with a point in each half of that band (a partition stands at all
    #: heights; desks, chairs, counters and low cabinets stay in the lower half).
    both_halves: bool = True

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CeilingSettings:
        known = {f.name for f in dataclasses.fields(cls)}
        d = {k.replace("-", "_"): v for k, v in d.items()}
        types = {f.name: f.type for f in dataclasses.fields(cls)}
        return cls(**{k: (bool(v) if types[k] in ("bool", bool) else float(v)) for k, v in d.items() if k in known})


def ceiling_occupancy(bu, bv, bz, band_z: int, p: CeilingSettings, bin_width: float, z_bin: float) -> Occupancy:
    """Where a storey's points show a ceiling: pixels whose upper-band points span at most ``span`` in height."""
    pixel = max(1, int(round(p.pixel / bin_width)))
    span = int(round(p.span / z_bin))
    return Occupancy.build(bu, bv, bz, band_z, pixel, max_span=span)


def ceiling_dividers(edges: list[Edge], ceiling: Occupancy, p: CeilingSettings, bin_width: float) -> list[Edge]:
    """The edges, those without a divider between a side with a ceiling and a side without one divided.

    A side has a ceiling along the face when at least ``min_scanned`` of the
    face's stretch has a ceiling pixel within ``side`` metres on that side
    (:meth:`engine.spaces.ridges.Occupancy.side_fraction`).  Returns new
    :class:`engine.spaces.merging.Edge` objects where a divider was added (kind
    ``"ceiling"``, at the face), the others unchanged.
    """
    if p.span <= 0 or ceiling.scanned.size == 0:
        return edges
    depth = max(1, int(round(p.side / bin_width)))
    out = []
    for e in edges:
        if e.divider is None:
            below, above = ceiling.side_profiles(e.axis, e.position, e.overlap[0], e.overlap[1], depth)
            if len(below) and float(np.mean(below != above)) >= p.min_scanned:
                e = dataclasses.replace(e, divider={"kind": "ceiling", "position": e.position * bin_width,
                                                    "width": 0.0, "score": 0.0})
        out.append(e)
    return out


def _window_levels(h: np.ndarray, s: int, c: int, q: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For every pixel boundary ``i`` (0..n) along axis 0 and chunk ``k`` of ``c`` pixels along axis 1, over the
    ``s`` pixels before ``i`` in the chunk: the median ceiling height, its spread (the ``q`` quantile less the
    ``1 - q`` quantile) and the fraction of the window with a ceiling.

    ``h``: heights, -1 where no ceiling.  Returns three arrays of shape ``(n + 1, chunks)``; level and spread
    are NaN where the window holds no ceiling.
    """
    n, m = h.shape
    k = -(-m // c)
    hp = np.full((n + s, k * c), np.nan)
    hp[s:, :m] = np.where(h >= 0, h, np.nan)
    # the window ending at boundary i: rows i - s .. i - 1 of h, i.e. rows i .. i + s - 1 of hp
    win = np.lib.stride_tricks.sliding_window_view(hp, s, axis=0)[: n + 1]  # (n + 1, k * c, s)
    win = win.reshape(n + 1, k, c * s)
    valid = ~np.isnan(win)
    cnt = valid.sum(axis=2)
    cover = cnt / float(c * s)
    srt = np.sort(np.where(valid, win, np.inf), axis=2)  # the window's heights first, in order

    def quantile(f: float) -> np.ndarray:
        """``np.nanquantile(win, f, axis=2)`` (linear), vectorised (nanquantile loops over the windows)."""
        pos = np.maximum(cnt - 1, 0) * f
        i0 = np.floor(pos).astype(np.int64)
        i1 = np.minimum(i0 + 1, np.maximum(cnt - 1, 0))
        a = np.take_along_axis(srt, i0[..., None], axis=2)[..., 0]
        b = np.take_along_axis(srt, i1[..., None], axis=2)[..., 0]
        with np.errstate(invalid="ignore"):
            return np.where(cnt > 0, a + (b - a) * (pos - i0), np.nan)

    return quantile(0.5), quantile(q) - quantile(1.0 - q), cover


def partition_support(normal: np.ndarray, along: np.ndarray, start: int, chunk: int, centre: np.ndarray,
                      tolerance: int) -> np.ndarray:
    """Per ``chunk``-bin stretch ``k`` along a line (from bin ``start``): whether a point lies within ``tolerance``
    bins of ``centre[k]``, the line's position in that stretch.

    ``normal``, ``along``: the bins of the points across and along the line (the caller keeps only those
    between the floor band and the ceiling band).  A partition under a step (glass, its mullions and rails, a
    door leaf or the transom over a door) returns points in nearly every stretch; the free edge of a soffit
    has open air under it, and only furniture that happens to stand there.
    """
    n = len(centre)
    k = (np.asarray(along) - start) // chunk
    inside = (k >= 0) & (k < n)
    k = k[inside]
    near = np.abs(np.asarray(normal)[inside] - centre[k]) <= tolerance
    return np.bincount(k[near], minlength=n)[:n] > 0


def step_lines(ceiling: Occupancy, p: CeilingSettings, ridge_params: RidgeSettings, bin_width: float, z_bin: float,
               ridges: Sequence[RidgeLine] = (), *, points: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
               floor_z: int | None = None) -> list[RidgeLine]:
    """Lines along which the ceiling changes height over a partition (:class:`engine.spaces.ridges.RidgeLine`, in bins
    of ``bin_width``).

    In every ``ridge_params.chunk`` stretch along each axis, a pixel boundary is a step where the
    ``level_window`` metres of ceiling before it and after it are each covered over at least ``min_scanned``,
    each lie at one height (the spread between their ``1 - level_quantile`` and ``level_quantile`` quantiles is
    below ``step``: one ceiling, not a window that straddles the step, and not a beam with the ceiling beside
    it or its shadow), and their median heights differ by at least ``step`` metres.  Steps are followed from
    chunk to chunk like ridges (:func:`engine.spaces.ridges.ridge_lines`: a line runs ``min_run`` m at least, within one
    pixel); where a ridge line runs within ``min_spacing`` of it, that stretch is the ridge's wall and is left out
    (the rest of the line is kept where it runs ``min_run`` m at least: a wall seen as a ridge along part of its
    length and as a ceiling step along the rest).

    With ``min_partition`` > 0 a run of a line is kept only where a partition stands under it
    (:func:`partition_support`): at least ``min_partition`` of its chunks, its first and last (the walls it
    meets) not counted, hold a point of ``points`` (the space's ``bu``, ``bv``, ``bz`` bins, all heights)
    within ``partition_tolerance`` of the line's position in that chunk, higher than ``floor_band`` over the
    floor (``floor_z``, a z bin) and lower than ``ceiling_band`` under the lower of the step's two ceilings
    (with ``both_halves``, one in each half of that band).  A soffit's or bulkhead's free edge is no wall.
    """
    if p.step <= 0 or p.span <= 0 or ceiling.height is None or ceiling.scanned.size == 0:
        return []
    test = p.min_partition > 0
    if test and (points is None or floor_z is None):
        raise ValueError("step_lines: min_partition > 0 needs the space's points and floor_z")
    px = ceiling.pixel
    pm = px * bin_width
    s = max(1, int(round(p.level_window / pm)))
    c = max(1, int(round(ridge_params.chunk / pm)))
    rp = dataclasses.replace(ridge_params, drift=pm, width=pm)
    need = p.step / z_bin
    sp = int(round(ridge_params.min_spacing / bin_width))
    band = _partition_band(ceiling, p, bin_width, z_bin, c, points, floor_z) if test else None
    out: list[RidgeLine] = []
    for axis in (0, 1):
        h = ceiling.height if axis == 0 else ceiling.height.T
        n0, a0 = (ceiling.u0, ceiling.v0) if axis == 0 else (ceiling.v0, ceiling.u0)
        before, spread_b, cov_b = _window_levels(h, s, c, p.level_quantile)
        after, spread_a, cov_a = (x[::-1] for x in _window_levels(h[::-1], s, c, p.level_quantile))
        # (reversed: the s pixels from boundary i on)
        with np.errstate(invalid="ignore"):
            diff = np.abs(before - after)
            mask = ((cov_b >= p.min_scanned) & (cov_a >= p.min_scanned) & (diff >= need)
                    & (spread_b < need) & (spread_a < need))
        if band is not None:
            normal, along = (band.pu, band.pv) if axis == 0 else (band.pv, band.pu)
            lower = np.fmin(before, after)  # the lower ceiling's level at each step (z bins)
        for r in ridge_lines(mask, np.nan_to_num(diff), axis, 0, 0, 1, rp, pm):
            line = RidgeLine(axis, n0 + r.cut * px, tuple((a0 + a * c * px, a0 + b * c * px) for a, b in r.runs),
                             r.strength, n0 + (r.lo if r.lo is not None else r.cut) * px,
                             n0 + (r.hi if r.hi is not None else r.cut) * px)
            runs = line.runs
            if band is not None:
                runs = _held_runs(r, mask, lower, normal, along, band, n0, a0, px, p)
            # where a ridge line within min_spacing runs beside it, that is the same wall: only the rest counts
            same = [q for q in ridges if q.axis == axis and abs(q.cut - line.cut) < sp]
            runs = uncovered_runs(runs, same, int(round(ridge_params.min_run / bin_width))) if same else runs
            if runs:
                out.append(dataclasses.replace(line, runs=runs))
    return out


def uncovered_runs(runs: Sequence[tuple[int, int]], lines: Sequence[RidgeLine], min_length: int
                   ) -> tuple[tuple[int, int], ...]:
    """The pieces of ``runs`` (``[a, b)`` bins) that none of the runs of ``lines`` covers, those of at least
    ``min_length`` bins."""
    cover = sorted(r for q in lines for r in q.runs)
    out = []
    for a, b in runs:
        for c0, c1 in cover:
            if c1 <= a or c0 >= b:
                continue
            if c0 - a >= min_length:
                out.append((a, c0))
            a = max(a, c1)
        if b - a >= min_length:
            out.append((a, b))
    return tuple(out)


@dataclass
class _PartitionBand:
    """The points of the partition test (bins): above the floor band and below the highest ceiling; the
    test's tolerance (bins), its chunk (bins) and the ceiling band (z bins)."""

    pu: np.ndarray
    pv: np.ndarray
    pz: np.ndarray
    z_lo: int
    tol: int
    cb: int
    ceil_band: int


def _partition_band(ceiling: Occupancy, p: CeilingSettings, bin_width: float, z_bin: float, c: int,
                    points, floor_z) -> _PartitionBand:
    """The points that may hold a partition under some step line (see :func:`step_lines`)."""
    px = ceiling.pixel
    bz = np.asarray(points[2])
    z_lo = floor_z + int(round(p.floor_band / z_bin))
    top = int(np.max(ceiling.height))
    band = (bz >= z_lo) & (bz < top)  # the vertical band of every line lies within this one
    pu, pv, pz = np.asarray(points[0])[band], np.asarray(points[1])[band], bz[band]
    tol = int(round(p.partition_tolerance / bin_width))
    cb = c * px
    ceil_band = int(round(p.ceiling_band / z_bin))
    return _PartitionBand(pu, pv, pz, z_lo, tol, cb, ceil_band)


def _held_runs(r, mask: np.ndarray, lower: np.ndarray, normal: np.ndarray, along: np.ndarray,
               band: _PartitionBand, n0: int, a0: int, px: int, p: CeilingSettings) -> tuple:
    """The runs of the step line ``r`` (in ``band.cb`` chunks) under which a partition stands."""
    cb, tol, z_lo, pz = band.cb, band.tol, band.z_lo, band.pz
    # the line's position in each chunk: the mean of its steps there (its cut where it has none)
    lo, hi = (r.lo if r.lo is not None else r.cut), (r.hi if r.hi is not None else r.cut)
    m = mask[lo:hi + 1]
    cnt = m.sum(axis=0)
    pos = np.where(cnt > 0, (m * np.arange(lo, hi + 1)[:, None]).sum(axis=0) / np.maximum(cnt, 1), r.cut)
    centre = n0 + pos * px
    z_hi = float(np.median(lower[lo:hi + 1][m])) - band.ceil_band  # under the lower ceiling
    if p.both_halves:  # points at all heights, not furniture only: in each half of the band
        mid = 0.5 * (z_lo + z_hi)
        low_half, high_half = pz < mid, (pz >= mid) & (pz < z_hi)
        held = (partition_support(normal[low_half], along[low_half], a0, cb, centre, tol)
                & partition_support(normal[high_half], along[high_half], a0, cb, centre, tol))
    else:
        sel = pz < z_hi
        held = partition_support(normal[sel], along[sel], a0, cb, centre, tol)
    # a run's end chunks are left out: the walls it meets stand there under a soffit's edge too
    return tuple((a0 + a * cb, a0 + b * cb) for a, b in r.runs
                 if b - a > 2 and held[a + 1:b - 1].mean() >= p.min_partition)
