"""From detections to per-point labels and ``elements.json`` (paper section 5.3, "points" granularity).

A point takes the class and element id of the highest-scoring detection whose
*voxelised box* holds it: the box (world centre, size, yaw) cut into K x K x K
sub-boxes of which only the occupied ones (the proposal's pattern ``B``) count,
each grown by ``label-margin`` metres (scan noise).  Points in no detection are
clutter (12) with element id -1.  One task per tile writes ``classification``
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
from engine.proposals import Proposal
from tiles import paths
from tiles.classes import CLUTTER
from tiles.schema import RESULT_NONE, Dimension
from tiles.tasks import run_tasks


def _boxes(elements: Sequence[Proposal]) -> dict[str, np.ndarray]:
    n = len(elements)
    k = max((np.asarray(e.occupancy).shape[0] for e in elements), default=1)
    out = {"center": np.zeros((n, 3)), "size": np.zeros((n, 3)), "yaw": np.zeros(n), "score": np.zeros(n),
           "cls": np.zeros(n, np.uint8), "eid": np.zeros(n, np.int32), "occ": np.ones((n, k, k, k), bool)}
    for i, e in enumerate(elements):
        out["center"][i], out["size"][i], out["yaw"][i] = e.center, e.world_size, e.yaw
        out["score"][i], out["cls"][i], out["eid"][i] = e.score, e.class_code, e.element_id
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


def label_arrays(xyz: np.ndarray, boxes: dict[str, np.ndarray], margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Class (uint8) and element id (int32) per point of ``xyz`` (world) from detection boxes."""
    n = len(xyz)
    cls = np.full(n, CLUTTER, dtype=np.uint8)
    eid = np.full(n, RESULT_NONE["element_id"], dtype=np.int32)
    best = np.full(n, -np.inf)
    if not len(boxes["score"]) or not n:
        return cls, eid
    bounds = _world_bounds(boxes, margin)
    order = np.argsort(xyz[:, 0], kind="stable")
    xs = xyz[order, 0]
    k = boxes["occ"].shape[1]
    for i in np.argsort(-boxes["score"], kind="stable"):
        a = np.searchsorted(xs, bounds[i, 0], side="left")
        b = np.searchsorted(xs, bounds[i, 3], side="right")
        if b <= a:
            continue
        idx = order[a:b]
        p = xyz[idx]
        sel = (p[:, 1] >= bounds[i, 1]) & (p[:, 1] <= bounds[i, 4]) & (p[:, 2] >= bounds[i, 2]) & (p[:, 2] <= bounds[i, 5])
        idx, p = idx[sel], p[sel]
        if not len(idx):
            continue
        c, s = np.cos(boxes["yaw"][i]), np.sin(boxes["yaw"][i])
        d = p - boxes["center"][i]
        local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)
        size = np.maximum(boxes["size"][i], 1e-9)
        rel = local + size / 2  # [0, size] inside
        inside = np.all((rel >= -margin) & (rel <= size + margin), axis=1)
        cell = np.clip(np.floor(rel / size * k).astype(np.int64), 0, k - 1)
        occ = boxes["occ"][i][cell[:, 0], cell[:, 1], cell[:, 2]]
        # a point within the margin outside the box falls in the nearest (edge) cell
        take = inside & occ & (boxes["score"][i] > best[idx])
        idx = idx[take]
        best[idx] = boxes["score"][i]
        cls[idx] = boxes["cls"][i]
        eid[idx] = boxes["eid"][i]
    return cls, eid


def _label_tile(job: tuple[str, dict[str, np.ndarray]], store: Any, margin: float) -> int:
    tile, boxes = job
    origin = np.asarray(store.meta.origin, dtype=np.float64)
    xyz = store.xyz(tile) + origin
    cls, eid = label_arrays(xyz, boxes, margin)
    store.write_array(tile, "classification", cls)
    store.write_array(tile, "element_id", eid)
    return int((cls != CLUTTER).sum())


def result_dimensions() -> list[Dimension]:
    """The two per-point arrays :func:`label_points` writes."""
    return [Dimension("classification", "uint8", "result", "element class code (0 ceiling ... 12 clutter)",
                      {"name": "classification"}),
            Dimension("element_id", "int32", "result", "detected element id (-1: none)",
                      {"name": "element_id", "type": "int32", "description": "detected element id"})]


def label_points(store: Any, elements: Sequence[Proposal], *, client=None, margin: float | None = None) -> int:
    """Write per-point ``classification`` and ``element_id`` in every tile from the detections.

    Returns the number of points labelled with an element class.
    """
    margin = float(config.get("detection.label-margin", 0.02) if margin is None else margin)
    boxes = _boxes(list(elements))
    bounds = _world_bounds(boxes, margin)
    items, subsets = [], []
    for t in store.tiles:
        tb = np.asarray(t.bounds)
        meet = np.all((bounds[:, :3] <= tb[3:]) & (bounds[:, 3:] >= tb[:3]), axis=1) if len(bounds) else np.zeros(0, bool)
        items.append(t.name)
        subsets.append({k: v[meet] for k, v in boxes.items()})
    counts = run_tasks(_label_tile, list(zip(items, subsets)),
                       client=client, label="label points", keys=items, extra_args=(store, margin))
    store.add_dimensions(result_dimensions())
    return int(sum(counts))


def element_records(elements: Sequence[Proposal], with_voxels: bool = True) -> list[dict[str, Any]]:
    """The ``elements.json`` records (world coordinates), in element id order."""
    return [e.element_record(with_voxels) for e in sorted(elements, key=lambda e: e.element_id)]


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
