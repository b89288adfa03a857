"""Merging the over-segmented cells into spaces (paper section 3.1.2).

Every shared face of two cells is tested for a divider (one histogram pass, one task per face); the cells are
then agglomerated through the faces without one, most open pair of groups first (:func:`agglomerate`: a
leaky face does not chain two rooms), and weak groups absorbed.  Why and how, with the measurements:
``docs/design/spaces.md`` (merging).
"""
from __future__ import annotations

import dataclasses
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from engine.spaces.dividers import DividerSettings, detect_dividers, empty_runs, nearly_empty_runs
from engine.spaces.histograms import BoxIndex, EdgeTables, Grid, edge_histograms, histogram_pass, share, tiles_by_size
from engine.spaces.slicing import Box
from tiles.tasks import run_tasks


@dataclass
class Edge:
    """Two cells of a storey sharing a face: ``a`` below, ``b`` above along ``axis`` at bin ``position``."""

    a: int
    b: int
    floor: int
    axis: int  # 0: the face is normal to u; 1: normal to v
    position: int
    overlap: tuple[int, int]  # bins along the other axis
    divider: dict[str, Any] | None = None
    tested: bool = False

    @property
    def length_bins(self) -> int:
        return self.overlap[1] - self.overlap[0]


def neighbour_edges(cells: list[Box], min_face_bins: int) -> list[Edge]:
    """All pairs of cells of a storey that share a face at least ``min_face_bins`` long."""
    edges: list[Edge] = []
    for axis in (0, 1):
        ends: dict[tuple[int, int], list[int]] = defaultdict(list)
        starts: dict[tuple[int, int], list[int]] = defaultdict(list)
        for i, c in enumerate(cells):
            lo, hi = c.range(axis)
            ends[(c.floor, hi)].append(i)
            starts[(c.floor, lo)].append(i)
        for key in sorted(ends):
            if key not in starts:
                continue
            for i in ends[key]:
                oi = cells[i].range(1 - axis)
                for j in starts[key]:
                    oj = cells[j].range(1 - axis)
                    o0, o1 = max(oi[0], oj[0]), min(oi[1], oj[1])
                    if o1 - o0 >= min_face_bins:
                        edges.append(Edge(i, j, key[0], axis, key[1], (o0, o1)))
    return edges


def build_edge_tables(index: BoxIndex, cells: list[Box], edges: list[Edge], window: int) -> EdgeTables:
    """Per storey block of the cells' arrangement, the edge on each of its four sides."""
    tables = [np.full((t.shape[0], t.shape[1], 4), -1, dtype=np.int64) for t in index.table]
    for e_id, e in enumerate(edges):
        f = e.floor
        ub, vb = index.ub[f], index.vb[f]
        along, other = (ub, vb) if e.axis == 0 else (vb, ub)
        o0, o1 = np.searchsorted(other, e.overlap[0]), np.searchsorted(other, e.overlap[1])
        for cell, side in ((e.a, 2 * e.axis + 1), (e.b, 2 * e.axis)):
            lo, hi = cells[cell].range(e.axis)
            a0, a1 = np.searchsorted(along, lo), np.searchsorted(along, hi)
            if e.axis == 0:
                tables[f][a0:a1, o0:o1, side] = e_id
            else:
                tables[f][o0:o1, a0:a1, side] = e_id
    flat = np.concatenate([t.reshape(-1) for t in tables] + [np.full(4, -1, np.int64)])
    return EdgeTables(flat, np.array([e.axis for e in edges], dtype=np.int64),
                      np.array([e.position for e in edges], dtype=np.int64), window)


