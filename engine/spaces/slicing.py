"""Slicing the building into an over-segmented set of cells with peak-gap-peak dividers (paper 3.1.1).

Storeys first (z, over the whole building), then recursively along ``u`` and ``v`` per storey, one pass over
the tiles per level and one task per box searched; the void test is made in the upper band.
:mod:`engine.spaces.merging` merges the cells back.  Why and how: ``docs/design/spaces.md`` (slicing).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from engine.spaces.dividers import Divider, DividerSettings, detect_dividers, empty_runs
from engine.spaces.histograms import (
    BoxIndex,
    Grid,
    histogram_pass,
    segment_histograms,
    share,
    tile_extents,
    tiles_touching,
)
from tiles.tasks import run_tasks

AXES = ("u", "v", "z")


@dataclass
class Box:
    """A box of one storey in aligned bins: ``u`` in ``[u0, u1)``, ``v`` in ``[v0, v1)``."""

    floor: int
    u0: int
    u1: int
    v0: int
    v1: int
    quiet: int = 0  # axes searched without a new divider since the box was made
    final: bool = False
    count: int = 0
    level: int = 0
    next_axis: int = 0  # the next axis to search (0: u, 1: v)

    def range(self, axis: int) -> tuple[int, int]:
        return (self.u0, self.u1) if axis == 0 else (self.v0, self.v1)

    def with_range(self, axis: int, a: int, b: int, **kw: Any) -> Box:
        r = dict(u0=a, u1=b) if axis == 0 else dict(v0=a, v1=b)
        return dataclasses.replace(self, **r, **kw)

    def row(self) -> list[int]:
        return [self.floor, self.u0, self.u1, self.v0, self.v1]


@dataclass
class FoundDivider:
    """A divider as recorded in ``meta/spaces``: positions in aligned metres."""

    axis: str  # "u", "v" (walls) or "z" (storey slabs)
    floor: int  # storey it was found in (-1 for slabs)
    position: float  # centre of the void along the axis
    width: float
    score: float
    extent: list[float]  # along the other horizontal axis (walls) or [] (slabs)
    kind: str = "peak-gap-peak"  # or "empty": a run without points
    level: int = 0
    contrast: float = 1.0
    void_ratio: float = 0.0
    yaw: float | None = None  # the frame of position/extent when not the building's (a refined space; same origin)

    def to_json(self) -> dict[str, Any]:
        out = {"axis": self.axis, "floor": self.floor, "position": round(self.position, 4),
               "width": round(self.width, 4), "score": round(float(self.score), 4),
               "extent": [round(v, 4) for v in self.extent], "kind": self.kind, "level": self.level,
               "contrast": round(float(self.contrast), 4), "void_ratio": round(float(self.void_ratio), 4)}
        if self.yaw is not None:
            out["yaw"] = float(self.yaw)
        return out

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> FoundDivider:
        return cls(**{f.name: d[f.name] for f in dataclasses.fields(cls) if f.name in d})


@dataclass
class Split:
    """The result of one box's divider search along one axis (bins are global)."""

    pieces: list[tuple[int, int, int]]  # (start, stop, points)
    dividers: list[dict[str, Any]] = field(default_factory=list)  # Divider.to_json + "cut"
    empties: list[tuple[int, int]] = field(default_factory=list)


def split_histogram(hist: np.ndarray, lo: int, params: DividerSettings, upper: np.ndarray | None = None,
                    ridges: list[int] | tuple[int, ...] = (), inner_empties: bool = True) -> Split:
    """Cut a histogram (first bin ``lo``) at its dividers and empty runs into occupied pieces.

    ``upper`` is the histogram of the upper band (see :func:`engine.spaces.dividers.detect_dividers`).
    ``ridges`` are global bins of ridge lines that cut the box too (:mod:`engine.spaces.ridges`); one
    within ``min_spacing`` of a peak-gap-peak divider gives way to it.  Without ``inner_empties`` only the
    empty runs at the two ends trim the box (a storey whose floor was not scanned: a room's middle is empty).
    """
    h = np.asarray(hist)
    n = len(h)
    runs = empty_runs(h, params.bins(params.empty_run))
    if not inner_empties:
        runs = [(r0, r1) for r0, r1 in runs if r0 == 0 or r1 == n]
    divs = detect_dividers(h, params, start=lo * params.bin_width, upper=upper)
    sp = params.bins(params.min_spacing)
    kinds = ["peak-gap-peak"] * len(divs)
    for r in sorted(set(int(c) for c in ridges)):
        cut = r - lo
        if 0 < cut < n and all(abs(cut - d.cut) >= sp for d in divs):
            divs.append(Divider(position=float(r * params.bin_width), width=0.0, margin=0.0, score=0.0,
                                contrast=0.0, void_ratio=0.0, cut=cut))
            kinds.append("ridge")
    kind_of = {id(d): k for d, k in zip(divs, kinds)}
    cs = np.concatenate(([0], np.cumsum(h)))
    # occupied intervals between the long empty runs
    spans, a = [], 0
    for r0, r1 in runs:
        if r0 > a:
            spans.append((a, r0))
        a = r1
    if a < n:
        spans.append((a, n))
    pieces = []
    kept = []
    for s0, s1 in spans:
        cuts = sorted(d.cut for d in divs if s0 < d.cut < s1)
        kept += [d for d in divs if s0 < d.cut < s1]
        edges = [s0, *cuts, s1]
        for p0, p1 in zip(edges[:-1], edges[1:]):
            c = int(cs[p1] - cs[p0])
            if c > 0:
                pieces.append((lo + p0, lo + p1, c))
    inner = [(lo + r0, lo + r1) for r0, r1 in runs if r0 > 0 and r1 < n]
    return Split(pieces, [{**d.to_json(), "cut": lo + d.cut, "kind": kind_of[id(d)]} for d in kept], inner)


