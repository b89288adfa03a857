"""Ceiling dividers: where a ceiling stops, or changes height, there is a wall (issue 8: hard buildings).

A room is closed above by its ceiling, a horizontal surface inside its
storey.  Some spaces have none there: a **stair tower** is a shaft through the
slabs, whose ceiling lies in the next storey (the underside of the slab above
the well), and an atrium or a double-height hall is open to the storey above.
Seen from a storey's upper band (above door height), such a space shows its
walls and the flight rising through it, but no horizontal surface above.

Peak-gap-peak (:mod:`engine.dividers`) measures a wall's void against the room
level *in the upper band* on both sides of a face, and the ridge search
(:mod:`engine.ridges`) needs a scanned ceiling on both sides: beside a shaft
the room level on the shaft's side is nothing, so neither can find the wall
between the shaft and its lobby, and the face reads open (h500-2storeys: the
lobby merged with the stair tower).  Yet a ceiling that stops at a line is
itself the evidence of a boundary: the part of a storey under a ceiling and
the part with none are not one room.  So, in the refinement of a large space
(:mod:`engine.refine`, where the space's points are in memory), a face without
a divider whose one side has a ceiling along most of it and whose other side
has none gets a ``"ceiling"`` divider (:func:`ceiling_dividers`).  Faces with
a ceiling on both sides (rooms of different ceiling heights included) or on
neither (inside the shaft, an unscanned room) are left as they were.

*The ceiling* is told from walls and from the rest of the upper band by its
shape (:meth:`engine.ridges.Occupancy.build` with ``max_span``): on a raster of
``pixel`` metres, a pixel is ceiling where its upper-band points lie within
``span`` metres of one height (a horizontal surface: scan noise and
registration offsets of a few cm), not where they run down the upper band (a
wall, a shaft's wall beside its landing: 0.3 m and more, from door height to
the ceiling).  A side has a ceiling along a stretch of the face where such a
pixel lies within ``side`` metres of it, and along the face where it has one
along at least ``min_scanned`` of it.

**Step lines.**  A room has one ceiling, and neighbouring rooms often have
different ones (a hallway lowered for ducts, a higher lobby or conference
room).  A line along which the ceiling changes height is a wall even where
its points show no void and no ridge: a glazed partition returns few points
(no ridge) and has no void between two faces, but the two rooms' ceilings
still meet at it at two heights.  :func:`step_lines` finds such lines on the
same raster (each ceiling pixel's height: the top of its points), the way
ridge lines are found (:mod:`engine.ridges`): in every ``chunk`` along an
axis, a pixel boundary is a step where the ``level_window`` metres on each
side are each covered by ceiling (``min_scanned``) *at one height* (their
spread between the 10 % and 90 % quantiles is below ``step``) and the two
heights differ by at least ``step``; steps are followed from chunk to chunk
and a line runs ``min_run`` metres at least.  A beam or a light panel under
the ceiling is no step: beside it a window holds the ceiling too (or the
beam's shadow on the ceiling, which is not scanned), so it is not at one
height; ``level_window`` (1 m, the room level's reach in the void test) is
wider than a beam and its shadow.  ``step`` (0.1 m) is well above the height
noise of a scanned ceiling (scan noise and registration offsets of a few cm;
a light panel's few cm).  The refinement adds the step lines to the ridge
lines: slicing cuts at them, and merging divides the stretch of a face they
cover.  What it cannot tell: a bulkhead or soffit at least ``level_window``
wide along a room's whole length would split the room (none of the generated
buildings lost by it).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from engine.merging import Edge
from engine.ridges import Occupancy, RidgeLine, RidgeParams, _lines


@dataclass(frozen=True)
class CeilingParams:
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

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "CeilingParams":
        known = {f.name for f in dataclasses.fields(cls)}
        d = {k.replace("-", "_"): v for k, v in d.items()}
        return cls(**{k: float(v) for k, v in d.items() if k in known})


def ceiling_occupancy(bu, bv, bz, band_z: int, p: CeilingParams, bin_width: float, z_bin: float) -> Occupancy:
    """Where a storey's points show a ceiling: pixels whose upper-band points span at most ``span`` in height."""
    pixel = max(1, int(round(p.pixel / bin_width)))
    span = int(round(p.span / z_bin))
    return Occupancy.build(bu, bv, bz, band_z, pixel, max_span=span)


def ceiling_dividers(edges: list[Edge], ceiling: Occupancy, p: CeilingParams, bin_width: float) -> list[Edge]:
    """The edges, those without a divider between a side with a ceiling and a side without one divided.

    A side has a ceiling along the face when at least ``min_scanned`` of the
    face's stretch has a ceiling pixel within ``side`` metres on that side
    (:meth:`engine.ridges.Occupancy.side_fraction`).  Returns new
    :class:`engine.merging.Edge` objects where a divider was added (kind
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


def step_lines(ceiling: Occupancy, p: CeilingParams, ridge_params: RidgeParams, bin_width: float, z_bin: float,
               ridges: Sequence[RidgeLine] = ()) -> list[RidgeLine]:
    """Lines along which the ceiling changes height (:class:`engine.ridges.RidgeLine`, in bins of ``bin_width``).

    In every ``ridge_params.chunk`` stretch along each axis, a pixel boundary is a step where the
    ``level_window`` metres of ceiling before it and after it are each covered over at least ``min_scanned``,
    each lie at one height (the spread between their ``1 - level_quantile`` and ``level_quantile`` quantiles is
    below ``step``: one ceiling, not a window that straddles the step, and not a beam with the ceiling beside
    it or its shadow), and their median heights differ by at least ``step`` metres.  Steps are followed from
    chunk to chunk like ridges (:func:`engine.ridges._lines`: a line runs ``min_run`` m at least, within one
    pixel); a line within ``min_spacing`` of a ridge line over the same stretch is that wall and is left out.
    """
    if p.step <= 0 or p.span <= 0 or ceiling.height is None or ceiling.scanned.size == 0:
        return []
    px = ceiling.pixel
    pm = px * bin_width
    s = max(1, int(round(p.level_window / pm)))
    c = max(1, int(round(ridge_params.chunk / pm)))
    rp = dataclasses.replace(ridge_params, drift=pm, width=pm)
    need = p.step / z_bin
    sp = int(round(ridge_params.min_spacing / bin_width))
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
        for r in _lines(mask, np.nan_to_num(diff), axis, 0, 0, 1, rp, pm):
            line = RidgeLine(axis, n0 + r.cut * px, tuple((a0 + a * c * px, a0 + b * c * px) for a, b in r.runs),
                             r.strength, n0 + (r.lo if r.lo is not None else r.cut) * px,
                             n0 + (r.hi if r.hi is not None else r.cut) * px)
            if any(q.axis == axis and abs(q.cut - line.cut) < sp
                   and any(q.covered(a, b) for a, b in line.runs) for q in ridges):
                continue
            out.append(line)
    return out
