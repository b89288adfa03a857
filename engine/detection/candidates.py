"""The windows of a space that become its detections, class by class.

Every window of the dictionary is scored over the space (:func:`window_candidates`; the atoms of one voxel
shape together), those above ``score-threshold`` are kept, at most ``pre-nms`` per window shape
(:func:`top_windows`); per class (:func:`class_windows`), non-maximum suppression of the boxes grown to
``nms-min-size``, a half-step local search (:func:`local_search`), NMS again, at most ``max-per-class``, and
the one ceiling and floor of ``one-per-space`` (every space gets both: ``one-per-space-always``), and a wall on
every side of the space that holds one (``side-classes``, :mod:`engine.detection.sides`).  Design notes:
``docs/design/detection.md``.
"""
from __future__ import annotations

import numpy as np

from engine.detection.features import window_features
from engine.detection.model import Model
from engine.detection.settings import DetectionSettings
from engine.detection.sides import best_at_sides, side_windows
from engine.detection.sliding import WindowScores, non_maximum_suppression, score_windows_many, window_shape
from engine.detection.surfaces import surface_order
from engine.detection.volume import SpaceVolume
from tiles.classes import ELEMENT_CLASSES


def window_candidates(vol: SpaceVolume, model: Model, settings: DetectionSettings,
                      classes: list[int] | None = None) -> dict[int, tuple[np.ndarray, ...]]:
    """Per dictionary atom, its windows above ``score-threshold`` (at most ``pre-nms``, best first).

    Returns ``{atom index: (lo, hi, score, atom index per window, side)}`` for the atoms of the
    trained (and requested) classes that have any; ``side`` marks the best window at each side of the space of a
    ``side-classes`` atom (:func:`engine.detection.sides.side_windows`, above ``side-floor``).  Atoms whose windows have the same
    voxel shape in this space are scored together (:func:`engine.detection.sliding.score_windows_many`
    computes their features once): the scores are those of one :func:`engine.detection.sliding.score_windows` call each.
    """
    grid = vol.grid
    wanted = set(range(len(ELEMENT_CLASSES)) if classes is None else classes)
    groups: dict[tuple[int, ...], list[int]] = {}
    for ai, atom in enumerate(model.dictionary.atoms_):
        c = atom.class_code
        if c in wanted and model.trained[c]:
            shape = window_shape(atom.size_in(grid.extent), grid)
            groups.setdefault(tuple(int(v) for v in shape), []).append(ai)
    always = {ELEMENT_CLASSES.index(c) for c in settings.one_per_space} if settings.one_per_space_always else set()
    sided = {ELEMENT_CLASSES.index(c) for c in settings.side_classes}
    thin, reach = settings.thin_voxels, side_reach(settings, grid.voxel)
    out: dict[int, tuple[np.ndarray, ...]] = {}
    for shape, members in groups.items():
        w, b = model.window_weights(members)
        # a class every space gets one of is scored everywhere: its best window may lie below the threshold
        codes = {model.dictionary.atoms_[ai].class_code for ai in members}
        floor = settings.score_threshold if not codes & sided else min(settings.score_threshold, settings.side_floor)
        scored = score_windows_many(vol, np.array(shape), w, b, model.layout, settings.stride,
                                    settings.min_window_points, settings.max_stride,
                                    floor=None if codes & always else floor)
        for ai, ws in zip(members, scored):
            c = model.dictionary.atoms_[ai].class_code
            parts = [top_windows(ws, ai, settings, -np.inf if c in always else None)]
            if c in sided:
                parts.append(side_windows(ws, ai, grid.shape, thin, reach, settings.side_floor))
            found = [(*p, np.full(len(p[0]), i == 1)) for i, p in enumerate(parts) if p is not None]
            if found:
                out[ai] = tuple(np.concatenate(a) for a in zip(*found))
    return out


def side_reach(settings: DetectionSettings, voxel: np.ndarray) -> np.ndarray:
    """``side-reach`` in whole voxels along each axis (at least one)."""
    return np.maximum(1, np.round(settings.side_reach / np.asarray(voxel, dtype=float))).astype(np.int64)


def top_windows(ws: WindowScores, atom: int, settings: DetectionSettings,
                threshold: float | None = None) -> tuple[np.ndarray, ...] | None:
    """One window shape's scored positions above ``threshold`` (None: ``score-threshold``), at most ``pre-nms``
    of the best; positions without a score (too few points) never pass.

    Returns ``(lo, hi, score, atom index per window)``, or None when no window passes.
    """
    flat = ws.scores.ravel()
    ok = np.nonzero((flat > (settings.score_threshold if threshold is None else threshold)) & np.isfinite(flat))[0]
    if len(ok) > settings.pre_nms:
        ok = ok[np.argpartition(-flat[ok], settings.pre_nms - 1)[:settings.pre_nms]]
    if not len(ok):
        return None
    lo, hi = ws.boxes(ok)
    return lo, hi, flat[ok], np.full(len(ok), atom)