def face_divider(hist: np.ndarray, support: tuple[int, int], position: int, window: int,
                 params: DividerSettings, upper: np.ndarray | None = None) -> dict[str, Any] | None:
    """The divider across a face, if any: a peak-gap-peak void containing it, or an empty run touching it.

    ``hist`` covers bins ``position - window ... position + window``; only
    ``support`` (the two cells' extent) is looked at; ``upper`` is the same for
    the upper band.
    """
    s0, s1 = support
    h = np.asarray(hist)[s0:s1]
    up = None if upper is None else np.asarray(upper)[s0:s1]
    first = position - window + s0  # global bin of h[0]
    bw = params.bin_width
    face = position * bw
    rel = window - s0  # index of the face in h
    # without a scanned floor, emptiness is no evidence (a room's middle is as empty as the way between rooms)
    runs = [] if params.band_only else empty_runs(h, params.bins(params.empty_run))
    if not params.band_only and not any(r0 <= rel <= r1 for r0, r1 in runs):
        # stray points in an unscanned stretch: the reference is the room level of the better scanned
        # side (the median over that side of the support)
        sides = [x for x in (h[:max(rel, 0)], h[max(rel, 0):]) if len(x)]
        level = max((float(np.median(x)) for x in sides), default=0.0)
        runs = nearly_empty_runs(h, params.bins(params.empty_run), level, params.empty_fraction,
                                 params.bins(params.empty_smooth))
    for r0, r1 in runs:
        if r0 <= rel <= r1:
            return {"kind": "empty", "position": (first + 0.5 * (r0 + r1)) * bw, "width": (r1 - r0) * bw,
                    "score": 0.0}
    best = None
    for d in detect_dividers(h, params, start=first * bw, upper=up):
        if abs(d.position - face) <= d.width / 2 + d.margin and (best is None or d.score > best.score):
            best = d
    if best is None or (params.band_only and up is not None and not _solid_below(h - up, best, first * bw, params)):
        return None
    return {"kind": "peak-gap-peak", **best.to_json()}


def _solid_below(lower: np.ndarray, d, start: float, params: DividerSettings) -> bool:
    """Whether a wall's void found in the upper band is one below it too (a wall stands on the floor).

    Without a scanned floor or ceiling, the gaps between beams or lamps are voids in the upper band as the
    gaps between furniture are below it; a wall's faces and void run through both.
    """
    low = dataclasses.replace(params, band_only=False)
    return any(abs(x.position - d.position) <= (x.width + d.width) / 2 + max(x.margin, d.margin)
               for x in detect_dividers(lower, low, start=start))


def _test(item: tuple[np.ndarray, np.ndarray, tuple[int, int], int, int, bool], params: DividerSettings
          ) -> dict[str, Any] | None:
    hist, upper, support, position, window, band_only = item
    if band_only:
        params = dataclasses.replace(params, band_only=True)
    return face_divider(hist, support, position, window, params, upper)


def test_edges(store, grid: Grid, floors: np.ndarray, cells: list[Box], edges: list[Edge], params: DividerSettings,
               window_m: float, band_z: np.ndarray, *, client=None, band_only: np.ndarray | None = None) -> None:
    """Fill ``edge.divider`` for every edge: one histogram pass over the tiles, one task per edge.

    ``band_only``: per storey, whether its faces are tested in the upper band alone (its floor was not scanned:
    :func:`engine.spaces.slicing.floor_scanned`).
    """
    if not edges:
        return
    window = params.bins(window_m)
    index = BoxIndex.build(floors, np.array([c.row() for c in cells]))
    tables = build_edge_tables(index, cells, edges, window)
    tiles = tiles_by_size(store)
    hists = histogram_pass(edge_histograms, tiles, np.zeros(2 * len(edges), dtype=np.int64),
                           np.full(2 * len(edges), 2 * window), client=client, label="merging: face histograms",
                           extra_args=(store, grid, share(client, index), share(client, tables), band_z))
    items = []
    for k, e in enumerate(edges):
        lo_a = cells[e.a].range(e.axis)[0]
        hi_b = cells[e.b].range(e.axis)[1]
        support = (max(0, lo_a - (e.position - window)), min(2 * window, hi_b - (e.position - window)))
        only = bool(band_only[e.floor]) if band_only is not None else False
        items.append((hists[2 * k] + hists[2 * k + 1], hists[2 * k + 1], support, e.position, window, only))
    results = run_tasks(_test, items, client=client, label="merging: face tests",
                        keys=list(range(len(edges))), extra_args=(params,))
    for e, r in zip(edges, results):
        e.divider, e.tested = r, True


