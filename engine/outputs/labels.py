"""From detections to per-point labels and ``elements.json`` (paper section 5.3, "points" granularity).

A point takes the class and element id of the first detection whose box (world
centre, size, yaw), grown by ``label-margin`` metres (scan noise), holds it; the
detections of the ``label-first`` classes (ceilings and floors: their boxes are
their surfaces' thin tightest boxes, and the floor under a table is the floor's)
come first, then the others by decreasing score.  With ``label-occupied`` only
the occupied cells of the box cut into K x K x K (the proposal's pattern ``B``,
its window's in the dictionary) count: the rule before 2026-12-05, which left
the parts of an element its window's pattern lacks as clutter
(docs/experiments/detection.md, "Point labels from whole boxes").  Points in no
detection are clutter (12) with element id -1.  One task per tile writes ``classification``
(uint8) and ``element_id`` (int32); only the detections whose bounds meet the
tile are sent to it.
"""
from __future__ import annotations

import json
import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from engine import config
from engine.detection.moments import column_bounds
from engine.detection.proposals import Proposal
from tiles import paths
from tiles.classes import CLUTTER, ELEMENT_CLASSES, element_class_list
from tiles.schema import RESULT_NONE, Dimension
from tiles.tasks import run_tasks


def _boxes(elements: Sequence[Proposal], occupied: bool = True) -> dict[str, np.ndarray]:
    """The detections as arrays for :func:`label_arrays`; without ``occupied`` every cell of a box counts."""
    n = len(elements)
    k = max((np.asarray(e.occupancy).shape[0] for e in elements), default=1) if occupied else 1
    out = {"center": np.zeros((n, 3)), "size": np.zeros((n, 3)), "yaw": np.zeros(n), "score": np.zeros(n),
           "cls": np.zeros(n, np.uint8), "eid": np.zeros(n, np.int32), "space": np.zeros(n, np.int64),
           "occ": np.ones((n, k, k, k), bool)}
    for i, e in enumerate(elements):
        out["center"][i], out["size"][i], out["yaw"][i] = e.center, e.world_size, e.yaw
        out["space"][i] = e.space_id
        out["score"][i], out["cls"][i], out["eid"][i] = e.score, e.class_code, e.element_id
        if not occupied:  # every cell counts: the ones already set
            continue
        occ = np.asarray(e.occupancy, dtype=bool)
        if occ.shape == (k, k, k):
            out["occ"][i] = occ
        elif occ.size:  # another K: nearest-cell resampling
            src = (np.arange(k) * occ.shape[0]) // k
            out["occ"][i] = occ[np.ix_(src, src, src)]
    return out


def _world_bounds(b: dict[str, np.ndarray], margin: float) -> np.ndarray:
    c, s = np.abs(np.cos(b["yaw"])), np.abs(np.sin(b["yaw"]))
    hx = (c * b["size"][:, 0] + s * b["size"][:, 1]) / 2 + margin
    hy = (s * b["size"][:, 0] + c * b["size"][:, 1]) / 2 + margin
    h = np.stack([hx, hy, b["size"][:, 2] / 2 + margin], axis=1)
    return np.concatenate([b["center"] - h, b["center"] + h], axis=1)


#: (cell, box) entries of the bucket grid built at once (bounds the memory of a batch: ~100 bytes each).
PAIR_BATCH = 2_000_000
#: Points labelled at once (bounds the memory of a batch: ~100 bytes each).
POINT_BATCH = 1_000_000
#: (cell, box) entries the bucket grid may hold; its cells grow until the boxes fit.
CELL_BUDGET = 8_000_000
#: Grids of at most this many cells get a dense table of each cell's first entry (else a binary search).
DENSE_CELLS = 4_000_000


