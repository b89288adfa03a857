"""Training the element detectors (paper section 4, "Learning to Detect Elements").

Training runs over any number of tile stores with ground truth, one dask task
per ground-truth space in every pass (a space's points gathered from the tiles
it touches), and only small arrays come back to the driver:

1. **Instances** (one pass): each space's canonical frame (the same function as
   at run time), the canonical box of each of its ground-truth elements (the
   ``meta/ground_truth`` box, bounded in the frame) and its occupancy pattern
   (K^3 sub-boxes holding points of the instance).
2. **Dictionary**: Affinity Propagation per class (:mod:`engine.detection.dictionary`).
3. **First samples** (one pass): positives are the ground-truth windows of the
   class and up to ``jitter-positives`` sliding windows per element overlapping it
   by ``pos-iou`` or more; negatives are the ground-truth windows of the other
   classes and ``random-negatives`` random sliding windows of the class's
   shapes overlapping no element of the class by ``neg-iou`` or more.
4. **Linear SVMs**: one ``LinearSVC`` (liblinear) per class on the layout's columns.
5. **Hard negatives** (bounded rounds): every space is scanned with the current
   detectors; windows overlapping no element of the class by ``neg-iou`` and
   scoring above -1 (margin violators) that are not yet negatives are kept, at
   most ``hard-negatives`` per class and space: the highest-scoring ones
   (``mining: hardest``; a random subset left the worst false positives out of
   training, see ``engine/detection/detection.yaml``) or a seeded random subset
   (``mining: random``, the older models), and the classes that got new ones
   are retrained, until no class gets any or ``rounds`` is reached.
6. **Box regression** (``box-fit`` classes, one pass): the trained detectors run over
   the training spaces; their detections near an element of their class teach the
   per-class regression of the element's faces on the points around the box
   (:mod:`engine.detection.boxfit`), kept per axis role only where leave-one-building-out
   validation says it helps.

Folds are buildings: :func:`cross_validate` trains on all buildings but one and
evaluates on that one, for each, so no building is both trained and tested on.
Everything random is seeded (``seed``): a run is reproducible.
"""
from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.svm import LinearSVC

from engine import config
from engine.detection import moments as mom
from engine.detection.boxfit import box_features, face_targets, fit_boxfit
from engine.detection.canonical import CanonicalFrame
from engine.detection.detect import DetectionSettings, detect_in_volume, prepare_indexed, prepare_space, space_frame
from engine.detection.dictionary import WindowDictionary
from engine.detection.features import ABLATIONS, FeatureLayout, SpaceVolume, window_features
from engine.detection.model import Model
from engine.detection.rescore import fit_rescorer, rescore_features
from engine.detection.sliding import box_iou, grid_iou, score_windows, window_positions, window_shape
from engine.spaces.points import SpaceRef, index_spaces, load_space
from tiles.classes import ELEMENT_CLASSES, element_class_list
from tiles.errors import UserError
from tiles.groundtruth import DOC as GT_DOC
from tiles.tasks import run_tasks

N_CLASSES = len(ELEMENT_CLASSES)
#: A training detection teaches the box regression when it overlaps an element of its class this much.
BOXFIT_MIN_IOU = 0.2
#: ... among the detections of a non-maximum suppression at this IoU (looser than the run's).
BOXFIT_NMS_IOU = 0.6
#: Elements with fewer points than this in their space are not used for training.
MIN_INSTANCE_POINTS = 10


@dataclass
class TrainSettings:
    """Training settings (``buildingparser.detection.train.*`` and the model's grid settings)."""

    k: int = 4
    voxel: float = 0.1
    max_cells: int = 2_000_000
    c: float = 0.05
    rounds: int = 3
    pos_iou: float = 0.6
    neg_iou: float = 0.4
    jitter_positives: int = 4
    random_negatives: int = 40
    hard_negatives: int = 150
    max_negatives: int = 30000
    seed: int = 0
    preference_quantile: float = 0.5
    max_atoms: int = 10
    max_instances: int = 400
    iou_weight: float = 0.5
    relative_ratio: float | None = None
    mining: str = "random"
    atom_weights: bool = False
    atom_scale: float = 1.0
    disabled: tuple[str, ...] = ()
    classes: tuple[int, ...] = tuple(range(N_CLASSES))
    max_stride: float = 0.5
    box_fit: str = ""
    select_groups: str = ""
    group_classes: str = ""
    context: bool = True
    rescore: bool = False

    def __post_init__(self) -> None:
        if self.k < 1 or self.voxel <= 0 or self.max_cells < 1:
            raise ValueError("k, voxel and max-cells must be positive")
        if self.c <= 0:
            raise ValueError("the SVM's C must be positive")
        if not 0 < self.neg_iou <= self.pos_iou <= 1:
            raise ValueError("need 0 < neg-iou <= pos-iou <= 1")
        if self.rounds < 0 or min(self.jitter_positives, self.random_negatives, self.hard_negatives) < 0:
            raise ValueError("rounds and sample counts must be >= 0")
        self.disabled = tuple(self.disabled)
        self.classes = tuple(int(c) for c in self.classes)
        if not self.classes or not all(0 <= c < N_CLASSES for c in self.classes):
            raise ValueError(f"classes must be element class codes 0..{N_CLASSES - 1}")
        if self.mining not in ("random", "hardest"):
            raise ValueError("mining must be 'random' or 'hardest'")
        if self.atom_scale <= 0:
            raise ValueError("atom-scale must be positive")
        self.box_fit = ",".join(element_class_list(self.box_fit, "box-fit"))
        self.group_classes = ",".join(element_class_list(self.group_classes, "group-classes"))
        if isinstance(self.select_groups, (list, tuple)):
            self.select_groups = ",".join(self.select_groups)
        bad = [g for g in self.select_groups.split(",") if g.strip() and g.strip() not in ABLATIONS or g.strip() == "full"]
        if bad:
            raise ValueError(f"select-groups: unknown ablation {bad[0]!r} (known: no_local, no_global, no_color)")
        self.select_groups = ",".join(g.strip() for g in self.select_groups.split(",") if g.strip())

    @property
    def box_fit_codes(self) -> list[int]:
        """Class codes that get a learned box regression (``box-fit``)."""
        return [ELEMENT_CLASSES.index(c) for c in self.box_fit.split(",") if c]

    @classmethod
    def from_config(cls, **overrides: Any) -> "TrainSettings":
        kw: dict[str, Any] = {}
        for f in fields(cls):
            if f.name in ("disabled", "classes"):
                continue
            key = f.name.replace("_", "-")
            v = config.get(f"detection.{key}") if f.name in ("k", "voxel", "max_cells") else \
                config.get(f"detection.train.{key}")
            if v is not None:
                kw[f.name] = float(v) if f.name == "relative_ratio" else \
                    _as_bool(v) if isinstance(f.default, bool) else type(f.default)(v)
        kw.update(overrides)
        return cls(**kw)

    def to_json(self) -> dict[str, Any]:
        return {f.name: (list(v) if isinstance(v := getattr(self, f.name), tuple) else v) for f in fields(self)}