def _search(item: tuple, params: DividerSettings) -> Split:
    hist, upper, lo, ridges, inner_empties = item
    return split_histogram(hist, lo, params, upper, ridges, inner_empties)


def floor_levels(z_hist: np.ndarray, z_lo: int, floors: list[tuple[int, int]], z_bin: float,
                 search: float = 1.0) -> list[int]:
    """z bin of each storey's floor: the densest bin in the lowest ``search`` metres of the storey."""
    out = []
    for a, b in floors:
        top = min(b, a + max(1, int(round(search / z_bin))))
        out.append(a + int(np.argmax(z_hist[a - z_lo:top - z_lo])))
    return out


def floor_scanned(z_hist: np.ndarray, z_lo: int, floors: list[tuple[int, int]], ground: list[int], z_bin: float,
                  margin: float = 0.1, max_below: float = 0.05, bottom_share: float = 0.01
                  ) -> tuple[list[int], list[bool]]:
    """Whether each storey's floor was scanned, and its floor bin (the storey's bottom where it was not).

    A scanned floor is the lowest surface of its storey: at most ``max_below`` of
    the storey's points lie more than ``margin`` metres below it (noise, a few
    cm of registration error).  Where more do, the densest low bin
    (:func:`floor_levels`) is a furniture top (the floor was cropped away, as
    users often do before a segmentation, or never scanned), and the floor is
    taken at the bin below which ``bottom_share`` of the storey's points lie.
    """
    levels, scanned = [], []
    m = max(1, int(round(margin / z_bin)))
    for (a, b), g in zip(floors, ground):
        h = z_hist[a - z_lo:b - z_lo]
        total = float(h.sum())
        below = float(h[:max(0, g - m - a)].sum())
        ok = total <= 0 or below <= max_below * total
        scanned.append(bool(ok))
        levels.append(int(g) if ok else a + int(np.searchsorted(np.cumsum(h), bottom_share * total)))
    return levels, scanned


def find_storeys(z_hist: np.ndarray, z_lo: int, params: DividerSettings, min_height: float = 2.0
                 ) -> tuple[list[tuple[int, int]], list[FoundDivider]]:
    """Storeys as z-bin ranges from the building's z histogram, and the slab dividers between them.

    A storey is at least ``min_height`` tall: while a slab cut leaves a thinner
    piece beside it (e.g. above the ordinary ceilings, the higher ceilings of
    some rooms), the cut bounding the thinnest piece whose gap is the fullest
    (then the weakest) is dropped.
    """
    split = split_histogram(z_hist, z_lo, params)
    cuts = sorted(split.dividers, key=lambda d: d["cut"])
    min_bins = params.bins(min_height)
    cs = np.concatenate(([0], np.cumsum(z_hist)))
    # occupied stretches between empty runs; cuts subdivide them
    runs = [(a, b) for a, b, _ in _stretches(z_hist, z_lo, params)]
    while True:
        pieces = []  # (start, stop, index of the cut below or None, index of the cut above or None)
        for a, b in runs:
            inside = [k for k, d in enumerate(cuts) if a < d["cut"] < b]
            edges = [a] + [cuts[k]["cut"] for k in inside] + [b]
            marks = [None] + inside + [None]
            for i in range(len(edges) - 1):
                pieces.append((edges[i], edges[i + 1], marks[i], marks[i + 1]))
        thin = [p for p in pieces if p[1] - p[0] < min_bins and (p[2] is not None or p[3] is not None)]
        if not thin:
            break
        a, b, below, above = min(thin, key=lambda p: (p[1] - p[0], p[0]))
        bounding = [k for k in (below, above) if k is not None]
        # drop the less slab-like cut: the fuller gap (a real slab's void holds nothing), then the weaker
        drop = max(bounding, key=lambda k: (cuts[k]["void_ratio"], -cuts[k]["score"], k))
        cuts.pop(drop)
    floors = []
    for a, b, _, _ in pieces:
        if cs[b - z_lo] - cs[a - z_lo] > 0:
            floors.append((a, b))
    divs = [FoundDivider("z", -1, d["position"], d["width"], d["score"], [], level=0,
                         contrast=d["contrast"], void_ratio=d["void_ratio"]) for d in cuts]
    divs += [FoundDivider("z", -1, 0.5 * (a + b) * params.bin_width, (b - a) * params.bin_width, 0.0, [],
                          kind="empty") for a, b in split.empties]
    return floors, divs