def ridge_faces(edges: list[Edge], ridges: list, params, bin_width: float, occupancy=None) -> list[Edge]:
    """The edges with every face without a divider cut where a ridge line covers it (:mod:`engine.spaces.ridges`).

    A wall seen as one dense surface (two faces merged by registration errors,
    glass) has no void for :func:`face_divider` to find; the ridge line found
    in 2-D over the space's upper band stands in for it, on the stretch it
    covers (:func:`engine.spaces.ridges.face_pieces`): the covered pieces get a
    ``"ridge"`` divider, the rest stays open where the ceiling was scanned on
    both sides (``occupancy``, :class:`engine.spaces.ridges.Occupancy`) and is left out
    of the face elsewhere.
    """

    from engine.spaces.ridges import face_pieces

    if not ridges:
        return edges
    out: list[Edge] = []
    for e in edges:
        if e.divider is not None:
            out.append(e)
            continue
        for a, b, r in face_pieces(ridges, e.axis, e.position, e.overlap, params, bin_width, occupancy):
            div = None if r is None else {"kind": "ridge", "position": r.cut * bin_width, "width": 0.0,
                                          "score": 0.0}
            out.append(dataclasses.replace(e, overlap=(a, b), divider=div))
    return out


@dataclass
class MergeRules:
    """When two groups of cells are one space, and when a group is too weak to be a space.

    ``min_open_ratio`` and ``min_scanned_density`` drive the agglomeration (see
    :func:`agglomerate`); the other three the absorption of weak groups.
    """

    min_space_area: float = 1.0  # m²
    min_space_width: float = 0.5  # m
    min_relative_density: float = 0.02  # of the median space's points per m²
    #: Two groups join only when the faces without a divider between them are at least this fraction
    #: of the smaller group's boundary.
    min_open_ratio: float = 0.05
    #: A cell with fewer points per m² than this fraction of the median cell's is nearly unscanned: its
    #: faces to scanned cells are no evidence of an opening.
    min_scanned_density: float = 0.2


@dataclass
class Components:
    """Space label of each cell (-1: noise) and how it came about."""

    labels: np.ndarray
    absorbed: list[tuple[int, int]] = field(default_factory=list)  # (weak space, into space) by old labels
    dropped: list[int] = field(default_factory=list)
    #: Pairs of groups (cell ids of one member each) with faces without a divider that were kept apart.
    refused: list[tuple[int, int]] = field(default_factory=list)