@dataclass
class TrainJob:
    """One ground-truth space of one training store."""

    store: Any
    ref: SpaceRef
    elements: list[dict[str, Any]]
    key: int
    building: str
    frame: dict[str, Any] | None = None  # the space's canonical frame, once pass 1 has computed it
    mined: dict[int, np.ndarray] | None = None  # per class, keys of this space's negatives mined so far


@dataclass
class Samples:
    """Training vectors of one class: positives, negatives, the window (atom) of each, the mined windows' keys."""

    pos: list[np.ndarray] = field(default_factory=list)
    neg: list[np.ndarray] = field(default_factory=list)
    keys: set[tuple[int, int]] = field(default_factory=set)
    pos_atom: list[np.ndarray] = field(default_factory=list)
    neg_atom: list[np.ndarray] = field(default_factory=list)

    def n_neg(self) -> int:
        return int(sum(len(x) for x in self.neg))


def _as_bool(v: Any) -> bool:
    """A boolean setting (YAML gives bools; environment variables give strings)."""
    if isinstance(v, str):
        return v.strip().lower() in ("1", "true", "yes", "on")
    return bool(v)


# -- jobs -----------------------------------------------------------------------------------

def training_jobs(stores: list[Any], *, client=None, building_names: list[str] | None = None) -> list[TrainJob]:
    """One job per ground-truth space of every store (stores need ``gt_space`` and ``meta/ground_truth``)."""
    jobs: list[TrainJob] = []
    for si, store in enumerate(stores):
        doc = store.doc(GT_DOC)
        if not doc or store.meta.dimension("gt_space") is None:
            raise UserError(store.url, "no ground truth (gt_space and the meta/ground_truth document) to train on")
        by_space: dict[int, list[dict[str, Any]]] = {}
        for e in doc.get("elements", []):
            if 0 <= int(e["class_code"]) < N_CLASSES:
                by_space.setdefault(int(e["space"]), []).append(e)
        name = building_names[si] if building_names else store.url
        for ref in index_spaces(store, "gt_space", client=client, min_points=50):
            jobs.append(TrainJob(store, ref, by_space.get(ref.space_id, []), len(jobs), name))
    return jobs


def _canonical_gt(job: TrainJob, vol: SpaceVolume, gt_instance: np.ndarray | None) -> dict[str, np.ndarray]:
    """The elements of a space as canonical boxes (metres), with their point counts."""
    origin = np.asarray(job.store.meta.origin, dtype=np.float64)
    f = vol.frame
    lo, hi, cls, ids = [], [], [], []
    for e in job.elements:
        p, s = f.world_box_to_unit(np.asarray(e["center"]) - origin, e["size"], float(e.get("yaw", 0.0)))
        a = np.clip(p * f.extent, 0, f.extent)
        b = np.clip((p + s) * f.extent, 0, f.extent)
        if np.any(b - a <= 1e-6):
            continue
        lo.append(a), hi.append(b), cls.append(int(e["class_code"])), ids.append(int(e["id"]))
    ids_a = np.asarray(ids, dtype=np.int64)
    counts = np.zeros(len(ids), dtype=np.int64)
    if gt_instance is not None and len(ids):
        u, c = np.unique(gt_instance, return_counts=True)
        lookup = dict(zip(u.tolist(), c.tolist()))
        counts = np.array([lookup.get(i, 0) for i in ids], dtype=np.int64)
    return {"lo": np.asarray(lo, dtype=np.float64).reshape(-1, 3), "hi": np.asarray(hi, dtype=np.float64).reshape(-1, 3),
            "cls": np.asarray(cls, dtype=np.int64), "id": ids_a, "points": counts}