def local_search(vol: SpaceVolume, lo: np.ndarray, hi: np.ndarray, scores: np.ndarray, weights: np.ndarray,
                 bias: np.ndarray | float, layout, stride: float, max_stride: float | None) -> tuple[np.ndarray,
                                                                                                  np.ndarray,
                                                                                                  np.ndarray]:
    """Move each detection by half a sliding step along each axis (27 candidates) to its best score.

    ``weights`` is ``(D,)`` for all detections or ``(n, D)`` one row per detection (its window's,
    :meth:`engine.detection.model.Model.window_weights`), ``bias`` a scalar or ``(n,)``.

    The coarse grid places a window up to half a step off; its score is highest
    where it fits, so the best of the half-step neighbours is kept (the window's
    size is unchanged).  Cheap: only the few windows that survived NMS are moved.
    """
    if not len(lo):
        return lo, hi, scores
    n = np.asarray(vol.grid.shape)
    w = hi - lo
    step = np.maximum(1, np.round(w * stride)).astype(np.int64)
    if max_stride is not None:
        step = np.minimum(step, np.maximum(1, np.floor(max_stride / vol.grid.voxel + 1e-9)).astype(np.int64))
    half = np.where(w < n, np.maximum(step // 2, 1), 0)  # spanning axes do not move
    offs = np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1], indexing="ij"), axis=-1).reshape(-1, 3)
    cand_lo = lo[:, None, :] + offs[None] * half[:, None, :]
    cand_lo = np.clip(cand_lo, 0, n - w[:, None, :])
    cand_hi = cand_lo + w[:, None, :]
    flat_lo, flat_hi = cand_lo.reshape(-1, 3), cand_hi.reshape(-1, 3)
    feats = window_features(vol.iv, vol.grid, flat_lo, flat_hi, layout)
    w_rows = np.broadcast_to(np.where(layout.mask, weights, 0.0), (len(lo), layout.size))
    b_rows = np.broadcast_to(np.asarray(bias, dtype=np.float64), (len(lo),))
    cand = np.einsum("ncd,nd->nc", feats.reshape(len(lo), len(offs), -1), w_rows) + b_rows[:, None]
    best = np.argmax(cand, axis=1)
    idx = np.arange(len(lo))
    better = cand[idx, best] > scores
    new_lo = np.where(better[:, None], cand_lo[idx, best], lo)
    return new_lo, new_lo + w, np.where(better, cand[idx, best], scores)


def class_windows(c: int, candidates: dict[int, tuple[np.ndarray, ...]], vol: SpaceVolume, model: Model,
                  settings: DetectionSettings) -> tuple[np.ndarray, ...] | None:
    """The detections of class ``c`` in a space from its atoms' ``candidates`` (:func:`window_candidates`'s).

    NMS, local search and NMS again (``local-search``), then the one window of a ``one-per-space`` class
    (with ``one-per-space-always``, the best of its windows below ``score-threshold`` when none is above it).
    Then, for a ``side-classes`` class, the best side window (:func:`window_candidates`'s ``side``) at each side
    of the space (:func:`engine.detection.sides.best_at_sides`), as a candidate that
    :func:`engine.detection.sides.settle_sides` keeps or drops once the final scores are known.
    Returns ``(lo, hi, score, class code, atom index, candidate)`` of the kept windows, or None without
    candidates.
    """
    grid = vol.grid
    atoms = model.dictionary.atoms_
    found = [_with_side(candidates[ai]) for ai in sorted(candidates) if atoms[ai].class_code == c]
    if not found:
        return None
    lo, hi, sc, at, side = (np.concatenate(parts) for parts in zip(*found))
    pool = (lo[side], hi[side], sc[side], at[side])
    normal = ~side | (sc > settings.score_threshold)
    lo, hi, sc, at = lo[normal], hi[normal], sc[normal], at[normal]
    if ELEMENT_CLASSES[c] in settings.one_per_space:  # windows below the threshold only when none is above it
        above = sc > settings.score_threshold
        if above.any() and not above.all():
            lo, hi, sc, at = lo[above], hi[above], sc[above], at[above]
    # NMS on boxes grown to nms-min-size: parallel slivers of one surface suppress each other
    pad = np.clip(np.ceil(settings.nms_min_size / grid.voxel) - (hi - lo), 0, None) / 2.0
    keep = non_maximum_suppression(lo - pad, hi + pad, sc, settings.nms_iou, settings.max_per_class)
    if settings.local_search:
        lo, hi, sc = lo[keep], hi[keep], sc[keep]
        at = at[keep]
        w, b = model.window_weights(at)
        lo, hi, sc = local_search(vol, lo, hi, sc, w, b, model.layout, settings.stride, settings.max_stride)
        pad = np.clip(np.ceil(settings.nms_min_size / grid.voxel) - (hi - lo), 0, None) / 2.0
        keep = non_maximum_suppression(lo - pad, hi + pad, sc, settings.nms_iou, settings.max_per_class)
    if ELEMENT_CLASSES[c] in settings.one_per_space:
        if ELEMENT_CLASSES[c] in ("ceiling", "floor"):
            keep = surface_order(keep, lo, hi, grid.shape[2], ELEMENT_CLASSES[c] == "ceiling",
                                 settings.surface_choice)
        keep = keep[:1]  # a space has one floor and one ceiling: the first window of the class
    lo, hi, sc, at = lo[keep], hi[keep], sc[keep], at[keep]
    candidate = np.zeros(len(keep), dtype=bool)
    if len(pool[0]):  # the best side window at each side, settled once the final scores are known
        add = best_at_sides(pool[0], pool[1], pool[2], grid.shape, settings.thin_voxels,
                            side_reach(settings, grid.voxel))
        lo, hi, sc, at = (np.concatenate([a, p[add]]) for a, p in zip((lo, hi, sc, at), pool))
        candidate = np.concatenate([candidate, np.ones(len(add), dtype=bool)])
    return lo, hi, sc, np.full(len(lo), c), at, candidate


def _with_side(found: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
    """A candidates entry with its ``side`` marks (none where the entry has none: candidates made without sides)."""
    return found if len(found) > 4 else (*found, np.zeros(len(found[0]), dtype=bool))
