"""The training vectors of the element detectors (paper section 4): positives and negatives of each class.

:func:`samples_task` is one pass over one ground-truth space.  Round 0: the ground-truth windows of
every element (positives of their class, negatives of the others), up to ``jitter-positives``
sliding windows per element that overlap it by ``pos-iou``, and ``random-negatives`` random sliding
windows of each class's shapes that overlap no element of the class by ``neg-iou``.  Later rounds:
the margin violators of the current detectors (hard negatives, :mod:`engine.training.mining`).
Everything random is seeded.  Design notes: ``docs/design/training.md``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from engine.detection import moments as mom
from engine.detection.canonical import CanonicalFrame
from engine.detection.features import window_features
from engine.detection.model import Model
from engine.detection.settings import DetectionSettings
from engine.detection.sliding import grid_iou, score_windows, window_positions, window_shape
from engine.detection.space import prepare_space
from engine.detection.volume import SpaceVolume
from engine.spaces.points import load_space
from engine.training.jobs import MIN_INSTANCE_POINTS, TrainJob, canonical_gt
from engine.training.settings import N_CLASSES, TrainSettings


@dataclass
class Samples:
    """Training vectors of one class: positives, negatives, the window (atom) of each, the mined windows' keys."""

    pos: list[np.ndarray] = field(default_factory=list)
    neg: list[np.ndarray] = field(default_factory=list)
    keys: set[tuple[int, int]] = field(default_factory=set)
    pos_atom: list[np.ndarray] = field(default_factory=list)
    neg_atom: list[np.ndarray] = field(default_factory=list)

    def n_neg(self) -> int:
        """How many negatives."""
        return int(sum(len(x) for x in self.neg))


def _rng(*key: int) -> np.random.Generator:
    return np.random.default_rng([int(k) & 0x7FFFFFFF for k in key])


def _window_key(atom: int, lo: np.ndarray) -> np.ndarray:
    lo = np.asarray(lo, dtype=np.int64).reshape(-1, 3)
    return (np.int64(atom) << 48) | (lo[:, 0] << 32) | (lo[:, 1] << 16) | lo[:, 2]


def samples_task(job: TrainJob, model: Model, settings: TrainSettings, round_: int,
                 det: DetectionSettings, active: tuple[int, ...]) -> dict[int, dict[str, np.ndarray]]:
    """Pass 2+: feature vectors of positives and negatives of every class in one space.

    Round 0: ground-truth windows, jittered positives, other classes' elements and
    random negatives.  Later rounds: margin violators of the current detectors.
    """
    pts = load_space(job.store, job.ref, "gt_space", truth=True)
    vol = prepare_space(pts, model, CanonicalFrame.from_json(job.frame) if job.frame else None)
    gt = canonical_gt(job, vol, pts.gt_instance)
    usable = gt["points"] >= MIN_INSTANCE_POINTS
    out: dict[int, dict[str, list]] = {c: {"pos": [], "neg": [], "keys": [], "pos_atom": [], "neg_atom": []}
                                       for c in range(N_CLASSES)}
    if round_ == 0 and usable.any():
        _ground_truth_windows(out, vol, gt, usable, model)
    for c in range(N_CLASSES):
        if c not in active:
            continue
        _class_windows(out[c], c, job, vol, gt, usable, model, settings, round_, det)
    d = model.layout.size
    return {c: {"pos": np.concatenate(v["pos"]) if v["pos"] else np.zeros((0, d), np.float32),
                "neg": np.concatenate(v["neg"]) if v["neg"] else np.zeros((0, d), np.float32),
                "keys": np.concatenate(v["keys"]) if v["keys"] else np.zeros(0, np.int64),
                "pos_atom": np.concatenate(v["pos_atom"]).astype(np.int64) if v["pos_atom"] else np.zeros(0, np.int64),
                "neg_atom": np.concatenate(v["neg_atom"]).astype(np.int64) if v["neg_atom"] else np.zeros(0, np.int64)}
            for c, v in out.items()}


def _ground_truth_windows(out: dict[int, dict[str, list]], vol: SpaceVolume, gt: dict[str, np.ndarray],
                          usable: np.ndarray, model: Model) -> None:
    """Round 0: every usable element's own window, a positive of its class and a negative of the others."""
    vox = vol.grid.voxel
    lo, hi = vol.voxel_box(gt["lo"][usable] / vol.frame.extent,
                           (gt["hi"][usable] - gt["lo"][usable]) / vol.frame.extent)
    feats = window_features(vol.iv, vol.grid, lo, hi, model.layout).astype(np.float32)
    cls = gt["cls"][usable]
    for c in range(N_CLASSES):
        near = _nearest_atoms((hi - lo) * vox, model, c, vol)
        out[c]["pos"].append(feats[cls == c]), out[c]["pos_atom"].append(near[cls == c])
        out[c]["neg"].append(feats[cls != c]), out[c]["neg_atom"].append(near[cls != c])