def _occupancy(metric: np.ndarray, lo: np.ndarray, hi: np.ndarray, k: int, min_points: int) -> np.ndarray:
    """K^3 occupancy pattern of points inside the box ``[lo, hi]`` (canonical metres)."""
    rel = (metric - lo) / np.maximum(hi - lo, 1e-9)
    inside = np.all((rel >= 0) & (rel <= 1), axis=1)
    idx = np.clip((rel[inside] * k).astype(np.int64), 0, k - 1)
    cnt = np.bincount(np.ravel_multi_index(idx.T, (k, k, k)), minlength=k ** 3) if len(idx) else np.zeros(k ** 3)
    return (cnt >= max(min_points, 1)).reshape(k, k, k)


def _instances_task(job: TrainJob, settings: TrainSettings) -> dict[str, np.ndarray]:
    """Pass 1: the canonical boxes and occupancy patterns of a space's elements."""
    pts = load_space(job.store, job.ref, "gt_space", truth=True)
    frame = space_frame(pts)
    metric = frame.to_metric(pts.xyz)
    vol = SpaceVolume(frame, mom.VoxelGrid.covering(frame.extent, settings.voxel, settings.max_cells),
                      np.zeros((1, 1, 1, 1)), len(pts.xyz))
    gt = _canonical_gt(job, vol, pts.gt_instance)
    keep = gt["points"] >= MIN_INSTANCE_POINTS
    k = settings.k
    occ = np.zeros((int(keep.sum()), k, k, k), dtype=bool)
    for j, i in enumerate(np.nonzero(keep)[0]):
        own = pts.gt_instance == gt["id"][i]
        occ[j] = _occupancy(metric[own], gt["lo"][i], gt["hi"][i], k, 1)
    size = gt["hi"][keep] - gt["lo"][keep]
    return {"cls": gt["cls"][keep], "metric_size": size, "unit_size": size / frame.extent, "occupancy": occ,
            "frame": frame.to_json()}


# -- samples ----------------------------------------------------------------------------------

def _rng(*key: int) -> np.random.Generator:
    return np.random.default_rng([int(k) & 0x7FFFFFFF for k in key])


def _window_key(atom: int, lo: np.ndarray) -> np.ndarray:
    lo = np.asarray(lo, dtype=np.int64).reshape(-1, 3)
    return (np.int64(atom) << 48) | (lo[:, 0] << 32) | (lo[:, 1] << 16) | lo[:, 2]


def _samples_task(job: TrainJob, model: Model, settings: TrainSettings, round_: int,
                  det: DetectionSettings, active: tuple[int, ...]) -> dict[int, dict[str, np.ndarray]]:
    """Pass 2+: feature vectors of positives and negatives of every class in one space.

    Round 0: ground-truth windows, jittered positives, other classes' elements and
    random negatives.  Later rounds: margin violators of the current detectors.
    """
    pts = load_space(job.store, job.ref, "gt_space", truth=True)
    vol = prepare_space(pts, model, CanonicalFrame.from_json(job.frame) if job.frame else None)
    gt = _canonical_gt(job, vol, pts.gt_instance)
    usable = gt["points"] >= MIN_INSTANCE_POINTS
    vox = vol.grid.voxel
    gt_lo_v, gt_hi_v = gt["lo"] / vox, gt["hi"] / vox
    lay = model.layout
    out: dict[int, dict[str, list]] = {c: {"pos": [], "neg": [], "keys": [], "pos_atom": [], "neg_atom": []}
                                       for c in range(N_CLASSES)}
    if round_ == 0 and usable.any():
        lo, hi = vol.voxel_box(gt["lo"][usable] / vol.frame.extent,
                               (gt["hi"][usable] - gt["lo"][usable]) / vol.frame.extent)
        feats = window_features(vol.iv, vol.grid, lo, hi, lay).astype(np.float32)
        cls = gt["cls"][usable]
        for c in range(N_CLASSES):
            near = _nearest_atoms((hi - lo) * vox, model, c, vol)
            out[c]["pos"].append(feats[cls == c]), out[c]["pos_atom"].append(near[cls == c])
            out[c]["neg"].append(feats[cls != c]), out[c]["neg_atom"].append(near[cls != c])
    for c in range(N_CLASSES):
        if c not in active:
            continue
        mine = gt["cls"] == c
        rng = _rng(settings.seed, round_, job.key, c)
        cand_lo, cand_hi, cand_keys, cand_scores, pos_lo, pos_hi, pos_at = [], [], [], [], [], [], []
        for ai, atom in enumerate(model.dictionary.atoms_):
            if atom.class_code != c:
                continue
            shape = window_shape(atom.size_in(vol.grid.extent), vol.grid)
            if round_ == 0:
                px, py, pz = window_positions(vol.grid, shape, det.stride, det.max_stride)
                counts = mom.box_sums_grid(vol.iv[..., :1], np.stack([px, px + shape[0]], 1),
                                           np.stack([py, py + shape[1]], 1), np.stack([pz, pz + shape[2]], 1))[..., 0]
                valid = counts >= det.min_window_points
                scores = np.zeros(valid.shape)
            else:
                w, b = model.window_weights([ai])
                ws = score_windows(vol, shape, w[0], float(b[0]), lay, det.stride, det.min_window_points,
                                   det.max_stride)
                px, py, pz = ws.px, ws.py, ws.pz
                valid = ws.scores > -1.0
                scores = ws.scores
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
            out[c]["pos"].append(window_features(vol.iv, vol.grid, lo, hi, lay).astype(np.float32))
            out[c]["pos_atom"].append(np.concatenate(pos_at))
        if cand_lo:
            lo, hi, keys = np.concatenate(cand_lo), np.concatenate(cand_hi), np.concatenate(cand_keys)
            n = settings.random_negatives if round_ == 0 else settings.hard_negatives
            if len(lo) > n:
                if round_ > 0 and settings.mining == "hardest":  # the n highest-scoring margin violators
                    pick = np.sort(np.argsort(-np.concatenate(cand_scores), kind="stable")[:n])
                else:
                    pick = np.sort(rng.choice(len(lo), n, replace=False))
                lo, hi, keys = lo[pick], hi[pick], keys[pick]
            if len(lo):
                out[c]["neg"].append(window_features(vol.iv, vol.grid, lo, hi, lay).astype(np.float32))
                out[c]["keys"].append(keys)
                out[c]["neg_atom"].append(keys >> 48)
    d = lay.size
    return {c: {"pos": np.concatenate(v["pos"]) if v["pos"] else np.zeros((0, d), np.float32),
                "neg": np.concatenate(v["neg"]) if v["neg"] else np.zeros((0, d), np.float32),
                "keys": np.concatenate(v["keys"]) if v["keys"] else np.zeros(0, np.int64),
                "pos_atom": np.concatenate(v["pos_atom"]).astype(np.int64) if v["pos_atom"] else np.zeros(0, np.int64),
                "neg_atom": np.concatenate(v["neg_atom"]).astype(np.int64) if v["neg_atom"] else np.zeros(0, np.int64)}
            for c, v in out.items()}


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


