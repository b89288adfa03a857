"""Sliding windows over a space's unit cube (paper section 4, "Semantic Element Proposal Generation").

Every window of the dictionary is slid over the space's voxel grid from the ``0`` face to the ``1`` face
with a stride of ``stride`` times its size (at least one voxel, at most ``max-stride`` metres), always
including the position flush with the far face.  :func:`score_windows` computes the linear SVM score of
all positions of one window shape at once, from the distinct sub-boxes of all positions (their features
computed once, the same sums as :func:`engine.detection.features.window_features`), scattered into the
windows that hold them (:func:`_slot_sums`), plus the global and context blocks per position;
:func:`score_windows_many` does it for several linear models of one shape.  :func:`non_maximum_suppression`
keeps, per class, the best windows that overlap a better one by at most ``nms_iou``.
Design notes: ``docs/design/detection.md``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.detection import moments as mom
from engine.detection.context_block import context_features, context_margin, context_sums, slab_interval
from engine.detection.global_block import global_scores
from engine.detection.layout import FeatureLayout
from engine.detection.local_block import LOCAL_SIZE, local_features, sub_bounds
from engine.detection.volume import SpaceVolume

#: Sub-boxes whose moments are computed in one go (bounds the memory of a batch).
SUBBOX_BATCH = 250_000
#: Sub-box terms (an occupied sub-box in one slot of one window) added in one go.
TERM_BATCH = 1 << 18


def window_shape(metric_size: np.ndarray, grid: mom.VoxelGrid) -> np.ndarray:
    """Voxels ``(3,)`` of a window of ``metric_size`` metres in ``grid`` (at least 1, at most the grid)."""
    shape = np.asarray(grid.shape)
    return np.clip(np.round(np.asarray(metric_size) / grid.voxel), 1, shape).astype(np.int64)


def axis_positions(n: int, w: int, stride: float, max_step: int | None = None) -> np.ndarray:
    """Window starts along one axis of ``n`` voxels for a window of ``w`` voxels: both faces included.

    The step is ``stride`` times the window (at least one voxel, at most ``max_step`` voxels).
    """
    step = max(1, int(round(w * stride)))
    if max_step is not None:
        step = max(1, min(step, int(max_step)))
    last = max(n - w, 0)
    return np.unique(np.append(np.arange(0, last + 1, step), last)).astype(np.int64)


def window_positions(grid: mom.VoxelGrid, shape: np.ndarray, stride: float,
                     max_stride: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sliding starts along x, y, z of a window of ``shape`` voxels (``max_stride`` in metres caps the step)."""
    n = grid.shape
    cap = [None] * 3 if max_stride is None else [max(1, int(np.floor(max_stride / v + 1e-9))) for v in grid.voxel]
    return tuple(axis_positions(int(n[a]), int(shape[a]), stride, cap[a]) for a in range(3))


