"""Adjusted Rand Index of a space parsing as a distributed reduction (paper Table 2).

Each tile yields the sparse contingency table of (ground-truth label,
predicted label): its distinct pairs and their counts.  The tables are summed
on the driver and the ARI comes from the sum, exactly as
``sklearn.metrics.adjusted_rand_score`` computes it (pair confusion matrix in
exact integers, 1.0 for empty data or full agreement).

Points with label -1:

* ground truth -1 (no ground-truth space: outside the annotated spaces) are
  left out: there is nothing to compare them with;
* prediction -1 (left out of every predicted space) are kept, and all of them
  form one more predicted cluster, "unassigned": leaving points out is scored
  as lumping them together, never as free.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp

from tiles.store import TileStore
from tiles.tasks import run_tasks

if TYPE_CHECKING:
    from distributed import Client


def contingency_pairs(truth: np.ndarray, pred: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct ``(truth, pred)`` pairs (``(k, 2)`` int64) and their counts, points with truth -1 left out."""
    t = np.asarray(truth, dtype=np.int64).ravel()
    p = np.asarray(pred, dtype=np.int64).ravel()
    if t.shape != p.shape:
        raise ValueError(f"truth and prediction differ in length: {t.shape} vs {p.shape}")
    keep = t >= 0
    t, p = t[keep], p[keep]
    if len(t) == 0:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64)
    # one integer key per pair: a bincount when the key range is small, else a sort
    t0, p0 = int(t.min()), int(p.min())
    width = int(p.max()) - p0 + 1
    key = (t - t0) * width + (p - p0)
    span = int(key.max()) + 1
    if span <= 4 * len(key) + 1024:
        counts = np.bincount(key, minlength=span)
        uniq = np.flatnonzero(counts)
        counts = counts[uniq]
    else:
        uniq, counts = np.unique(key, return_counts=True)
    pairs = np.stack([uniq // width + t0, uniq % width + p0], axis=1)
    return pairs.astype(np.int64), counts.astype(np.int64)


def sum_pairs(parts: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Sum sparse contingency tables given as (pairs, counts)."""
    parts = [p for p in parts if len(p[1])]
    if not parts:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64)
    pairs = np.concatenate([p[0] for p in parts])
    counts = np.concatenate([p[1] for p in parts])
    uniq, inv = np.unique(pairs, axis=0, return_inverse=True)
    return uniq, np.bincount(inv.ravel(), weights=counts, minlength=len(uniq)).astype(np.int64)


def contingency_table(pairs: np.ndarray, counts: np.ndarray) -> sp.coo_array:
    """The (truth x prediction) contingency table of summed pairs, rows and columns renumbered densely."""
    if len(counts) == 0:
        return sp.coo_array((np.zeros(0, dtype=np.int64), (np.zeros(0, int), np.zeros(0, int))), shape=(0, 0))
    _, rows = np.unique(pairs[:, 0], return_inverse=True)
    _, cols = np.unique(pairs[:, 1], return_inverse=True)
    return sp.coo_array((counts, (rows.ravel(), cols.ravel())), shape=(rows.max() + 1, cols.max() + 1))


def ari_from_contingency(table: Any) -> float:
    """ARI of a contingency table (rows: ground truth, columns: prediction; dense or scipy.sparse).

    The same arithmetic as ``sklearn.metrics.adjusted_rand_score`` (pair
    confusion matrix in exact Python integers), so the two agree exactly.
    """
    if sp.issparse(table):
        coo = sp.coo_array(table)
        coo.sum_duplicates()
        data = coo.data
        rows = np.asarray(coo.sum(axis=1)).ravel()
        cols = np.asarray(coo.sum(axis=0)).ravel()
    else:
        dense = np.asarray(table)
        data = dense[dense != 0].ravel() if dense.size else np.zeros(0)
        rows = dense.sum(axis=1).ravel() if dense.size else np.zeros(0)
        cols = dense.sum(axis=0).ravel() if dense.size else np.zeros(0)
    if np.any(data < 0):
        raise ValueError("a contingency table holds counts, not negative numbers")

    def sq(a: np.ndarray) -> int:
        return sum(int(v) * int(v) for v in np.asarray(a).ravel() if v)

    n = int(sum(int(v) for v in data))
    sum_sq = sq(data)
    tp = sum_sq - n
    fp = sq(cols) - sum_sq
    fn = sq(rows) - sum_sq
    tn = n * n - fp - fn - sum_sq
    if fn == 0 and fp == 0:
        return 1.0
    return 2.0 * (tp * tn - fn * fp) / ((tp + fn) * (fn + tn) + (tp + fp) * (fp + tn))


def ari(truth: np.ndarray, pred: np.ndarray) -> float:
    """ARI of two in-memory labelings with this module's rules for -1 (see the module docstring)."""
    return ari_from_contingency(contingency_table(*contingency_pairs(truth, pred)))


def _tile_pairs(tile: str, store, truth: str, pred: str) -> tuple[np.ndarray, np.ndarray]:
    cols = store.read(tile, [truth, pred])
    return contingency_pairs(cols[truth], cols[pred])


def distributed_contingency(store: TileStore, truth: str = "gt_space", pred: str = "space_id",
                            client: Client | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The summed sparse contingency table of two per-point arrays of a tile store, as (pairs, counts)."""
    names = store.meta.names()
    for name in (truth, pred):
        if name not in names:
            from tiles.errors import UserError

            raise UserError(store.url, f"no per-point array {name!r} in this tile store")
    tiles = [t.name for t in store.tiles]
    parts = run_tasks(_tile_pairs, tiles, client=client, label=f"ARI {pred}", keys=tiles,
                      extra_args=(store, truth, pred))
    return sum_pairs(parts)


def distributed_ari(store: TileStore, truth: str = "gt_space", pred: str = "space_id",
                    client: Client | None = None) -> float:
    """ARI of ``pred`` against ``truth`` over all points of a tile store, one contingency table per tile."""
    return ari_from_contingency(contingency_table(*distributed_contingency(store, truth, pred, client)))