@dataclass
class SVMFit:
    """One class's fitted SVM: shared weights and intercept, and per window (atom) its own part."""

    weights: np.ndarray  # (D,) full layout
    bias: float
    atom_weights: dict[int, np.ndarray] = field(default_factory=dict)  # atom index -> (D,)
    atom_bias: dict[int, float] = field(default_factory=dict)


def _fit_svm(pos: np.ndarray, neg: np.ndarray, mask: np.ndarray, c: float, seed: int,
             atoms: tuple[np.ndarray, np.ndarray] | None = None, atom_scale: float = 1.0) -> SVMFit:
    """One linear SVM on the layout's active columns; returns full-layout weights and bias.

    With ``atoms`` (the window of each positive and negative, -1 for none) the SVM is one
    liblinear problem over ``[x, atom_scale * x (x) e_a, atom_scale * e_a]``: weights shared by
    the class plus each window's own weights and intercept, learnt jointly (the shared part is
    what windows have in common, the window's own part what only its shape shows: an open
    door's leaf, a low bookcase's top).  A window's score is then the sum of both parts, all
    in one margin, so scores of different windows stay comparable.  ``atom_scale`` weighs the
    windows' own parts against the shared one in the regulariser (larger: freer windows).
    """
    x = np.concatenate([pos, neg])[:, mask].astype(np.float64)
    y = np.concatenate([np.ones(len(pos)), -np.ones(len(neg))])
    svm = LinearSVC(C=c, class_weight="balanced", loss="squared_hinge", dual="auto", max_iter=5000,
                    random_state=seed)
    ids = np.zeros(0, dtype=np.int64)
    if atoms is not None:
        at = np.concatenate(atoms).astype(np.int64)
        ids = np.unique(at[at >= 0])
    if len(ids):
        x_fit = _atom_design(x, at, ids, atom_scale)
    else:
        x_fit = x
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        svm.fit(x_fit, y)
    d = int(mask.sum())
    coef = svm.coef_[0]
    w = np.zeros(len(mask))
    w[mask] = coef[:d]
    out = SVMFit(w, float(svm.intercept_[0]))
    for j, a in enumerate(ids.tolist()):
        block = coef[d + j * (d + 1): d + (j + 1) * (d + 1)] * atom_scale
        wa = np.zeros(len(mask))
        wa[mask] = block[:d]
        out.atom_weights[a], out.atom_bias[a] = wa, float(block[d])
    return out


def _atom_design(x: np.ndarray, atom: np.ndarray, ids: np.ndarray, scale: float):
    """Sparse ``[x, scale * x (x) e_a, scale * e_a]``: each row's features again in its window's block."""
    import scipy.sparse as sp

    n, d = x.shape
    block = np.searchsorted(ids, atom)
    has = (atom >= 0)
    rows = np.nonzero(has)[0]
    cols = (block[rows] * (d + 1))[:, None] + np.arange(d + 1)[None]
    vals = np.concatenate([x[rows], np.ones((len(rows), 1))], axis=1) * scale
    own = sp.csr_matrix((vals.ravel(), cols.ravel(), np.concatenate([[0], np.cumsum(has * (d + 1))])),
                        shape=(n, len(ids) * (d + 1)))
    return sp.hstack([sp.csr_matrix(x), own], format="csr")


# -- training ---------------------------------------------------------------------------------

def train(stores: list[Any], *, client=None, settings: TrainSettings | None = None,
          detection: DetectionSettings | None = None, provenance: dict[str, Any] | None = None,
          jobs: list[TrainJob] | None = None, log=None, names: list[str] | None = None) -> Model:
    """Train a model on ground-truth spaces of ``stores`` (or on the given ``jobs``).

    See :func:`train_with_samples` for the parameters; this returns only the model.
    """
    return train_with_samples(stores, client=client, settings=settings, detection=detection,
                              provenance=provenance, jobs=jobs, log=log, names=names)[0]


