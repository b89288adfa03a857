"""The training spaces (paper section 4): one job per ground-truth space, its elements as canonical boxes.

:func:`training_jobs` lists the ground-truth spaces of the training stores; :func:`canonical_gt` gives a
space's elements as boxes of its canonical frame; :func:`instances_task` is the first pass, the
canonical size and occupancy pattern of every element instance (what the window dictionary is learnt
from).  Design notes: ``docs/design/training.md``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from engine.detection import moments as mom
from engine.detection.space import space_frame
from engine.detection.volume import SpaceVolume
from engine.spaces.points import SpaceRef, index_spaces, load_space
from engine.training.settings import N_CLASSES, TrainSettings
from tiles.errors import UserError
from tiles.groundtruth import DOC as GT_DOC

#: Elements with fewer points than this in their space are not used for training.
MIN_INSTANCE_POINTS = 10


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


def canonical_gt(job: TrainJob, vol: SpaceVolume, gt_instance: np.ndarray | None) -> dict[str, np.ndarray]:
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
    return {"lo": np.asarray(lo, dtype=np.float64).reshape(-1, 3),
            "hi": np.asarray(hi, dtype=np.float64).reshape(-1, 3),
            "cls": np.asarray(cls, dtype=np.int64), "id": ids_a, "points": counts}


def _occupancy(metric: np.ndarray, lo: np.ndarray, hi: np.ndarray, k: int, min_points: int) -> np.ndarray:
    """K^3 occupancy pattern of points inside the box ``[lo, hi]`` (canonical metres)."""
    rel = (metric - lo) / np.maximum(hi - lo, 1e-9)
    inside = np.all((rel >= 0) & (rel <= 1), axis=1)
    idx = np.clip((rel[inside] * k).astype(np.int64), 0, k - 1)
    cnt = np.bincount(np.ravel_multi_index(idx.T, (k, k, k)), minlength=k ** 3) if len(idx) else np.zeros(k ** 3)
    return (cnt >= max(min_points, 1)).reshape(k, k, k)


def instances_task(job: TrainJob, settings: TrainSettings) -> dict[str, np.ndarray]:
    """Pass 1: the canonical boxes and occupancy patterns of a space's elements."""
    pts = load_space(job.store, job.ref, "gt_space", truth=True)
    frame = space_frame(pts)
    metric = frame.to_metric(pts.xyz)
    vol = SpaceVolume(frame, mom.VoxelGrid.covering(frame.extent, settings.voxel, settings.max_cells),
                      np.zeros((1, 1, 1, 1)), len(pts.xyz))
    gt = canonical_gt(job, vol, pts.gt_instance)
    keep = gt["points"] >= MIN_INSTANCE_POINTS
    k = settings.k
    occ = np.zeros((int(keep.sum()), k, k, k), dtype=bool)
    for j, i in enumerate(np.nonzero(keep)[0]):
        own = pts.gt_instance == gt["id"][i]
        occ[j] = _occupancy(metric[own], gt["lo"][i], gt["hi"][i], k, 1)
    size = gt["hi"][keep] - gt["lo"][keep]
    return {"cls": gt["cls"][keep], "metric_size": size, "unit_size": size / frame.extent, "occupancy": occ,
            "frame": frame.to_json()}