def _stretches(hist: np.ndarray, lo: int, params: DividerSettings) -> list[tuple[int, int, int]]:
    """Occupied stretches ``(start, stop, points)`` (global bins) between runs of ``empty_run`` empty bins."""
    runs = empty_runs(hist, params.bins(params.empty_run))
    out, a, n = [], 0, len(hist)
    for r0, r1 in runs:
        if r0 > a:
            out.append((lo + a, lo + r0, int(np.sum(hist[a:r0]))))
        a = r1
    if a < n:
        out.append((lo + a, lo + n, int(np.sum(hist[a:n]))))
    return out


def slice_storeys(store, grid: Grid, floors: list[tuple[int, int]], start: list[Box], params: DividerSettings,
                  band_z: np.ndarray, *, client=None, max_levels: int = 8, ridges: list | None = None,
                  ridge_params=None, floor_scanned: np.ndarray | None = None
                  ) -> tuple[list[Box], list[FoundDivider], list[dict[str, Any]]]:
    """Recursive slicing of the storeys' boxes; returns the final cells, the dividers and per-pass stats.

    Each box has its next axis.  A box cut along an axis gives children that
    search the other axis next; a box searched along both axes without a new
    divider is final.  A box not searched yet (a storey) gets the histograms of
    both axes in the same pass, so that when its first axis has no divider the
    second is searched at once (one pass less).  ``band_z`` is the first z bin
    of each storey's upper band (points above door height).  ``ridges``
    (:class:`engine.spaces.ridges.RidgeLine`, with ``ridge_params``) also cut every box
    they run through far enough (:func:`engine.spaces.ridges.box_cuts`).  In a storey whose floor was not
    scanned (``floor_scanned`` False) an empty run inside a box divides nothing (a room's middle is empty).
    """
    from engine.spaces.ridges import box_cuts
    boxes = list(start)
    dividers: list[FoundDivider] = []
    stats: list[dict[str, Any]] = []
    order = np.argsort([-t.count for t in store.tiles], kind="stable")  # largest tiles first
    names = np.array([t.name for t in store.tiles])[order]
    extents = tile_extents(store, grid)[order]
    bw = grid.bin_width
    for level in range(1, max_levels + 1):
        active_ids = [i for i, b in enumerate(boxes) if not b.final]
        if not active_ids:
            break
        # per box: whether the other axis is wanted too (a box never searched)
        both = np.array([(not b.final) and b.quiet == 0 for b in boxes], dtype=bool)
        # only the tiles that touch a box still searched
        tiles = names[tiles_touching(extents, np.array(floors), np.array([boxes[i].row() for i in active_ids]))]
        hists, lo = _level_histograms(store, grid, floors, boxes, active_ids, both, list(tiles), band_z, client,
                                      level)

        def item(i: int, which: int) -> tuple[np.ndarray, np.ndarray, int, list[int], bool]:
            k = 4 * i + 2 * which
            cuts: list[int] = []
            if ridges:
                b = boxes[i]
                ax = b.next_axis if which == 0 else 1 - b.next_axis
                a0, a1 = b.range(ax)
                cuts = [r.cut for r in box_cuts(ridges, ax, a0, a1, b.range(1 - ax), ridge_params, bw)]
            inner = True if floor_scanned is None else bool(floor_scanned[boxes[i].floor])
            return hists[k] + hists[k + 1], hists[k + 1], int(lo[i, which]), cuts, inner

        firsts = run_tasks(_search, [item(i, 0) for i in active_ids], client=client,
                           label=f"dividers pass {level}", keys=active_ids, extra_args=(params,))
        # boxes never searched whose first axis is quiet: their second axis, from the same pass
        second_ids = [i for i, sp in zip(active_ids, firsts) if both[i] and _quiet(sp)]
        seconds = dict(zip(second_ids, run_tasks(_search, [item(i, 1) for i in second_ids], client=client,
                                                   label=f"dividers pass {level} (other axis)", keys=second_ids,
                                                   extra_args=(params,))))
        new, n_div = _next_boxes(boxes, active_ids, firsts, seconds, dividers, level, bw)
        stats.append({"pass": level, "searched": len(active_ids) + len(second_ids), "dividers": n_div,
                      "boxes": len(new), "tiles": len(tiles)})
        boxes = new
    for b in boxes:
        b.final = True
    boxes.sort(key=lambda b: (b.floor, b.u0, b.v0))
    return boxes, dividers, stats