def train_with_samples(stores: list[Any], *, client=None, settings: TrainSettings | None = None,
                       detection: DetectionSettings | None = None, provenance: dict[str, Any] | None = None,
                       jobs: list[TrainJob] | None = None, log=None,
                       names: list[str] | None = None) -> tuple[Model, dict[int, Samples]]:
    """Train a model on ground-truth spaces of ``stores`` (or on the given ``jobs``); also its samples.

    Parameters
    ----------
    stores
        Tile stores with ground truth (``gt_space``, ``gt_instance``, ``meta/ground_truth``).
    client
        A ``distributed.Client``; every pass runs one task per space.
    settings, detection
        Training and sliding-window settings (default: ``buildingparser.detection.*``).
    provenance
        Extra facts stored in the model (data sources, seeds...).
    jobs
        Precomputed :func:`training_jobs` (a subset for cross-validation).
    log
        A callable taking one line of progress, or None.
    names
        A stable description of each store (``"synthetic seed 1000"``, a dataset's name) that the
        model's provenance records instead of the stores' URLs (temporary folders would make two
        trainings on the same data differ); default: the URLs.

    The model's provenance holds only facts of the data and settings (no timestamp, no duration),
    so that training again on the same data writes the same model.

    Returns
    -------
    The model and, per class code, the training vectors it was fitted on (full layout: every
    feature group is computed, the disabled ones are only left out of the fit), for
    :func:`refit_without`.
    """
    settings = settings or TrainSettings.from_config()
    det_run = detection or DetectionSettings.from_config()
    # mining scans every training space each round: a coarser cap on the stride than at run time
    det = dataclasses.replace(det_run, max_stride=max(det_run.max_stride, settings.max_stride))
    say = log or (lambda s: None)
    t0 = time.perf_counter()
    jobs = jobs if jobs is not None else training_jobs(stores, client=client, building_names=names)
    if not jobs:
        raise UserError(None, "no ground-truth spaces to train on")
    layout = FeatureLayout(settings.k, settings.disabled, context=settings.context)
    inst = run_tasks(_instances_task, jobs, client=client, label="training instances",
                     keys=[f"space {j.key}" for j in jobs], extra_args=(settings,))
    cls = np.concatenate([r["cls"] for r in inst])
    jobs = [dataclasses.replace(j, frame=r["frame"]) for j, r in zip(jobs, inst)]  # frames computed once
    say(f"{len(jobs)} spaces, {len(cls)} element instances")
    dictionary = WindowDictionary(settings.k, iou_weight=settings.iou_weight,
                                  preference_quantile=settings.preference_quantile,
                                  max_instances=settings.max_instances, max_atoms=settings.max_atoms,
                                  random_state=settings.seed, relative_ratio=settings.relative_ratio)
    use = np.isin(cls, settings.classes)
    dictionary.fit(cls[use], np.concatenate([r["unit_size"] for r in inst])[use],
                   np.concatenate([r["metric_size"] for r in inst])[use],
                   np.concatenate([r["occupancy"] for r in inst])[use])
    say(f"dictionary: {len(dictionary.atoms_)} windows "
        f"({', '.join(f'{ELEMENT_CLASSES[c]} {len(dictionary.atoms_of(c))}' for c in range(N_CLASSES))})")
    trained = np.array([c in settings.classes and len(dictionary.atoms_of(c)) > 0 for c in range(N_CLASSES)])
    model = Model(layout, dictionary, np.zeros((N_CLASSES, layout.size)), np.zeros(N_CLASSES), trained,
                  voxel=settings.voxel, max_cells=settings.max_cells, stride=det.stride)
    samples = {c: Samples() for c in range(N_CLASSES)}
    mask = layout.mask
    history = []
    active = tuple(c for c in range(N_CLASSES) if trained[c])
    for round_ in range(settings.rounds + 1):
        if round_ > 0 and settings.mining == "hardest":
            mined: dict[int, dict[int, list[int]]] = {j.key: {} for j in jobs}
            for c in range(N_CLASSES):
                for jk, kk in samples[c].keys:
                    mined[jk].setdefault(c, []).append(kk)
            jobs = [dataclasses.replace(j, mined={c: np.array(v, dtype=np.int64) for c, v in mined[j.key].items()})
                    for j in jobs]
        res = run_tasks(_samples_task, jobs, client=client, label=f"training samples, round {round_}",
                        keys=[f"space {j.key}" for j in jobs], extra_args=(model, settings, round_, det, active))
        new = np.zeros(N_CLASSES, dtype=np.int64)
        for job, r in zip(jobs, res):
            for c in range(N_CLASSES):
                s = samples[c]
                if len(r[c]["pos"]):
                    s.pos.append(r[c]["pos"]), s.pos_atom.append(r[c]["pos_atom"])
                neg, keys, neg_atom = r[c]["neg"], r[c]["keys"], r[c]["neg_atom"]
                if round_ == 0 and len(neg) > len(keys):  # other classes' elements come first, keyless
                    s.neg.append(neg[:len(neg) - len(keys)]), s.neg_atom.append(neg_atom[:len(neg) - len(keys)])
                    neg, neg_atom = neg[len(neg) - len(keys):], neg_atom[len(neg) - len(keys):]
                fresh = [i for i, kk in enumerate(keys.tolist()) if (job.key, kk) not in s.keys]
                if fresh and s.n_neg() < settings.max_negatives:
                    s.keys.update((job.key, keys[i]) for i in fresh)
                    s.neg.append(neg[fresh]), s.neg_atom.append(neg_atom[fresh])
                    new[c] += len(fresh)
        weights, bias = model.weights.copy(), model.bias.copy()
        atom_w, atom_b = (model.atom_weights.copy(), model.atom_bias.copy()) if model.atom_weights is not None else \
            (np.zeros((len(dictionary.atoms_), layout.size)), np.zeros(len(dictionary.atoms_)))
        for c in range(N_CLASSES):
            s = samples[c]
            if not trained[c]:
                continue
            if not s.pos or not s.neg:
                trained[c] = False
                continue
            if round_ == 0 or new[c]:
                fit = _fit_class(s, mask, settings)
                weights[c], bias[c] = fit.weights, fit.bias
                for a in [i for i, at in enumerate(dictionary.atoms_) if at.class_code == c]:
                    atom_w[a], atom_b[a] = fit.atom_weights.get(a, 0.0), fit.atom_bias.get(a, 0.0)
        model = Model(layout, dictionary, weights, bias, trained, voxel=settings.voxel,
                      max_cells=settings.max_cells, stride=det.stride,
                      **({"atom_weights": atom_w, "atom_bias": atom_b} if settings.atom_weights else {}))
        history.append({"round": round_, "new_negatives": new.tolist(),
                        "positives": [int(sum(len(x) for x in samples[c].pos)) for c in range(N_CLASSES)],
                        "negatives": [samples[c].n_neg() for c in range(N_CLASSES)]})
        say(f"round {round_}: new negatives {new.tolist()}")
        # classes without new violators are done (their detector no longer changes)
        active = tuple(c for c in active if trained[c] and (round_ == 0 or new[c] > 0))
        if round_ > 0 and not active:
            break
    groups_report, folds = None, []
    if settings.select_groups:
        model, groups_report = _select_groups(jobs, model, samples, settings, det_run, client, say, folds)
    if any(model.trained[c] for c in settings.box_fit_codes):
        model.boxfit = _train_boxfit(jobs, model, det_run, settings, client, say)
    if settings.rescore:
        model.rescorer = _train_rescorer(jobs, model, folds, det_run, client, say)
    model.detection = det_run.to_json()
    model.svm = {"estimator": "sklearn.svm.LinearSVC (liblinear)", "C": settings.c, "class_weight": "balanced",
                 "loss": "squared_hinge", "settings": settings.to_json(), "rounds": history,
                 "atom_weights": settings.atom_weights, "atom_scale": settings.atom_scale, "groups": groups_report}
    model.provenance = dict(provenance or {})
    model.provenance.update({"spaces": len(jobs), "instances": int(len(cls)),
                             "buildings": sorted({j.building for j in jobs}),
                             "instances_per_class": {ELEMENT_CLASSES[c]: int((cls == c).sum()) for c in range(N_CLASSES)}})
    say(f"trained in {time.perf_counter() - t0:.0f} s")
    return model, samples


