"""Element detection as a pipeline stage: sliding windows per space, as dask tasks (paper section 4).

For every space (one task each, its points gathered from the tiles it touches):

1. its canonical frame from its own points (:func:`engine.canonical.estimate_frame`);
2. one pass over its points: voxel moments and their integral volume
   (:class:`engine.features.SpaceVolume`, voxel size and K from the model);
3. for every class, every window of the dictionary slid over the unit cube and
   scored by the class's linear SVM (:func:`engine.sliding.score_windows`);
   windows above ``score-threshold``, the ``pre-nms`` best per window shape;
4. per class, non-maximum suppression (3D IoU ``nms-iou``), at most
   ``max-per-class`` proposals;
5. thin-box refinement: along an axis where a detection is at most
   ``thin-voxels`` voxels thick (walls, floors, ceilings, boards...), its extent
   becomes the dense run around the peak of its points' histogram along that
   axis (``refine-bin`` metres), so that a 2 cm wall is not reported as a 10 cm
   voxel slab; the points are found through a voxel-sorted index, not a search;
6. the proposals, mapped back to world coordinates through the frame
   (:class:`engine.proposals.Proposal`: unit-cube P, S, B plus the world box).

Settings: ``buildingparser.detection.*`` (``engine/detection.yaml``).
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from engine import config
from engine import moments as mom
from engine.canonical import CanonicalFrame, estimate_frame
from engine.features import SpaceVolume
from engine.model import Model, load_model
from engine.proposals import Proposal
from engine.sliding import non_maximum_suppression, score_windows, window_shape
from engine.spacedata import SpacePoints, SpaceRef, index_spaces, load_space
from tiles.classes import ELEMENT_CLASSES
from tiles.tasks import run_tasks


@dataclass
class DetectionSettings:
    """Run-time settings of the detector (see ``engine/detection.yaml``)."""

    stride: float = 0.25
    min_window_points: int = 10
    score_threshold: float = -0.75
    pre_nms: int = 300
    nms_iou: float = 0.3
    max_per_class: int = 30
    refine: bool = True
    thin_voxels: int = 2
    refine_bin: float = 0.005
    label_margin: float = 0.02

    def __post_init__(self) -> None:
        if not 0 < self.stride <= 1:
            raise ValueError(f"stride must be in (0, 1], got {self.stride}")
        if not 0 <= self.nms_iou <= 1:
            raise ValueError(f"nms-iou must be in [0, 1], got {self.nms_iou}")
        if self.max_per_class < 1 or self.pre_nms < 1:
            raise ValueError("max-per-class and pre-nms must be >= 1")
        if self.refine_bin <= 0 or self.thin_voxels < 0 or self.label_margin < 0:
            raise ValueError("refine-bin must be > 0, thin-voxels and label-margin >= 0")

    @classmethod
    def from_config(cls, **overrides: Any) -> "DetectionSettings":
        """Settings from ``buildingparser.detection.*``, with keyword overrides."""
        kw = {}
        for f in fields(cls):
            v = config.get(f"detection.{f.name.replace('_', '-')}")
            if v is not None:
                kw[f.name] = type(f.default)(v)
        kw.update(overrides)
        return cls(**kw)

    def to_json(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class PointIndex:
    """A space's canonical points sorted by voxel, so that the points of a voxel box are a few slices."""

    def __init__(self, metric: np.ndarray, grid: mom.VoxelGrid):
        self.grid = grid
        idx = grid.index(metric)
        flat = np.ravel_multi_index((idx[:, 0], idx[:, 1], idx[:, 2]), grid.shape)
        order = np.argsort(flat, kind="stable")
        self.points = metric[order]
        self.offsets = np.concatenate([[0], np.cumsum(np.bincount(flat, minlength=int(np.prod(grid.shape))))])

    def points_in(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Canonical points ``(m, 3)`` of the voxel box ``[lo, hi)``."""
        nx, ny, nz = self.grid.shape
        xs, ys = np.meshgrid(np.arange(lo[0], hi[0]), np.arange(lo[1], hi[1]), indexing="ij")
        col = (xs.ravel() * ny + ys.ravel()) * nz
        start, stop = self.offsets[col + lo[2]], self.offsets[col + hi[2]]
        lengths = stop - start
        total = int(lengths.sum())
        if total == 0:
            return np.zeros((0, 3))
        base = np.repeat(start - np.concatenate([[0], np.cumsum(lengths)[:-1]]), lengths)
        return self.points[base + np.arange(total)]


def refine_extent(values: np.ndarray, lo: float, hi: float, bin_size: float, frac: float = 0.05) -> tuple[float, float]:
    """The dense run of ``values`` around the peak of their histogram in ``[lo, hi]`` (a surface's extent)."""
    if len(values) == 0:
        return lo, hi
    nb = max(int(np.ceil((hi - lo) / bin_size)), 1)
    h = np.bincount(np.clip(((values - lo) / bin_size).astype(np.int64), 0, nb - 1), minlength=nb)
    peak = int(np.argmax(h))
    dense = h >= frac * h[peak]
    a = peak
    while a > 0 and dense[a - 1]:
        a -= 1
    b = peak
    while b < nb - 1 and dense[b + 1]:
        b += 1
    return lo + a * bin_size, min(lo + (b + 1) * bin_size, hi)


def space_frame(points: SpacePoints, connection: np.ndarray | None = None) -> CanonicalFrame:
    """The canonical frame of a space (store-local coordinates), the same at training and run time."""
    return estimate_frame(points.xyz, connection=connection)


def prepare_space(points: SpacePoints, model: Model, frame: CanonicalFrame | None = None) -> SpaceVolume:
    """Frame and integral volume of one space for a model's voxel size."""
    frame = frame if frame is not None else space_frame(points)
    return SpaceVolume.build(points.xyz, points.rgb, frame, model.voxel, model.max_cells)


@dataclass
class Detections:
    """Detections of one space in its voxel grid, before conversion to proposals."""

    lo: np.ndarray  # (n, 3) voxel box
    hi: np.ndarray
    lo_m: np.ndarray  # (n, 3) refined box, canonical metres
    hi_m: np.ndarray
    score: np.ndarray
    class_code: np.ndarray
    atom: np.ndarray


def detect_in_volume(vol: SpaceVolume, model: Model, settings: DetectionSettings,
                     index: PointIndex | None = None, classes: list[int] | None = None) -> Detections:
    """Sliding windows, NMS and refinement in one prepared space."""
    grid = vol.grid
    lo_all, hi_all, sc_all, cl_all, at_all = [], [], [], [], []
    atoms = model.dictionary.atoms_
    for c in (range(len(ELEMENT_CLASSES)) if classes is None else classes):
        if not model.trained[c]:
            continue
        los, his, scs, ats = [], [], [], []
        for ai, atom in enumerate(atoms):
            if atom.class_code != c:
                continue
            shape = window_shape(atom.size_in(grid.extent), grid)
            ws = score_windows(vol, shape, model.weights[c], model.bias[c], model.layout, settings.stride,
                               settings.min_window_points)
            flat = ws.scores.ravel()
            ok = np.nonzero(flat > settings.score_threshold)[0]
            if len(ok) > settings.pre_nms:
                ok = ok[np.argpartition(-flat[ok], settings.pre_nms - 1)[:settings.pre_nms]]
            if not len(ok):
                continue
            lo, hi = ws.boxes(ok)
            los.append(lo), his.append(hi), scs.append(flat[ok]), ats.append(np.full(len(ok), ai))
        if not los:
            continue
        lo, hi, sc, at = np.concatenate(los), np.concatenate(his), np.concatenate(scs), np.concatenate(ats)
        keep = non_maximum_suppression(lo, hi, sc, settings.nms_iou, settings.max_per_class)
        lo_all.append(lo[keep]), hi_all.append(hi[keep]), sc_all.append(sc[keep])
        cl_all.append(np.full(len(keep), c)), at_all.append(at[keep])
    if not lo_all:
        z3 = np.zeros((0, 3), dtype=np.int64)
        return Detections(z3, z3, z3.astype(float), z3.astype(float), np.zeros(0), np.zeros(0, np.int64),
                          np.zeros(0, np.int64))
    lo, hi = np.concatenate(lo_all), np.concatenate(hi_all)
    vox = grid.voxel
    lo_m, hi_m = lo * vox, hi * vox
    if settings.refine and index is not None:
        for i in range(len(lo)):
            thin = np.nonzero(hi[i] - lo[i] <= settings.thin_voxels)[0]
            if not len(thin):
                continue
            pts = index.points_in(lo[i], hi[i])
            for a in thin:
                lo_m[i, a], hi_m[i, a] = refine_extent(pts[:, a], lo_m[i, a], hi_m[i, a], settings.refine_bin)
    return Detections(lo, hi, lo_m, hi_m, np.concatenate(sc_all), np.concatenate(cl_all), np.concatenate(at_all))


def to_proposals(det: Detections, vol: SpaceVolume, model: Model, space_id: int,
                 origin: np.ndarray) -> list[Proposal]:
    """Detections as :class:`Proposal` objects in world coordinates (``origin`` = store-local to world shift)."""
    f = vol.frame
    world = CanonicalFrame(f.yaw, f.origin + np.asarray(origin, dtype=np.float64), f.extent, f.entrance, f.info)
    out = []
    atoms = model.dictionary.atoms_
    for i in range(len(det.score)):
        p = det.lo_m[i] / f.extent
        s = (det.hi_m[i] - det.lo_m[i]) / f.extent
        center, size, yaw = world.unit_box_to_world(p, s)
        out.append(Proposal(space_id=int(space_id), class_code=int(det.class_code[i]), score=float(det.score[i]),
                            position=p, size=s, occupancy=atoms[int(det.atom[i])].occupancy.copy(),
                            center=center, world_size=size, yaw=float(yaw),
                            extra={"atom": int(det.atom[i])}))
    return out


def detect_space(points: SpacePoints, model: Model, settings: DetectionSettings | None = None,
                 origin: np.ndarray | None = None) -> list[Proposal]:
    """All proposals of one space (its points in store-local coordinates)."""
    settings = settings or DetectionSettings.from_config()
    if len(points.xyz) < max(settings.min_window_points, 4):
        return []
    vol = prepare_space(points, model)
    index = PointIndex(vol.frame.to_metric(points.xyz), vol.grid) if settings.refine else None
    det = detect_in_volume(vol, model, settings, index)
    return to_proposals(det, vol, model, points.space_id, np.zeros(3) if origin is None else origin)


def _detect_task(ref: SpaceRef, store, model: Model, space_array: str,
                 settings: DetectionSettings) -> list[Proposal]:
    points = load_space(store, ref, space_array)
    return detect_space(points, model, settings, np.asarray(store.meta.origin, dtype=np.float64))


def detect(store, *, model: Model | str | None = None, client=None, space_array: str = "space_id",
           settings: DetectionSettings | None = None) -> list[Proposal]:
    """Element proposals of every space of a store, one dask task per space.

    Parameters
    ----------
    store
        A :class:`tiles.store.TileStore` with per-point ``space_array`` ids.
    model
        A :class:`Model`, a model path, or None for the shipped default model.
    client
        A ``distributed.Client``; None runs here.
    space_array
        ``"space_id"`` (parsed spaces) or ``"gt_space"`` (ground-truth spaces).
    settings
        Detection settings; default from ``buildingparser.detection.*``.

    Returns
    -------
    The proposals of all spaces (world coordinates), with ``element_id`` numbered
    from 0 by space, class and decreasing score.
    """
    if not isinstance(model, Model):
        model = load_model(model)
    settings = settings or DetectionSettings.from_config()
    refs = index_spaces(store, space_array, client=client)
    if client is not None and refs:
        [model_arg] = client.scatter([model], broadcast=True)
    else:
        model_arg = model
    results = run_tasks(_detect_task, refs, client=client, label="detect elements",
                        keys=[f"space {r.space_id}" for r in refs],
                        extra_args=(store, model_arg, space_array, settings))
    proposals = [p for r in results for p in r]
    proposals.sort(key=lambda p: (p.space_id, p.class_code, -p.score))
    for i, p in enumerate(proposals):
        p.element_id = i
    return proposals