def agglomerate(cells: list[Box], edges: list[Edge], bin_width: float, rules: MergeRules | None = None,
                band_only: np.ndarray | None = None) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Groups of cells joined through faces without a divider, most open pair first (a graph partition).

    Every cell starts as its own group.  For each pair of groups with faces
    without a divider between them, the *openness* is the total length of
    those faces over the boundary length of the smaller group (its cells'
    perimeters less twice the faces inside it).  Repeatedly the most open pair
    is joined (ties: the lowest pair of group ids), as long as its openness is
    at least ``min_open_ratio``.  Pairs that never qualify stay apart: a single
    leaky face (a wall whose divider was missed: registration errors, glass, a
    hidden wall) is a small part of the boundary of two real rooms and no
    longer chains them, and through them every room beyond, into one space,
    as connected components did.  Cells of one room share long faces (the
    room's width) and join first; a small cell has a short boundary, so its
    faces are a large part of it.

    A face between a scanned cell and a nearly unscanned one (fewer points
    per m² than ``min_scanned_density`` times the median cell with points:
    an unscanned room, the empty surroundings with a few flying points) is no
    evidence of an opening, only of not having looked: it does not count.
    Nearly unscanned cells still join each other, and weak groups are absorbed
    afterwards by :func:`merge` into ONE neighbour.  In a storey without a
    scanned floor (``band_only``, per storey) a thin cell is only a stretch
    of bare floor: there every cell counts as scanned.

    Parameters
    ----------
    cells
        The over-segmented cells.
    edges
        Their neighbour edges, each tested (``divider`` None: no divider across the face).
    bin_width
        Metres per bin of the cells' boxes.
    rules
        ``min_open_ratio`` and ``min_scanned_density``.

    Returns
    -------
    labels
        Group of each cell (the smallest cell id of the group).
    refused
        One ``(cell, cell)`` per pair of final groups with faces without a divider between them.
    """
    r = rules or MergeRules()
    n = len(cells)
    g = np.arange(n, dtype=np.int64)
    if n == 0 or not edges:
        return g, []
    ea = np.array([e.a for e in edges], dtype=np.int64)
    eb = np.array([e.b for e in edges], dtype=np.int64)
    length = np.array([e.length_bins for e in edges], dtype=np.float64) * bin_width
    box = np.array([[c.u0, c.u1, c.v0, c.v1] for c in cells], dtype=np.float64) * bin_width
    perimeter = 2.0 * ((box[:, 1] - box[:, 0]) + (box[:, 3] - box[:, 2]))
    sparse = _nearly_unscanned(cells, box, r.min_scanned_density, band_only)
    free = np.array([e.divider is None for e in edges], dtype=bool) & (sparse[ea] == sparse[eb])
    while True:
        ga, gb = g[ea], g[eb]
        cross = ga != gb
        open_ = cross & free
        if not open_.any():
            return g, []
        boundary = (np.bincount(g, weights=perimeter, minlength=n)
                    - np.bincount(ga[~cross], weights=2.0 * length[~cross], minlength=n))
        lo, hi = np.minimum(ga, gb)[open_], np.maximum(ga, gb)[open_]
        keys, inv = np.unique(lo * n + hi, return_inverse=True)
        face = np.bincount(inv.ravel(), weights=length[open_])
        pa, pb = keys // n, keys % n
        ratio = face / np.maximum(np.minimum(boundary[pa], boundary[pb]), 1e-12)
        ok = ratio >= r.min_open_ratio
        if not ok.any():
            return g, [(int(a), int(b)) for a, b in zip(pa, pb)]
        cand = np.flatnonzero(ok)
        j = cand[np.lexsort((keys[cand], -ratio[cand]))[0]]
        g[g == pb[j]] = pa[j]


def _nearly_unscanned(cells: list[Box], box: np.ndarray, min_density: float,
                      band_only: np.ndarray | None) -> np.ndarray:
    """Cells with fewer points per m² than ``min_density`` times the median scanned cell (never in a
    storey without a scanned floor, where a thin cell is bare floor)."""
    area = (box[:, 1] - box[:, 0]) * (box[:, 3] - box[:, 2])
    count = np.array([c.count for c in cells], dtype=np.float64)
    density = count / np.maximum(area, 1e-12)
    scanned = count > 0
    level = float(np.median(density[scanned])) if scanned.any() else 0.0
    sparse = density < min_density * level
    if band_only is not None:
        sparse &= ~np.asarray(band_only, dtype=bool)[np.array([c.floor for c in cells], dtype=np.int64)]
    return sparse


def merge(cells: list[Box], edges: list[Edge], bin_width: float, rules: MergeRules | None = None,
          band_only: np.ndarray | None = None) -> Components:
    """Agglomeration of the cells through faces without a divider, then absorption of weak groups (smallest first).

    ``band_only``: per storey, whether its floor was not scanned (see :func:`agglomerate`).
    """
    r = rules or MergeRules()
    n = len(cells)
    if n == 0:
        return Components(np.zeros(0, dtype=np.int64))
    ea = np.array([e.a for e in edges], dtype=np.int64)
    eb = np.array([e.b for e in edges], dtype=np.int64)
    elen = np.array([e.length_bins for e in edges], dtype=np.float64)
    ediv = np.array([e.divider is not None for e in edges], dtype=bool)
    groups, refused = agglomerate(cells, edges, bin_width, r, band_only)
    ids, labels = np.unique(groups, return_inverse=True)
    labels = labels.ravel().astype(np.int64)
    k_comps = len(ids)
    parent = np.arange(k_comps)
    dropped = np.zeros(k_comps, dtype=bool)

    def roots() -> np.ndarray:
        p = parent
        while True:
            q = p[p]
            if np.array_equal(q, p):
                return p
            p = q

    area = np.array([(c.u1 - c.u0) * (c.v1 - c.v0) * bin_width ** 2 for c in cells])
    count = np.array([c.count for c in cells], dtype=np.float64)
    bounds = np.array([[c.u0, c.u1, c.v0, c.v1] for c in cells], dtype=np.int64)
    absorbed: list[tuple[int, int]] = []
    big = np.iinfo(np.int64).max
    for _ in range(k_comps + 1):
        comp = roots()[labels]
        c_area = np.bincount(comp, weights=area, minlength=k_comps)
        c_count = np.bincount(comp, weights=count, minlength=k_comps)
        live = np.zeros(k_comps, dtype=bool)
        live[comp] = True
        live &= ~dropped
        dens = np.where(c_area > 0, c_count / np.maximum(c_area, 1e-12), 0.0)
        med = float(np.median(dens[live])) if live.any() else 0.0
        lo_u, lo_v = np.full(k_comps, big), np.full(k_comps, big)
        hi_u, hi_v = np.full(k_comps, -big), np.full(k_comps, -big)
        np.minimum.at(lo_u, comp, bounds[:, 0])
        np.maximum.at(hi_u, comp, bounds[:, 1])
        np.minimum.at(lo_v, comp, bounds[:, 2])
        np.maximum.at(hi_v, comp, bounds[:, 3])
        width = np.minimum(hi_u - lo_u, hi_v - lo_v) * bin_width
        weak = live & ((c_area < r.min_space_area) | (width < r.min_space_width) | (c_count == 0)
                       | (dens < r.min_relative_density * med))
        if not weak.any():
            break
        cand = np.flatnonzero(weak)
        k = int(cand[np.lexsort((cand, c_area[cand]))[0]])  # the smallest weak group
        ca, cb = comp[ea], comp[eb]
        touch = (ca == k) != (cb == k)
        other = np.where(ca == k, cb, ca)[touch]
        ok = ~dropped[other]
        other, length, div = other[ok], elen[touch][ok], ediv[touch][ok]
        if len(other) == 0:
            dropped[k] = True  # noise beyond the building: no neighbour to join
            continue
        free = np.bincount(other, weights=length * ~div, minlength=k_comps)
        divided = np.bincount(other, weights=length * div, minlength=k_comps)
        opts = np.unique(other)
        into = int(opts[np.lexsort((opts, -divided[opts], -free[opts]))[0]])
        parent[k] = into
        absorbed.append((k, into))
    comp = roots()[labels]
    out = np.full(n, -1, dtype=np.int64)
    keep = ~dropped[comp]
    ids, first = np.unique(comp[keep], return_index=True)
    order = ids[np.argsort(np.flatnonzero(keep)[first], kind="stable")]  # numbered by their first cell
    new = np.full(k_comps, -1, dtype=np.int64)
    new[order] = np.arange(len(order))
    out[keep] = new[comp[keep]]
    return Components(out, absorbed, [int(k) for k in np.flatnonzero(dropped)], refused)