def _select_groups(jobs: list[TrainJob], model: Model, samples: dict[int, Samples], settings: TrainSettings,
                   det: DetectionSettings, client, say, folds: list | None = None) -> tuple[Model, dict[str, Any]]:
    """Per-class feature groups by building-wise validation (:mod:`engine.training.groups`); the model with them.

    ``folds``, if a list, receives each validation fold's held-out buildings and its detectors with the
    chosen groups (``(set_of_buildings, model)``), for out-of-fold detections.
    """
    from engine.training import groups
    candidates = tuple(settings.select_groups.split(","))
    if len({j.building for j in jobs}) < groups.FOLDS:
        say("feature groups: one building, nothing to validate on: every class keeps all")
        return model, {"candidates": list(candidates), "skipped": "fewer buildings than folds", "chosen": {}}
    inner = dataclasses.replace(settings, select_groups="", box_fit="", rescore=False)
    fold_models: list = []
    ap = groups.validation_ap(
        jobs, lambda tj: train_with_samples([], client=client, settings=inner, detection=det, jobs=tj),
        candidates, settings, det, client=client, say=say, folds=fold_models)
    chosen = groups.choose_groups(ap, settings.group_classes.split(",") if settings.group_classes else None)
    if folds is not None:
        folds += [(held, groups.compose_chosen(ms, ("full",) + candidates, chosen)) for held, ms in fold_models]
    say("feature groups: " + (", ".join(f"{c} {v}" for c, v in chosen.items()) or "every class keeps all"))
    report = {"candidates": list(candidates), "classes": settings.group_classes or "all", "folds": groups.FOLDS,
              "margin": groups.MARGIN, "min_gt": groups.MIN_GT, "validation_ap": ap, "chosen": chosen}
    return groups.apply_groups(model, samples, chosen, settings), report