def _bucket_grid(bx: dict[str, np.ndarray], bounds: np.ndarray, cos: np.ndarray, sin: np.ndarray, margin: float,
                 lo: np.ndarray, hi: np.ndarray, cell: float) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Cell size, grid shape and the sorted ``(cell, box)`` entries of boxes over the points' extent.

    Each box (rank order) is entered in the cells of its axis-aligned ``bounds``
    clipped to ``[lo, hi]`` that may hold a point of the box: a cell whose
    bounding sphere lies wholly outside the turned box grown by ``margin`` (plus a
    micrometre for rounding) is left out, so a wall turned 20 degrees is not
    tested against the whole rectangle around it.  The cells double until the
    entries fit :data:`CELL_BUDGET`.  Entries are sorted by cell, then by box, so
    a cell's candidates come best first.
    """
    while True:
        shape = np.maximum(np.floor((hi - lo) / cell).astype(np.int64) + 1, 1)
        a = np.clip(np.floor((bounds[:, :3] - lo) / cell).astype(np.int64), 0, shape - 1)
        b = np.clip(np.floor((bounds[:, 3:] - lo) / cell).astype(np.int64), 0, shape - 1)
        ext = b - a + 1
        per_box = ext.prod(axis=1)
        if int(per_box.sum()) <= CELL_BUDGET or cell > 1e6:
            break
        cell *= 2.0
    total = int(per_box.sum())
    first = np.cumsum(per_box) - per_box
    reach = np.maximum(bx["size"], 1e-9) / 2 + margin + cell * np.sqrt(3) / 2 + 1e-6 + 1e-12 * np.abs(hi - lo).max()
    flats, boxes = [], []
    for s in range(0, total, PAIR_BATCH):
        e = np.arange(s, min(s + PAIR_BATCH, total))
        box = np.searchsorted(first, e, side="right") - 1
        # position of each entry inside its box's block of cells, unravelled along the box's extent
        within = e - first[box]
        ex = ext[box]
        cz = within % ex[:, 2]
        rest = within // ex[:, 2]
        cy, cx = rest % ex[:, 1], rest // ex[:, 1]
        g = a[box] + np.stack([cx, cy, cz], axis=1)
        d = lo + (g + 0.5) * cell - bx["center"][box]
        c, sn = cos[box], sin[box]
        local = np.abs(np.stack([c * d[:, 0] + sn * d[:, 1], -sn * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1))
        keep = np.all(local <= reach[box], axis=1)
        g, box = g[keep], box[keep]
        flats.append((g[:, 0] * shape[1] + g[:, 1]) * shape[2] + g[:, 2])
        boxes.append(box)
    flat = np.concatenate(flats) if flats else np.zeros(0, np.int64)
    box = np.concatenate(boxes) if boxes else np.zeros(0, np.int64)
    order = np.lexsort((box, flat))
    return cell, shape, flat[order], box[order]


def _contains(p: np.ndarray, i: np.ndarray, boxes: dict[str, np.ndarray], bounds: np.ndarray,
              cos: np.ndarray, sin: np.ndarray, margin: float) -> np.ndarray:
    """Whether each point ``p[j]`` lies in an occupied sub-box (grown by ``margin``) of box ``i[j]``.

    The same arithmetic, operation for operation, as the box-by-box rule: the
    world bounds first, then the box's own frame, then the occupancy of the cell
    (a point within the margin outside the box falls in the nearest edge cell).
    """
    bd = bounds[i]
    ok = ((p[:, 0] >= bd[:, 0]) & (p[:, 0] <= bd[:, 3]) & (p[:, 1] >= bd[:, 1]) & (p[:, 1] <= bd[:, 4])
          & (p[:, 2] >= bd[:, 2]) & (p[:, 2] <= bd[:, 5]))
    sel = np.nonzero(ok)[0]
    p, i = p[sel], i[sel]
    c, s = cos[i], sin[i]
    d = p - boxes["center"][i]
    local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)
    size = np.maximum(boxes["size"][i], 1e-9)
    rel = local + size / 2
    inside = np.all((rel >= -margin) & (rel <= size + margin), axis=1)
    occ = boxes["occ"]
    k = occ.shape[1]
    cell = np.clip(np.floor(rel / size * k).astype(np.int64), 0, k - 1)
    ok[sel] = inside & occ.reshape(len(occ), -1)[i, (cell[:, 0] * k + cell[:, 1]) * k + cell[:, 2]]
    return ok


def label_arrays(xyz: np.ndarray, boxes: dict[str, np.ndarray], margin: float, *,
                 space: np.ndarray | None = None, cell: float = 0.25,
                 first: Sequence[int] = ()) -> tuple[np.ndarray, np.ndarray]:
    """Class (uint8) and element id (int32) per point of ``xyz`` (world) from detection boxes.

    A point takes the class and element id of the first box whose occupied
    sub-boxes (grown by ``margin``) hold it: the boxes of the classes ``first``
    (codes) before the others, each group by decreasing score; of boxes with
    equal scores, the first in ``boxes`` order; boxes scored NaN or -inf label
    nothing.

    The boxes are bucketed into a grid of ``cell`` metres (coarsened when the
    boxes are many and large) and each point is tested only against the boxes
    of its cell, best first, until one holds it; points go in batches: the work
    is linear in points plus boxes (times the boxes per cell), not their product.

    Parameters
    ----------
    xyz
        ``(n, 3)`` world coordinates.
    boxes
        The detections as :func:`_boxes` gives them.
    margin
        Metres by which each occupied sub-box is grown.
    space
        Optional ``(n,)`` space id per point: a box then labels only the points
        of its own space (``boxes["space"]``).  None: any point (the default rule).
    cell
        Side in metres of the bucket grid's cells (a speed setting; the labels do not depend on it).
    """
    n = len(xyz)
    cls = np.full(n, CLUTTER, dtype=np.uint8)
    eid = np.full(n, RESULT_NONE["element_id"], dtype=np.int32)
    score = np.asarray(boxes["score"], dtype=np.float64)
    if not len(score) or not n:
        return cls, eid
    ahead = np.isin(np.asarray(boxes["cls"]), np.asarray(list(first), dtype=np.int64))
    order = np.lexsort((-score, ~ahead))  # stable: equal keys keep the boxes' order
    order = order[score[order] > -np.inf]  # NaN and -inf never beat the initial -inf
    if not len(order):
        return cls, eid
    bx = {key: np.asarray(v)[order] for key, v in boxes.items()}  # rank order: lower index wins
    bounds = _world_bounds(bx, margin)
    cos, sin = np.cos(bx["yaw"]), np.sin(bx["yaw"])
    if space is not None:
        space = np.asarray(space)
        box_space = np.asarray(bx["space"])
    xyz = np.asarray(xyz, dtype=np.float64)
    lo, hi = column_bounds(xyz)
    cell, shape, e_cell, e_box = _bucket_grid(bx, bounds, cos, sin, margin, lo, hi, cell)
    n_cells = int(np.prod(shape))
    if n_cells <= DENSE_CELLS:
        start = np.zeros(n_cells + 1, dtype=np.int64)
        np.cumsum(np.bincount(e_cell, minlength=n_cells), out=start[1:])
    for s in range(0, n, POINT_BATCH):
        p_all = xyz[s:s + POINT_BATCH]
        g = np.clip(np.floor((p_all - lo) / cell).astype(np.int64), 0, shape - 1)
        flat = (g[:, 0] * shape[1] + g[:, 1]) * shape[2] + g[:, 2]
        if n_cells <= DENSE_CELLS:
            first = start[flat]
            count = start[flat + 1] - first
        else:
            first = np.searchsorted(e_cell, flat, side="left")
            count = np.searchsorted(e_cell, flat, side="right") - first
        # rounds: each point still unlabelled is tested against its next candidate (its cell's
        # boxes run best first), so that a point stops at its first hit, its best box
        active = np.nonzero(count > 0)[0]
        r = 0
        while len(active):
            bi = e_box[first[active] + r]
            hit = _contains(p_all[active], bi, bx, bounds, cos, sin, margin)
            if space is not None:
                hit &= space[s + active] == box_space[bi]
            done = active[hit]
            cls[s + done] = bx["cls"][bi[hit]]
            eid[s + done] = bx["eid"][bi[hit]]
            r += 1
            active = active[~hit & (count[active] > r)]
    return cls, eid


def _label_tile(job: tuple[str, dict[str, np.ndarray]], store: Any, margin: float, space_array: str | None,
                first: tuple[int, ...] = ()) -> int:
    tile, boxes = job
    origin = np.asarray(store.meta.origin, dtype=np.float64)
    xyz = store.xyz(tile) + origin
    space = store.read(tile, [space_array])[space_array] if space_array else None
    cls, eid = label_arrays(xyz, boxes, margin, space=space, first=first)
    store.write_array(tile, "classification", cls)
    store.write_array(tile, "element_id", eid)
    return int((cls != CLUTTER).sum())


def result_dimensions() -> list[Dimension]:
    """The two per-point arrays :func:`label_points` writes."""
    return [Dimension("classification", "uint8", "result", "element class code (0 ceiling ... 12 clutter)",
                      {"name": "classification"}),
            Dimension("element_id", "int32", "result", "detected element id (-1: none)",
                      {"name": "element_id", "type": "int32", "description": "detected element id"})]


def label_rule() -> dict[str, Any]:
    """The labelling settings (``buildingparser.detection.label-*``): ``margin``, ``occupied``, ``first`` (names)."""
    return {"margin": float(config.setting("detection.label-margin")),
            "occupied": bool(config.setting("detection.label-occupied")),
            "first": list(element_class_list(config.setting("detection.label-first"), "detection.label-first"))}


def label_points(store: Any, elements: Sequence[Proposal], *, client=None, margin: float | None = None,
                 own_space: str | None = None, occupied: bool | None = None,
                 first: Sequence[str] | None = None) -> int:
    """Write per-point ``classification`` and ``element_id`` in every tile from the detections.

    ``own_space`` names a per-point space array (``"space_id"``, whose ids the
    elements' ``space_id`` follow): a detection then labels only the points of its
    own space (the far face of a wall belongs to the room behind it).  None (the
    default): a detection labels every point its box holds.  ``margin``,
    ``occupied`` (only the occupied sub-boxes count) and ``first`` (the classes
    whose boxes come before the others) default to :func:`label_rule`'s.

    Returns the number of points labelled with an element class.
    """
    rule = label_rule()
    margin = float(rule["margin"] if margin is None else margin)
    occupied = rule["occupied"] if occupied is None else bool(occupied)
    codes = tuple(ELEMENT_CLASSES.index(c) for c in (rule["first"] if first is None else first))
    boxes = _boxes(list(elements), occupied)
    bounds = _world_bounds(boxes, margin)
    items, subsets = [], []
    for t in sorted(store.tiles, key=lambda t: -t.count):  # largest first: no long task left alone at the end
        tb = np.asarray(t.bounds)
        meet = np.all((bounds[:, :3] <= tb[3:]) & (bounds[:, 3:] >= tb[:3]), axis=1) if len(bounds) else np.zeros(0, bool)
        items.append(t.name)
        subsets.append({k: v[meet] for k, v in boxes.items()})
    counts = run_tasks(_label_tile, list(zip(items, subsets)),
                       client=client, label="label points", keys=items, extra_args=(store, margin, own_space, codes))
    store.add_dimensions(result_dimensions())
    return int(sum(counts))


def element_records(elements: Sequence[Proposal], with_voxels: bool = True) -> list[dict[str, Any]]:
    """The ``elements.json`` records (world coordinates), in element id order; an element that the space
    update's reconciliation made from several (:mod:`engine.outputs.reconcile`) also has ``reconciled``
    (``from``: the element ids joined, ``reason``)."""
    out = []
    for e in sorted(elements, key=lambda e: e.element_id):
        rec = e.element_record(with_voxels)
        if e.extra.get("reconciled"):
            rec["reconciled"] = e.extra["reconciled"]
        out.append(rec)
    return out


def write_elements_json(elements: Sequence[Proposal], path: str | os.PathLike, *, with_voxels: bool = True,
                        storage_options: dict[str, Any] | None = None) -> str:
    """Write ``elements.json``: a JSON list of :meth:`Proposal.element_record` dicts (local path or URL)."""
    path = paths.normalize(path)
    text = json.dumps(element_records(elements, with_voxels), indent=1)
    if paths.is_local(path):
        local = paths.local_path(path)
        d = os.path.dirname(local)
        if d:
            os.makedirs(d, exist_ok=True)
        with open(local, "w") as f:
            f.write(text + "\n")
    else:
        fs, p = paths.filesystem(path, storage_options)
        with fs.open(p, "w") as f:
            f.write(text + "\n")
    return path


def read_elements_json(path: str | os.PathLike) -> list[dict[str, Any]]:
    """The records of an ``elements.json``."""
    with open(paths.local_path(paths.normalize(path))) as f:
        return json.load(f)