def _class_windows(out: dict[str, list], c: int, job: TrainJob, vol: SpaceVolume, gt: dict[str, np.ndarray],
                   usable: np.ndarray, model: Model, settings: TrainSettings, round_: int,
                   det: DetectionSettings) -> None:
    """The sliding-window samples of class ``c`` in one space, appended to ``out``: jittered positives
    (round 0) and negatives (random in round 0, the detectors' margin violators later)."""
    vox = vol.grid.voxel
    gt_lo_v, gt_hi_v = gt["lo"] / vox, gt["hi"] / vox
    mine = gt["cls"] == c
    rng = _rng(settings.seed, round_, job.key, c)
    cand_lo, cand_hi, cand_keys, cand_scores, pos_lo, pos_hi, pos_at = [], [], [], [], [], [], []
    for ai, atom in enumerate(model.dictionary.atoms_):
        if atom.class_code != c:
            continue
        shape, px, py, pz, valid, scores = _scan(ai, atom, vol, model, round_, det)
        best = np.zeros(valid.shape)
        for g in np.nonzero(mine)[0]:
            iou = grid_iou(shape, px, py, pz, gt_lo_v[g], gt_hi_v[g])
            best = np.maximum(best, iou)
            if round_ == 0 and usable[g] and settings.jitter_positives:
                good = np.nonzero((iou >= settings.pos_iou).ravel() & valid.ravel())[0]
                if len(good):
                    pick = rng.choice(good, min(len(good), settings.jitter_positives), replace=False)
                    i, j, k = np.unravel_index(pick, valid.shape)
                    l = np.stack([px[i], py[j], pz[k]], axis=1)
                    pos_lo.append(l), pos_hi.append(l + shape), pos_at.append(np.full(len(l), ai))
        neg = np.nonzero((valid & (best < settings.neg_iou)).ravel())[0]
        if len(neg):
            i, j, k = np.unravel_index(neg, valid.shape)
            l = np.stack([px[i], py[j], pz[k]], axis=1)
            cand_lo.append(l), cand_hi.append(l + shape), cand_keys.append(_window_key(ai, l))
            cand_scores.append(scores[i, j, k])
    if cand_lo and round_ > 0 and settings.mining == "hardest" and job.mined and len(job.mined.get(c, ())):
        # a violator mined in an earlier round is in the training set already: the next ones down
        fresh = [~np.isin(kk, job.mined[c]) for kk in cand_keys]
        cand_lo = [x[f] for x, f in zip(cand_lo, fresh)]
        cand_hi = [x[f] for x, f in zip(cand_hi, fresh)]
        cand_keys = [x[f] for x, f in zip(cand_keys, fresh)]
        cand_scores = [x[f] for x, f in zip(cand_scores, fresh)]
    if pos_lo:
        lo, hi = np.concatenate(pos_lo), np.concatenate(pos_hi)
        out["pos"].append(window_features(vol.iv, vol.grid, lo, hi, model.layout).astype(np.float32))
        out["pos_atom"].append(np.concatenate(pos_at))
    if cand_lo:
        _pick_negatives(out, vol, model, settings, round_, rng, cand_lo, cand_hi, cand_keys, cand_scores)


def _scan(ai: int, atom, vol: SpaceVolume, model: Model, round_: int,
          det: DetectionSettings) -> tuple[np.ndarray, ...]:
    """The sliding positions of window ``ai`` in the space: ``shape``, ``px``, ``py``, ``pz``, which are
    candidates (round 0: enough points; later: margin violators, score > -1) and their scores."""
    shape = window_shape(atom.size_in(vol.grid.extent), vol.grid)
    if round_ == 0:
        px, py, pz = window_positions(vol.grid, shape, det.stride, det.max_stride)
        counts = mom.box_sums_grid(vol.iv[..., :1], np.stack([px, px + shape[0]], 1),
                                   np.stack([py, py + shape[1]], 1), np.stack([pz, pz + shape[2]], 1))[..., 0]
        valid = counts >= det.min_window_points
        scores = np.zeros(valid.shape)
    else:
        w, b = model.window_weights([ai])
        ws = score_windows(vol, shape, w[0], float(b[0]), model.layout, det.stride, det.min_window_points,
                           det.max_stride)
        px, py, pz = ws.px, ws.py, ws.pz
        valid = ws.scores > -1.0
        scores = ws.scores
    return shape, px, py, pz, valid, scores


def _pick_negatives(out: dict[str, list], vol: SpaceVolume, model: Model, settings: TrainSettings, round_: int,
                    rng: np.random.Generator, cand_lo: list, cand_hi: list, cand_keys: list,
                    cand_scores: list) -> None:
    """At most ``random-negatives`` (round 0) or ``hard-negatives`` of the candidate windows, appended to
    ``out``: the highest-scoring (``mining: hardest``, after round 0) or a seeded random subset."""
    lo, hi, keys = np.concatenate(cand_lo), np.concatenate(cand_hi), np.concatenate(cand_keys)
    n = settings.random_negatives if round_ == 0 else settings.hard_negatives
    if len(lo) > n:
        if round_ > 0 and settings.mining == "hardest":  # the n highest-scoring margin violators
            pick = np.sort(np.argsort(-np.concatenate(cand_scores), kind="stable")[:n])
        else:
            pick = np.sort(rng.choice(len(lo), n, replace=False))
        lo, hi, keys = lo[pick], hi[pick], keys[pick]
    if len(lo):
        out["neg"].append(window_features(vol.iv, vol.grid, lo, hi, model.layout).astype(np.float32))
        out["keys"].append(keys)
        out["neg_atom"].append(keys >> 48)


def _nearest_atoms(sizes: np.ndarray, model: Model, c: int, vol: SpaceVolume) -> np.ndarray:
    """Per box size (metres), the window of class ``c`` in this space whose size overlaps it most (-1: none).

    Centred boxes' IoU: a ground-truth window is a sample of the atom it most resembles.
    """
    atoms = [ai for ai, a in enumerate(model.dictionary.atoms_) if a.class_code == c]
    if not atoms or not len(sizes):
        return np.full(len(sizes), -1, dtype=np.int64)
    win = np.array([window_shape(model.dictionary.atoms_[ai].size_in(vol.grid.extent), vol.grid) * vol.grid.voxel
                    for ai in atoms])
    inter = np.prod(np.minimum(sizes[:, None, :], win[None]), axis=2)
    iou = inter / (np.prod(sizes, axis=1)[:, None] + np.prod(win, axis=1)[None] - inter)
    return np.asarray(atoms, dtype=np.int64)[np.argmax(iou, axis=1)]