def _boxfit_task(job: TrainJob, model: Model, det: DetectionSettings, codes: tuple[int, ...],
                 min_iou: float) -> dict[str, np.ndarray]:
    """The space's detections of classes ``codes`` that overlap an element of their class by ``min_iou``,
    with their box-regression features and the faces of that element (:mod:`engine.detection.boxfit`)."""
    pts = load_space(job.store, job.ref, "gt_space", truth=True)
    frame = CanonicalFrame.from_json(job.frame) if job.frame else space_frame(pts)
    vol, index = prepare_indexed(pts, model, frame)
    d = detect_in_volume(vol, model, det, index, classes=list(codes))
    gt = _canonical_gt(job, vol, pts.gt_instance)
    rows, match = [], []
    for i in range(len(d.score)):
        same = np.nonzero(gt["cls"] == d.class_code[i])[0]
        if len(same):
            iou = box_iou(d.lo_m[i], d.hi_m[i], gt["lo"][same], gt["hi"][same])[0]
            if iou.max() >= min_iou:
                rows.append(i), match.append(same[int(np.argmax(iou))])
    lo, hi = d.lo_m[rows].reshape(-1, 3), d.hi_m[rows].reshape(-1, 3)
    gt_lo, gt_hi = gt["lo"][match].reshape(-1, 3), gt["hi"][match].reshape(-1, 3)
    feats, _ = box_features(index.points_in_metric, lo, hi, frame.extent)
    return {"cls": d.class_code[rows].astype(np.int64), "feats": feats,
            "targets": face_targets(lo, hi, gt_lo, gt_hi, frame.extent), "lo": lo, "hi": hi, "gt_lo": gt_lo,
            "gt_hi": gt_hi, "extent": np.tile(np.asarray(frame.extent, dtype=np.float64), (len(rows), 1))}


def _train_boxfit(jobs: list[TrainJob], model: Model, det: DetectionSettings, settings: TrainSettings, client,
                  say) -> Any:
    """The box regressions (:func:`engine.detection.boxfit.fit_boxfit`) of the ``box-fit`` classes, from the trained
    detectors' own detections in the training spaces."""
    codes = tuple(c for c in settings.box_fit_codes if model.trained[c])
    # a looser NMS than at run time: the near misses beside each element, which the regression is to
    # fix on new buildings, are in the samples too (the kept detections alone fit the training
    # elements too well to teach it: about three times as many samples on the shipped model's data)
    det = dataclasses.replace(det, nms_iou=BOXFIT_NMS_IOU, max_per_class=max(det.max_per_class, 100))
    res = run_tasks(_boxfit_task, jobs, client=client, label="box regression samples",
                    keys=[f"space {j.key}" for j in jobs], extra_args=(model, det, codes, BOXFIT_MIN_IOU))
    names = sorted({j.building for j in jobs})
    samples = {k: np.concatenate([r[k] for r in res]) for k in res[0]}
    samples["building"] = np.concatenate([np.full(len(r["cls"]), names.index(j.building)) for j, r in zip(jobs, res)])
    fit = fit_boxfit(samples, list(codes))
    fit.report["min_iou"] = BOXFIT_MIN_IOU
    on = [ELEMENT_CLASSES[c] for c in range(N_CLASSES) if fit.enabled[c]]
    say(f"box regression: {len(samples['cls'])} matched detections; used for {', '.join(on) or 'no class'}")
    return fit


def _rescore_task(job: TrainJob, model: Model, det: DetectionSettings) -> dict[str, np.ndarray]:
    """The space's final detections (``model`` with its box regression) with their re-ranking features
    (:func:`engine.detection.rescore.rescore_features`) and whether each is a true element (VOC, IoU 0.5)."""
    from engine.metrics.detection import match_detections

    pts = load_space(job.store, job.ref, "gt_space", truth=True)
    frame = CanonicalFrame.from_json(job.frame) if job.frame else space_frame(pts)
    vol, index = prepare_indexed(pts, model, frame)
    d = detect_in_volume(vol, model, det, index)
    gt = _canonical_gt(job, vol, pts.gt_instance)
    tp = np.zeros(len(d.score), dtype=bool)

    def boxes(lo, hi):
        return np.concatenate([(lo + hi) / 2.0, hi - lo, np.zeros((len(lo), 1))], axis=1)

    for c in np.unique(d.class_code):
        m, g = np.nonzero(d.class_code == c)[0], np.nonzero(gt["cls"] == c)[0]
        if len(g):
            tp[m] = match_detections(boxes(d.lo_m[m], d.hi_m[m]), d.score[m], np.arange(len(m)),
                                     boxes(gt["lo"][g], gt["hi"][g]))
    feats = rescore_features(d.score, d.lo_m, d.hi_m, index.points_in_metric, np.asarray(frame.extent, dtype=float))
    return {"cls": d.class_code.astype(np.int64), "feats": feats, "tp": tp,
            "n_gt": np.bincount(gt["cls"], minlength=N_CLASSES)[:N_CLASSES]}


def _train_rescorer(jobs: list[TrainJob], model: Model, folds: list, det: DetectionSettings, client, say) -> Any:
    """The re-ranking (:func:`engine.detection.rescore.fit_rescorer`) from detections in the training spaces: out of
    fold where the feature-group validation trained fold detectors (each building detected by the fold's
    detectors that did not see it, with the final model's box regression: the errors a new building gets),
    else the final detectors' own."""
    models = [model] + [dataclasses.replace(m, boxfit=model.boxfit, rescorer=None) for _, m in folds]
    which = [next((1 + i for i, (held, _) in enumerate(folds) if j.building in held), 0) for j in jobs]
    res = run_tasks(_rescore_job, list(zip(jobs, which)), client=client, label="re-ranking samples",
                    keys=[f"space {j.key}" for j in jobs], extra_args=(models, det))
    names = sorted({j.building for j in jobs})
    samples = {k: np.concatenate([r[k] for r in res]) for k in ("cls", "feats", "tp")}
    samples["building"] = np.concatenate([np.full(len(r["cls"]), names.index(j.building)) for j, r in zip(jobs, res)])
    fit = fit_rescorer(samples, np.sum([r["n_gt"] for r in res], axis=0))
    fit.report["samples"] = "out of fold" if folds else "the final detectors' own"
    on = [ELEMENT_CLASSES[c] for c in range(N_CLASSES) if fit.enabled[c]]
    say(f"re-ranking: {len(samples['cls'])} detections ({int(samples['tp'].sum())} true, "
        f"{fit.report['samples']}); used for {', '.join(on) or 'no class'}")
    return fit