def _intervals(pos: np.ndarray, w: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Distinct sub-box intervals ``(u, 2)`` of all positions (sorted by start, then stop) and, per position and
    slot, their index.  An interval is one integer key ``start * span + stop`` (``np.unique`` of rows sorts
    them the same way, several times slower)."""
    b = sub_bounds(np.array(w), k)
    lo, hi = (pos[:, None] + b[None, :-1]).ravel(), (pos[:, None] + b[None, 1:]).ravel()
    span = int(hi.max()) + 1 if len(hi) else 1
    keys, inv = np.unique(lo * span + hi, return_inverse=True)
    return np.stack([keys // span, keys % span], axis=1), inv.reshape(len(pos), k)


def _exclusive_cumsum(c: np.ndarray) -> np.ndarray:
    """``[0, c0, c0 + c1, ...]``: the start of each run of lengths ``c``."""
    out = np.zeros_like(c)
    np.cumsum(c[:-1], out=out[1:])
    return out


def _slot_sums(nu: tuple[int, int, int], where: tuple[np.ndarray, np.ndarray, np.ndarray], values: np.ndarray,
               index: tuple[np.ndarray, np.ndarray, np.ndarray], w2: np.ndarray, k: int) -> np.ndarray:
    """``sum over slots (a, b, c) of feats[index_x[:, a], index_y[:, b], index_z[:, c]] @ w2[a, b, c]``.

    ``feats`` is the ``(ux, uy, uz, F)`` table (``nu = (ux, uy, uz)``) over distinct
    sub-box intervals, zero but at ``where`` (three index arrays) where it holds
    ``values`` ``(n, F)``; ``index[d]`` ``(n_d, k)`` is the interval of each position
    and slot along axis ``d``, ``w2`` ``(k, k, k, F, m)``.  Returns ``(m, n_x, n_y, n_z)``.

    Sparse: only the non-zero entries are visited.  Each is scattered to the
    windows that hold it: per axis, the (position, slot) pairs whose interval
    it is (usually one, up to ``k`` where a stride of a quarter window shares
    intervals between positions); every combination is one term
    ``values[i] @ w2[slot]`` added to its window (``np.bincount``).  The terms
    are ordered by slot (a counting sort of one byte) so that each slot's
    weights multiply its terms' feature rows in one matrix product.  In a room
    about one sub-box in ten holds points: this is about a tenth of the work
    of a pass over every window and slot.  Terms are taken in batches of
    :data:`TERM_BATCH`.
    """
    npos = tuple(len(i) for i in index)
    nf, m = values.shape[-1], w2.shape[-1]
    k3 = k ** 3
    nwin = int(np.prod(npos))
    out = np.zeros((m, nwin))
    # per axis, the (position, slot) pairs grouped by interval: pair e is position pos[e], slot slot[e];
    # the pairs of the entry's interval are first[i] ... first[i] + count[i] - 1
    first, count, pos, slot = [], [], [], []
    for d in range(3):
        flat = np.asarray(index[d], dtype=np.int64).ravel()
        order = np.argsort(flat, kind="stable")
        cnt = np.bincount(flat, minlength=nu[d])
        first.append(_exclusive_cumsum(cnt)[where[d]])
        count.append(cnt[where[d]])
        pos.append(order // k)
        slot.append(order % k)
    terms = count[0] * count[1] * count[2]
    live = np.nonzero(terms)[0]
    ends = np.cumsum(terms[live])
    wflat = w2.reshape(k3, nf, m)
    slot_type = np.uint8 if k3 <= 256 else np.int64
    s = 0
    while s < len(live):
        e = max(int(np.searchsorted(ends, (ends[s - 1] if s else 0) + TERM_BATCH, side="right")), s + 1)
        ent = live[s:e]
        # expand the entries axis by axis into their terms (an axis whose intervals all have one
        # pair costs one look-up)
        pair: list[np.ndarray] = []
        for d in range(3):
            c = count[d][ent]
            if len(c) and c.max() > 1:
                rep = np.repeat(np.arange(len(ent)), c)
                ent = ent[rep]
                pair = [p[rep] for p in pair]
                pair.append(first[d][ent] + (np.arange(len(rep)) - np.repeat(_exclusive_cumsum(c), c)))
            else:
                pair.append(first[d][ent])
        ex, ey, ez = pair
        win = (pos[0][ex] * npos[1] + pos[1][ey]) * npos[2] + pos[2][ez]
        sl = ((slot[0][ex] * k + slot[1][ey]) * k + slot[2][ez]).astype(slot_type)
        order = np.argsort(sl, kind="stable")
        bounds = np.searchsorted(sl[order], np.arange(k3 + 1))
        rows = values[ent[order]]
        val = np.empty((len(order), m))
        for q in np.nonzero(bounds[1:] > bounds[:-1])[0]:
            a, b = bounds[q], bounds[q + 1]
            np.matmul(rows[a:b], wflat[q], out=val[a:b])
        win = win[order]
        for o in range(m):
            out[o] += np.bincount(win, weights=val[:, o], minlength=nwin)
        s = e
    return out.reshape(m, *npos)


@dataclass
class WindowScores:
    """Scores of one window shape at all its positions (``scores[i, j, k]`` at ``(px[i], py[j], pz[k])``)."""

    shape: np.ndarray  # (3,) voxels
    px: np.ndarray
    py: np.ndarray
    pz: np.ndarray
    scores: np.ndarray  # (nx, ny, nz); -inf where the window holds too few points
    counts: np.ndarray  # (nx, ny, nz) points in the window

    def boxes(self, flat_index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Voxel boxes ``[lo, hi)`` of positions given as flat indices into ``scores``."""
        i, j, k = np.unravel_index(flat_index, self.scores.shape)
        lo = np.stack([self.px[i], self.py[j], self.pz[k]], axis=-1)
        return lo, lo + self.shape


def score_windows(vol: SpaceVolume, shape: np.ndarray, weights: np.ndarray, bias: float,
                  layout: FeatureLayout, stride: float, min_points: int = 10,
                  max_stride: float | None = None) -> WindowScores:
    """The linear score of a window of ``shape`` voxels at every sliding position of a space.

    Equal, to rounding, to ``window_features(...) @ weights + bias`` for each window
    (tested); ``weights`` are the full layout's (masked groups are ignored).
    """
    return score_windows_many(vol, shape, np.asarray(weights)[None], np.array([bias], dtype=np.float64), layout,
                              stride, min_points, max_stride)[0]


def score_windows_many(vol: SpaceVolume, shape: np.ndarray, weights: np.ndarray, bias: np.ndarray,
                       layout: FeatureLayout, stride: float, min_points: int = 10,
                       max_stride: float | None = None, floor: float | None = None) -> list[WindowScores]:
    """:func:`score_windows` of one window shape for several linear models ``(m, F)`` at once.

    The features of the windows (the box sums and local features of their
    sub-boxes, most of the cost) are computed once for all ``m`` weight vectors:
    for the atoms of a dictionary whose windows have the same voxel shape in a
    space (the same or different classes).  ``bias`` is ``(m,)``.

    ``floor``: only scores above it are wanted.  The context block is then computed only at
    the positions where some model's score without it, plus the most its context block can add
    in this space (:attr:`engine.detection.volume.SpaceVolume.context_range`), exceeds ``floor``;
    elsewhere the score is ``-inf`` (it could not exceed ``floor``).  Scores above ``floor`` are
    the same as without it.
    """
    k = layout.k
    k3 = k ** 3
    grid = vol.grid
    n = np.asarray(grid.shape)
    shape = np.minimum(np.asarray(shape, dtype=np.int64), n)
    w = np.where(layout.mask, np.asarray(weights, dtype=np.float64).reshape(-1, layout.size), 0.0)
    m = len(w)
    bias = np.asarray(bias, dtype=np.float64).reshape(m)
    wg = w[:, :layout.n_global]
    wl = w[:, layout.n_global:layout.local_end].reshape(m, k3, -1)  # (m, K^3, 9) per slot, x-major
    px, py, pz = window_positions(grid, shape, stride, max_stride)
    ux, ix = _intervals(px, int(shape[0]), k)
    uy, iy = _intervals(py, int(shape[1]), k)
    uz, iz = _intervals(pz, int(shape[2]), k)
    # window counts, and the global part where a window holds enough points (elsewhere -inf)
    win = lambda p, s: np.stack([p, p + s], axis=1)  # noqa: E731
    iv_n = vol.count_iv  # the counts alone: window counts, and which sub-boxes are occupied
    counts = mom.box_sums_grid(iv_n, win(px, shape[0]), win(py, shape[1]), win(pz, shape[2]))[..., 0]
    valid = counts >= min_points
    acc = np.zeros((2 * m,) + counts.shape)  # per model: the linear part, then the ratio's weighted raw counts
    # the global part, separable: a term per position along each axis and a constant per shape
    terms, const = global_scores((px, py, pz), shape, n, grid.voxel, wg, layout.boundary)
    for j in range(m):
        acc[j] = terms[0][j][:, None, None] + terms[1][j][None, :, None] + terms[2][j][None, None, :]
        acc[j] += const[j] + bias[j]
    # local part, in batches of x positions so that the sub-box count table stays bounded.  Only
    # the occupied sub-boxes get local features (they are all zero elsewhere; in a room most
    # sub-boxes are air), and only they are scattered to the windows and slots that hold them
    # (_slot_sums): a slot's term is linear in its sub-box's features.
    per_x = max(1, SUBBOX_BATCH // max(len(uy) * len(uz), 1))
    occupied = max(int(layout.min_points), 1)
    # weights (K, K, K, 9, 2m): each model's linear part (ratio excluded: it is divided by the
    # window's count at the end), then each model's weight of the raw count
    w2 = np.zeros((k, k, k, LOCAL_SIZE, 2 * m))
    for j in range(m):
        w2[..., j] = wl[j].reshape(k, k, k, -1)
        w2[..., 1, j] = 0.0
        w2[..., 1, m + j] = wl[j, :, 1].reshape(k, k, k)
    for s in range(0, len(px), per_x):
        sl = slice(s, s + per_x)
        need, sub_ix = np.unique(ix[sl], return_inverse=True)
        sub_ix = sub_ix.reshape(ix[sl].shape)
        xs = ux[need]
        occ = np.nonzero(mom.box_sums_grid(iv_n, xs, uy, uz)[..., 0] >= occupied)
        # all moments only there (in a room about one sub-box in ten holds points)
        lo = np.stack([xs[occ[0], 0], uy[occ[1], 0], uz[occ[2], 0]], axis=-1)
        hi = np.stack([xs[occ[0], 1], uy[occ[1], 1], uz[occ[2], 1]], axis=-1)
        sums = mom.box_sums(vol.iv, lo, hi)
        part = local_features(sums, np.ones(len(sums)), k, layout.min_points)
        part[:, 1] = sums[:, 0]  # raw count: ratio = count / window count
        acc[:, sl] += _slot_sums((len(xs), len(uy), len(uz)), occ, part, (sub_ix, iy, iz), w2, k)
    n_win = np.maximum(counts, 1.0)
    score = np.where(valid, acc[:m] + acc[m:] / n_win * k3, -np.inf)
    wc = w[:, layout.local_end:]
    if layout.context and np.any(wc):
        if floor is None:
            score += _context_scores(vol, (win(px, shape[0]), win(py, shape[1]), win(pz, shape[2])), wc)
        else:
            _add_context_above(score, vol, (px, py, pz), shape, wc, floor)
    return [WindowScores(shape, px, py, pz, score[j], counts) for j in range(m)]


def _add_context_above(score: np.ndarray, vol: SpaceVolume, starts: tuple[np.ndarray, np.ndarray, np.ndarray],
                       shape: np.ndarray, weights: np.ndarray, floor: float) -> None:
    """Add in place the context block's share to the scores ``(m, nx, ny, nz)`` of the positions where it may
    lift some model above ``floor``; set the others to ``-inf`` (see :func:`score_windows_many`)."""
    lo_f, hi_f = vol.context_range
    most = np.maximum(weights * lo_f, weights * hi_f).sum(axis=1)  # (m,)
    flat = score.reshape(len(weights), -1)
    may = (flat + most[:, None] > floor).any(axis=0)
    flat[:, ~may] = -np.inf
    need = np.flatnonzero(may)
    dims = score.shape[1:]
    for s in range(0, len(need), SUBBOX_BATCH):
        at = need[s:s + SUBBOX_BATCH]
        i, j, k = np.unravel_index(at, dims)
        lo = np.stack([starts[0][i], starts[1][j], starts[2][k]], axis=-1)
        feats = context_features(*context_sums(vol.context_iv, vol.grid, lo, lo + shape, channels=None))
        flat[:, at] += weights @ feats.T


def _context_scores(vol: SpaceVolume, wins: tuple[np.ndarray, np.ndarray, np.ndarray],
                    weights: np.ndarray) -> np.ndarray:
    """The context block's share ``(m, nx, ny, nz)`` of the scores of windows at ``wins`` (per-axis intervals).

    The window's and its six slabs' sums are separable box sums (:func:`engine.detection.moments.box_sums_grid`),
    taken in batches of x positions.
    """
    civ = vol.context_iv
    n = vol.grid.shape
    g = context_margin(vol.grid.voxel)
    slabs = [[slab_interval(wins[a], side, int(g[a]), int(n[a])) for side in (-1, 1)] for a in range(3)]
    per_x = max(1, SUBBOX_BATCH // max(len(wins[1]) * len(wins[2]), 1))
    out = np.empty((len(weights), len(wins[0]), len(wins[1]), len(wins[2])))
    for s in range(0, len(wins[0]), per_x):
        sl = slice(s, s + per_x)
        cut = (wins[0][sl], wins[1], wins[2])
        window = mom.box_sums_grid(civ, *cut)
        sides = []
        for a in range(3):
            for iv in slabs[a]:
                axes = list(cut)
                axes[a] = iv[sl] if a == 0 else iv
                sides.append(mom.box_sums_grid(civ, *axes))
        feats = context_features(window, np.stack(sides, axis=-2))
        out[:, sl] = np.einsum("xyzf,mf->mxyz", feats, weights)
    return out


def box_iou(lo_a: np.ndarray, hi_a: np.ndarray, lo_b: np.ndarray, hi_b: np.ndarray) -> np.ndarray:
    """IoU ``(n, m)`` of axis-aligned boxes ``[lo, hi)`` (any units)."""
    lo_a, hi_a = np.asarray(lo_a, float).reshape(-1, 3), np.asarray(hi_a, float).reshape(-1, 3)
    lo_b, hi_b = np.asarray(lo_b, float).reshape(-1, 3), np.asarray(hi_b, float).reshape(-1, 3)
    ov = np.clip(np.minimum(hi_a[:, None], hi_b[None]) - np.maximum(lo_a[:, None], lo_b[None]), 0, None)
    inter = ov.prod(axis=2)
    va, vb = (hi_a - lo_a).prod(axis=1), (hi_b - lo_b).prod(axis=1)
    union = va[:, None] + vb[None] - inter
    return np.divide(inter, union, out=np.zeros_like(inter), where=union > 0)


def grid_iou(shape: np.ndarray, px: np.ndarray, py: np.ndarray, pz: np.ndarray, lo: np.ndarray,
             hi: np.ndarray) -> np.ndarray:
    """IoU ``(nx, ny, nz)`` of a window of ``shape`` voxels at every position with one box ``[lo, hi)``.

    Voxel units (the box may have fractional corners); the intersection is separable per axis.
    """
    def overlap(p, w, a):
        return np.clip(np.minimum(p + w, hi[a]) - np.maximum(p, lo[a]), 0, None).astype(np.float64)

    ox, oy, oz = (overlap(p, shape[a], a) for a, p in enumerate((px, py, pz)))
    inter = ox[:, None, None] * oy[None, :, None] * oz[None, None, :]
    union = float(np.prod(shape)) + float(np.prod(np.asarray(hi) - np.asarray(lo))) - inter
    return inter / union


def non_maximum_suppression(lo: np.ndarray, hi: np.ndarray, scores: np.ndarray, iou: float,
                            max_keep: int) -> np.ndarray:
    """Indices of the kept boxes, best first: greedy NMS on 3D IoU."""
    order = np.lexsort((np.arange(len(scores)), -scores))
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    vol = (hi - lo).prod(axis=1)
    alive = np.ones(len(scores), dtype=bool)
    keep: list[int] = []
    for i in order:
        if not alive[i]:
            continue
        keep.append(int(i))
        if len(keep) >= max_keep:
            break
        ov = np.clip(np.minimum(hi, hi[i]) - np.maximum(lo, lo[i]), 0, None).prod(axis=1)
        alive &= ov / (vol + vol[i] - ov) <= iou
        alive[i] = False
    return np.asarray(keep, dtype=np.int64)