def _level_histograms(store, grid: Grid, floors: list[tuple[int, int]], boxes: list[Box], active_ids: list[int],
                      both: np.ndarray, tiles: list[str], band_z: np.ndarray, client, level: int
                      ) -> tuple[list[np.ndarray], np.ndarray]:
    """One pass over ``tiles``: the histograms of the boxes still searched along their next axis, and along the
    other too where ``both``, keyed ``4 * box + 2 * (0: its axis, 1: the other) + band``; and their first bins."""
    index = BoxIndex.build(np.array(floors), np.array([b.row() for b in boxes]))
    axis_of = np.array([-1 if b.final else b.next_axis for b in boxes], dtype=np.int64)  # -1: final
    lo = np.zeros((len(boxes), 2), dtype=np.int64)
    length = np.zeros((len(boxes), 2), dtype=np.int64)
    for i in active_ids:
        b = boxes[i]
        for which, ax in enumerate((b.next_axis, 1 - b.next_axis)):
            if which == 0 or both[i]:
                lo[i, which], hi = b.range(ax)
                length[i, which] = hi - lo[i, which]
    hists = histogram_pass(segment_histograms, tiles, np.repeat(lo.ravel(), 2),
                           np.repeat(length.ravel(), 2), client=client, label=f"slicing pass {level}",
                           extra_args=(store, grid, share(client, index), axis_of, both, band_z))
    return hists, lo


def _next_boxes(boxes: list[Box], active_ids: list[int], firsts: list, seconds: dict[int, Any],
                dividers: list[FoundDivider], level: int, bw: float) -> tuple[list[Box], int]:
    """The boxes after a level's searches (``firsts``: along each active box's axis; ``seconds``: along the other
    axis of the boxes never searched whose first was quiet); the dividers found appended to ``dividers``."""
    new: list[Box] = [b for b in boxes if b.final]
    n_div = 0
    for i, sp in zip(active_ids, firsts):
        b = boxes[i]
        n_div += _record(dividers, b, b.next_axis, sp, level, bw)
        if not _quiet(sp):
            new += [b.with_range(b.next_axis, p0, p1, quiet=1, final=False, count=c, level=level,
                                 next_axis=1 - b.next_axis) for p0, p1, c in sp.pieces]
            continue
        p0, p1, c = sp.pieces[0]
        b = b.with_range(b.next_axis, p0, p1, count=c, level=level)
        if i not in seconds:
            new.append(dataclasses.replace(b, quiet=b.quiet + 1, final=b.quiet + 1 >= 2,
                                           next_axis=1 - b.next_axis))
            continue
        sp2 = seconds[i]
        other = 1 - b.next_axis
        n_div += _record(dividers, b, other, sp2, level, bw)
        if _quiet(sp2):
            q0, q1, c2 = sp2.pieces[0]
            new.append(b.with_range(other, q0, q1, quiet=2, final=True, count=c2))
        else:
            new += [b.with_range(other, q0, q1, quiet=1, final=False, count=c2, next_axis=b.next_axis)
                    for q0, q1, c2 in sp2.pieces]
    return new, n_div


def _quiet(sp: Split) -> bool:
    """No divider and no empty run inside: the box stays whole (its ends may be trimmed)."""
    return len(sp.pieces) == 1 and not sp.dividers


def _record(dividers: list[FoundDivider], b: Box, axis: int, sp: Split, level: int, bw: float) -> int:
    """Add a search's dividers (and empty runs) to the list, with their extent along the other axis."""
    other = (b.v0, b.v1) if axis == 0 else (b.u0, b.u1)
    extent = [other[0] * bw, other[1] * bw]
    for d in sp.dividers:
        dividers.append(FoundDivider(AXES[axis], b.floor, d["position"], d["width"], d["score"], extent,
                                     kind=d.get("kind", "peak-gap-peak"), level=level, contrast=d["contrast"],
                                     void_ratio=d["void_ratio"]))
    for a0, a1 in sp.empties:
        dividers.append(FoundDivider(AXES[axis], b.floor, 0.5 * (a0 + a1) * bw, (a1 - a0) * bw, 0.0, extent,
                                     kind="empty", level=level))
    return len(sp.dividers)