def _rescore_job(item: tuple[TrainJob, int], models: list[Model], det: DetectionSettings) -> dict[str, np.ndarray]:
    """:func:`_rescore_task` of one job with the detectors ``models[i]`` chosen for its building."""
    return _rescore_task(item[0], models[item[1]], det)


def _fit_class(s: Samples, mask: np.ndarray, settings: TrainSettings) -> SVMFit:
    """The SVM of one class on its samples (with each window's own part when ``settings.atom_weights``)."""
    atoms = (np.concatenate(s.pos_atom), np.concatenate(s.neg_atom)) if settings.atom_weights else None
    return _fit_svm(np.concatenate(s.pos), np.concatenate(s.neg), mask, settings.c, settings.seed, atoms,
                    settings.atom_scale)


def refit_without(model: Model, samples: dict[int, Samples], disabled: tuple[str, ...],
                  settings: TrainSettings | None = None) -> Model:
    """The model's SVMs fitted again on the same samples without the feature groups ``disabled``.

    A cheap ablation (paper Table 3): the dictionary and the training vectors are the
    model's own, so the negatives were mined with the full model's detectors, not with
    the ablated ones (a full ablation would mine again with every pass over the spaces).

    Parameters
    ----------
    model, samples
        A model and its samples, as :func:`train_with_samples` returns them.
    disabled
        Feature groups to leave out (:data:`engine.detection.features.ABLATIONS` values), added to the
        model's own disabled groups.
    settings
        The SVM's ``c`` and ``seed`` (default: the model's training settings).
    """
    kw = model.svm.get("settings", {})
    if settings is None:
        settings = TrainSettings(c=float(kw.get("c", 0.05)), seed=int(kw.get("seed", 0)),
                                 atom_weights=bool(kw.get("atom_weights", False)),
                                 atom_scale=float(kw.get("atom_scale", 1.0)))
    layout = model.layout.without(disabled)
    weights, bias = np.zeros_like(model.weights), np.zeros_like(model.bias)
    n_atoms = len(model.dictionary.atoms_)
    atom_w, atom_b = np.zeros((n_atoms, layout.size)), np.zeros(n_atoms)
    trained = model.trained.copy()
    for cl in range(N_CLASSES):
        s = samples.get(cl)
        if not trained[cl] or s is None or not s.pos or not s.neg:
            trained[cl] = False
            continue
        fit = _fit_class(s, layout.mask, settings)
        weights[cl], bias[cl] = fit.weights, fit.bias
        for a, wa in fit.atom_weights.items():
            atom_w[a], atom_b[a] = wa, fit.atom_bias[a]
    own = {"atom_weights": atom_w, "atom_bias": atom_b} if settings.atom_weights else \
        {"atom_weights": None, "atom_bias": None}
    # the CRF and the re-ranking were learnt on the full model's scores: not this model's
    out = dataclasses.replace(model, layout=layout, weights=weights, bias=bias, trained=trained,
                              crf=None, crf_arrays={}, rescorer=None, **own)
    out.svm = dict(model.svm, ablation={"disabled": list(disabled),
                                        "samples": "the full model's (negatives mined with all features)"})
    return out


def synthetic_yaw(seed: int) -> float:
    """The yaw (degrees) of generated training building ``seed``: seeded, so that frames are exercised."""
    return float(np.random.default_rng([int(seed), 7]).uniform(0.0, 90.0))


def evaluate_on(store: Any, model: Model, *, client=None, space_array: str = "gt_space",
                detection: DetectionSettings | None = None):
    """Detect on ``store`` (ground-truth or parsed spaces) and score against its ground truth."""
    from engine.detection.detect import detect
    from engine.metrics.detection import evaluate_detections

    props = detect(store, model=model, client=client, space_array=space_array, settings=detection)
    doc = store.doc(GT_DOC) or {}
    return evaluate_detections(props, doc.get("elements", []), client=client), props


def cross_validate(stores: list[Any], *, client=None, settings: TrainSettings | None = None,
                   detection: DetectionSettings | None = None, log=None,
                   names: list[str] | None = None) -> dict[str, Any]:
    """Building-wise folds: train without one building, evaluate on it (ground-truth spaces), for each.

    ``names`` describe the stores (see :func:`train`); default: their URLs.

    Returns ``{"folds": [{"building", "ap": {...}, "mean_ap", ...}], "mean_ap": mean over folds}``.
    """
    if len(stores) < 2:
        raise UserError(None, "cross-validation needs at least two buildings (stores)")
    say = log or (lambda s: None)
    names = list(names) if names is not None else [s.url for s in stores]
    folds = []
    for i, test in enumerate(stores):
        train_stores = [s for j, s in enumerate(stores) if j != i]
        say(f"fold {i + 1}/{len(stores)}: test on {names[i]}")
        model = train(train_stores, client=client, settings=settings, detection=detection, log=log,
                      names=[n for j, n in enumerate(names) if j != i])
        ev, _ = evaluate_on(test, model, client=client, detection=detection)
        folds.append({"building": names[i], **ev.to_json()})
    return {"folds": folds, "mean_ap": float(np.nanmean([f["mean_ap"] for f in folds]))}
